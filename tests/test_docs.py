"""The docs link only to files the project has; docstrings cite only what the package ships;
matplotlib loads only to plot; the templates of docs/extending.md work."""

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


# The README links to the project's own files by their address on GitHub (so that the links work
# on the package index too); those must name files the repository has, like relative ones.
# Pages the docs build writes itself (docs/_ext/gallery.py makes the gallery from examples/).
GENERATED_PAGES = {ROOT / "docs" / "gallery.md"}
OWN_FILES = re.compile(r"^https://github\.com/liesample/liesample/(?:blob|tree)/main/")


def _relative_links(path: Path):
    """``(target, folder it is relative to)`` of each link to a file of the project."""
    for target in LINK.findall(path.read_text()):
        own = OWN_FILES.match(target)
        if own:
            yield target[own.end() :], ROOT
        elif not re.match(r"^[a-z][a-z0-9+.-]*:", target):  # not http:, https:, mailto:
            yield target, path.parent


def test_there_are_docs_to_check():
    names = {path.name for path in DOCUMENTS}
    assert {"README.md", "mathematics.md", "architecture.md"} <= names


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: p.name)
def test_every_relative_link_resolves_inside_the_project(document):
    broken = []
    for target, folder in _relative_links(document):
        file_part, _, anchor = target.partition("#")
        resolved = (folder / file_part).resolve() if file_part else document
        if resolved in GENERATED_PAGES and not anchor:
            continue
        if not resolved.is_relative_to(ROOT) or not resolved.exists():
            broken.append(target)
            continue
        if anchor and resolved.suffix == ".md":
            headings = re.findall(r"^#+ (.+)$", resolved.read_text(), flags=re.MULTILINE)
            if anchor not in {_slug(h) for h in headings}:
                broken.append(target)
    assert not broken, f"{document.name}: links that do not resolve: {broken}"


def test_links_to_the_projects_own_files_on_github_are_checked(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(
        "[a](https://github.com/liesample/liesample/blob/main/docs/mathematics.md#sign)"
        " [b](https://github.com/other/project/blob/main/x.md) [c](local.md)"
    )
    assert list(_relative_links(page)) == [
        ("docs/mathematics.md#sign", ROOT),
        ("local.md", tmp_path),
    ]


def test_the_readme_links_work_on_the_package_index():
    """The package index shows the README without the repository: a relative link is dead."""
    relative = [t for t in LINK.findall((ROOT / "README.md").read_text()) if ":" not in t]
    assert not relative, f"README.md: relative links (use the GitHub address): {relative}"


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: p.name)
def test_no_reference_to_files_users_do_not_have(document):
    text = document.read_text()
    assert "../shared" not in text and "MATH.md" not in text and "ARCHITECTURE.md" not in text


# --- Docstrings cite only what the package ships -------------------------------------------------

PACKAGE = ROOT / "liesample"
SHIPPED = {path.relative_to(ROOT).as_posix() for path in PACKAGE.rglob("*.py")}

# A file the package does not ship: a Markdown/TeX/notebook file, anything under the project's
# non-package folders, or the shared notes by their names (``MATH.md §2``, ``ARCHITECTURE:``).
NOT_SHIPPED = re.compile(
    r"(?<![\w/.-])(?:\.\./)*(?:docs|benchmarks|tests|examples|shared|paper)/(?:[\w./:-]*\w)?"
    r"|[\w./-]+\.(?:md|tex|rst|ipynb)\b"
    r"|\b(?:MATH|ARCHITECTURE|RESULTS)\b"
)
# A path to a Python file: fine only when it is one of the package's own modules.
PYTHON_PATH = re.compile(r"(?<![\w/.-])[\w.-]+(?:/[\w.-]+)+\.py\b")


def _docstrings(path: Path):
    """``(line, text)`` of the module's docstring and of every class's and function's."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if not isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        first = node.body[0] if node.body else None
        value = first.value if isinstance(first, ast.Expr) else None
        if isinstance(value, ast.Constant) and isinstance(value.value, str):
            yield first.lineno, value.value


def citations_of_unshipped_files(path: Path, root: Path = ROOT) -> list[str]:
    """``file:line: cited`` for each docstring citation of a file the package does not ship."""
    found = set()
    for first_line, text in _docstrings(path):
        for offset, line in enumerate(text.splitlines()):
            cited = NOT_SHIPPED.findall(line) + [
                p for p in PYTHON_PATH.findall(line) if p not in SHIPPED
            ]
            for name in cited:
                found.add((first_line + offset, name))
    relative = path.relative_to(root).as_posix()
    return [f"{relative}:{line}: {name}" for line, name in sorted(found)]


def test_docstrings_cite_only_shipped_files():
    """A user reads docstrings without the repository: they may cite the package's own modules
    and the seed paper's labels (``eq:poisson-langevin-eq``), never notes, tests or benchmarks."""
    offenders = [
        hit for path in sorted(PACKAGE.rglob("*.py")) for hit in citations_of_unshipped_files(path)
    ]
    assert not offenders, "docstrings cite files the package does not ship:\n" + "\n".join(
        offenders
    )


def test_the_docstring_check_can_fail(tmp_path):
    module = tmp_path / "liesample" / "fake.py"
    module.parent.mkdir()
    module.write_text(
        '"""See MATH.md §1 and the paper, ``eq:poisson-langevin-eq``."""\n\n\n'
        "class A:\n"
        '    """Fine: :mod:`liesample.dynamics.system`, ``liesample/cli.py``."""\n\n'
        "    def f(self):\n"
        '        """Two lines.\n\n'
        '        Measured in ``tests/test_x.py`` and docs/architecture.md."""\n'
    )
    assert citations_of_unshipped_files(module, root=tmp_path) == [
        "liesample/fake.py:1: MATH.md",
        "liesample/fake.py:10: docs/architecture.md",
        "liesample/fake.py:10: tests/test_x.py",
    ]


# --- matplotlib only where a figure is drawn ---------------------------------------------------


def test_matplotlib_is_imported_only_by_the_plots():
    importers = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            names = (
                [alias.name for alias in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            if any(name.split(".")[0] == "matplotlib" for name in names):
                importers.add(path.relative_to(ROOT).as_posix())
    assert importers <= {"liesample/analysis/plots.py"}, sorted(importers)


def test_importing_liesample_does_not_import_matplotlib():
    code = "import sys, liesample, liesample.cli; print('matplotlib' in sys.modules)"
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True
    )
    assert result.stdout.strip() == "False"


# --- The templates of docs/extending.md work -------------------------------------------------


def test_the_system_template_builds_and_samples_one_step():
    import jax
    import jax.numpy as jnp

    import liesample
    from liesample.integrators._template_integrator import group_midpoint
    from liesample.samplers.contract import check_info
    from liesample.systems._template_system import moment_in_field

    system = moment_in_field((0.0, 0.0, 2.0))
    start = jnp.array([1.0, 0.0, 0.0])
    for integrator in ("splitting", group_midpoint):
        sampler = liesample.lie_poisson_langevin(
            system, beta=1.5, sigma=1.0, step_size=0.05, integrator=integrator
        )
        state, info = jax.jit(sampler.step)(jax.random.key(0), sampler.init(start))
        check_info(info)
        assert not bool(info.is_divergent)
        assert abs(float(jnp.linalg.norm(state.position)) - 1.0) < 1e-12  # stays on the orbit
    reference = system.reference(1.5, start)
    assert reference.kappa == pytest.approx(1.5 * 1.0 * 2.0)
    assert reference.mean()[2] > 0.0


def test_the_sampler_and_space_templates_take_one_step():
    import jax
    import jax.numpy as jnp

    import liesample
    from liesample.geometry._template_space import PositiveReals
    from liesample.samplers._template_sampler import orbit_metropolis
    from liesample.samplers.contract import check_info
    from liesample.systems._template_system import moment_in_field

    sampler = orbit_metropolis(moment_in_field(), beta=1.0, scale=0.5)
    state, info = jax.jit(sampler.step)(jax.random.key(0), sampler.init(jnp.array([0.0, 0.6, 0.8])))
    check_info(info)
    assert abs(float(jnp.linalg.norm(state.position)) - 1.0) < 1e-12

    def gamma_logdensity(x):  # Gamma(3, 1) with respect to the Haar measure dx/x
        return jnp.sum(3.0 * jnp.log(x) - x)

    hmc = liesample.geometric_hmc(
        gamma_logdensity, PositiveReals((2,)), step_size=0.3, num_integration_steps=5
    )
    state, info = jax.jit(hmc.step)(jax.random.key(1), hmc.init(jnp.array([1.0, 2.0])))
    check_info(info)
    assert bool(jnp.all(state.position > 0.0))
    with pytest.raises(ValueError, match="> 0"):
        hmc.init(jnp.array([1.0, -2.0]))


# --- every public callable has an example (``make doctest`` runs them) -------------------------

# The modules whose names users call, by the file that holds their ``__all__`` (liesample's own
# public names are ``_ATTRIBUTES`` of its ``__init__.py``; ``algebras`` has no ``__all__``: its
# public top-level names).
PUBLIC_MODULES = [
    "systems/__init__.py", "geometry/spaces.py", "analysis/diagnostics.py",
    "integrators/accuracy.py", "targets/__init__.py", "geometry/algebras.py", "run/sharding.py",
    "integrators/stability.py", "integrators/drivers.py", "numpyro.py",
]  # fmt: skip


def _module_file(module: str) -> Path:
    path = PACKAGE.parent / module.replace(".", "/")
    return path / "__init__.py" if path.is_dir() else path.with_suffix(".py")


def _public_names(path: Path) -> list[str]:
    """``__all__`` of the module at ``path`` (or of the module it takes it from), else the
    public names it defines."""
    tree = ast.parse(path.read_text())
    defined = []
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and "__all__" in {a.name for a in node.names}:
            return _public_names(_module_file(node.module))
        targets = node.targets if isinstance(node, ast.Assign) else []
        if any(getattr(target, "id", "") == "__all__" for target in targets):
            return list(ast.literal_eval(node.value))
        if isinstance(node, ast.FunctionDef | ast.ClassDef):
            defined.append(node.name)
        defined += [target.id for target in targets if isinstance(target, ast.Name)]
    return [name for name in defined if not name.startswith("_")]


def _definition_docstring(path: Path, name: str) -> str | None:
    """The docstring a user's ``help(name)`` shows, found in the source (nothing imported):
    a function's or class's own, a sampler's (its ``as_top_level_api``), an object's (its
    class's); ``None`` for a constant or a type alias (nothing to call)."""
    tree = ast.parse(path.read_text())
    for node in reversed(tree.body):  # the last definition wins (after typing.overload stubs)
        if isinstance(node, ast.FunctionDef | ast.ClassDef) and node.name == name:
            return ast.get_docstring(node) or ""
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == name for t in node.targets):
            if not isinstance(node.value, ast.Call) or not isinstance(node.value.func, ast.Name):
                return None  # a constant
            call = node.value
            made_by = call.args[0].id if call.func.id == "sampling_api" else call.func.id
            return _definition_docstring(path, made_by)
    for node in tree.body:
        if (
            isinstance(node, ast.ImportFrom)
            and node.level == 0
            and node.module.startswith("liesample")
        ):
            imported = {alias.asname or alias.name for alias in node.names}
            if name in imported or "*" in imported:
                found = _definition_docstring(_module_file(node.module), name)
                if found is not None or name in imported:
                    return found
    return None


def _public_callables():
    init = ast.parse((PACKAGE / "__init__.py").read_text())
    attributes = next(
        node.value for node in init.body
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "_ATTRIBUTES"
    )  # fmt: skip
    for name, module in ast.literal_eval(attributes).items():
        yield f"liesample.{name}", _module_file(module), name
    for relative in PUBLIC_MODULES:
        path = PACKAGE / relative
        for name in _public_names(path):
            module = path.relative_to(PACKAGE.parent).with_suffix("").as_posix().replace("/", ".")
            yield f"{module.removesuffix('.__init__')}.{name}", path, name


def test_every_public_callable_has_an_examples_section():
    """Each name of the public ``__all__``s (modules aside) documents a call that runs: an
    ``Examples`` section, run by ``make doctest`` (constants and type aliases have none)."""
    callables = [
        (label, _definition_docstring(path, name)) for label, path, name in _public_callables()
    ]
    assert len(callables) > 100
    missing = [
        label for label, doc in callables if doc is not None and "\nExamples\n--------\n" not in doc
    ]
    assert not missing, "no Examples section in the docstring of: " + ", ".join(missing)


def test_the_examples_check_reads_each_kind_of_definition(tmp_path):
    module = tmp_path / "fake.py"
    module.write_text(
        "LIMIT = 2.0\n\n\n"
        "class Law:\n"
        '    """A law.\n\n    Examples\n    --------\n    >>> Law()\n    """\n\n\n'
        "def plain():\n"
        '    """No example."""\n\n\n'
        "law = Law()\n"
    )
    docs = {name: _definition_docstring(module, name) for name in ("LIMIT", "law", "plain")}
    assert docs["LIMIT"] is None and docs["plain"] == "No example."
    assert "\nExamples\n--------\n" in docs["law"]  # an object: its class's docstring
