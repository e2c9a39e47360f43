# Python >= 3.12 is required (ArviZ 1.x, current jax). Pick the first interpreter that qualifies.
PY_CANDIDATES := python3.13 python3.12 python3 $(wildcard /root/.pyenv/versions/3.1[2-9]*/bin/python3) $(wildcard /usr/local/bin/python3.1[2-9]) $(wildcard /usr/bin/python3.1[2-9])
PYTHON ?= $(shell for p in $(PY_CANDIDATES); do \
	$$p -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' >/dev/null 2>&1 && { echo $$p; break; }; done)
VENV := .venv
BIN := $(VENV)/bin
JOBS ?= 2

.PHONY: demo test test-slow test-oldest bench docs doctest docs-figures clean check-python

check-python:
	@test -n "$(PYTHON)" || { echo "error: Python >= 3.12 not found (tried: $(PY_CANDIDATES))"; exit 1; }

# uv (from PyPI, into the venv) installs the dependencies: many times faster than pip on a
# fresh machine, where downloads dominate. It compiles their bytecode at install time, so that a
# machine that never writes it (PYTHONDONTWRITEBYTECODE) does not recompile jax, scipy and
# ArviZ from source in every process (each test worker and subprocess: seconds each).
INSTALL := $(BIN)/uv pip install -q --compile-bytecode --python $(BIN)/python

$(BIN)/uv: | check-python
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --disable-pip-version-check uv

$(BIN)/.installed: pyproject.toml | $(BIN)/uv
	$(INSTALL) -e .
	touch $@

$(BIN)/.installed-test: $(BIN)/.installed
	$(INSTALL) -e '.[test]'
	touch $@

demo: $(BIN)/.installed
	$(BIN)/liesample demo

# The lint and the format check first (a second or two), with the rule set of pyproject.toml
# [tool.ruff.lint] and ruff's formatter on the Python files ([tool.ruff.format]).
# Each test file runs on one worker (--dist loadfile): a file's module-scoped samplers and runs,
# and the programs its tests share, are built and compiled once, not once per worker.
TEST_DIST := --dist loadfile
test: $(BIN)/.installed-test
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/python -m pytest -n $(JOBS) $(TEST_DIST) -q

test-slow: $(BIN)/.installed-test
	$(BIN)/python -m pytest -n $(JOBS) --dist worksteal -q -m slow

# Every declared floor at once, in its own venv: uv resolves each direct dependency of
# pyproject.toml (jax, jaxlib, numpy, scipy, blackjax, arviz, xarray, h5netcdf, matplotlib,
# tqdm, and the test extras with NumPyro) to the lowest version it allows, and
# `make test-oldest` runs the default suite on that set.
VENV_OLDEST := .venv-oldest

$(VENV_OLDEST)/bin/.installed-test: pyproject.toml | check-python
	rm -rf $(VENV_OLDEST)  # afresh: a kept newer version would hide a floor
	$(PYTHON) -m venv $(VENV_OLDEST)
	$(VENV_OLDEST)/bin/pip install -q --disable-pip-version-check uv
	$(VENV_OLDEST)/bin/uv pip install -q --compile-bytecode --python $(VENV_OLDEST)/bin/python \
		--resolution lowest-direct -e '.[test]'
	touch $@

test-oldest: $(VENV_OLDEST)/bin/.installed-test
	$(VENV_OLDEST)/bin/python -m pytest -n $(JOBS) $(TEST_DIST) -q

$(BIN)/.installed-bench: $(BIN)/.installed
	$(INSTALL) -e '.[bench]'
	touch $@

# Cold compiles, as a first run on a new machine sees them: no persistent compilation cache
# (liesample.foundation.cache; a suite that measures the cache turns it on itself).
bench: $(BIN)/.installed-bench
	LIESAMPLE_COMPILATION_CACHE=0 $(BIN)/python benchmarks/run.py

# The guides in docs/ and the API reference from the docstrings, rendered into site/ by MkDocs
# with mkdocstrings; --strict: a warning (a broken link, a docstring the parser cannot read)
# fails the build.
$(BIN)/.installed-docs: $(BIN)/.installed
	$(INSTALL) -e '.[docs]'
	touch $@

docs: $(BIN)/.installed-docs
	$(BIN)/python -m mkdocs build --strict

# Every docstring's Examples section, run (not part of `make test`): x64 on, the examples' names
# and XLA's cheap back-end setting come from the root conftest.py.
doctest: $(BIN)/.installed-test
	$(BIN)/python -m pytest -q -p no:cacheprovider --doctest-modules liesample -o addopts="" \
		-o doctest_optionflags="NORMALIZE_WHITESPACE ELLIPSIS"

# The figures checked in under docs/figures/ (the demo's and the examples'), drawn anew: each
# script runs once (minutes). The benchmark figures come from `make bench`.
docs-figures: $(BIN)/.installed
	$(BIN)/python docs/figures/make_figures.py

clean:
	rm -rf $(VENV) $(VENV_OLDEST) liesample-demo-output .pytest_cache site
