"""What a fresh install carries: the version from the metadata, the typing marker, the licence."""

import os
import subprocess
import sys
import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest

import liesample

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_version_is_the_installed_metadata():
    assert liesample.__version__ == version("liesample")
    assert liesample.__version__ == PYPROJECT["project"]["version"]


def test_typing_marker_ships_with_the_package():
    assert (Path(liesample.__file__).parent / "py.typed").is_file()
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["liesample"]


def test_licence_is_the_declared_one():
    assert PYPROJECT["project"]["license"] == "MIT"
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
    assert PYPROJECT["project"]["license-files"] == ["LICENSE"]


def test_changelog_keeps_an_unreleased_section_and_the_current_version():
    text = (ROOT / "CHANGELOG.md").read_text()
    assert "## [Unreleased]" in text
    assert f"## [{PYPROJECT['project']['version']}]" in text


# --- import liesample is cheap; its names load on first use ------------------------------------


def test_import_loads_no_heavy_dependency_until_a_name_is_used():
    code = (
        "import sys, liesample\n"
        "heavy = ['jax', 'blackjax', 'arviz_stats', 'arviz_base', 'xarray', 'pandas', "
        "'scipy.stats', 'matplotlib', 'numpyro']\n"
        "print([m for m in heavy if m in sys.modules])\n"
        "from liesample.spaces import Sphere\n"
        "import liesample.geometry.spaces as spaces\n"
        "assert sys.modules['liesample.spaces'] is spaces is liesample.spaces\n"
        "assert spaces.__spec__.name == 'liesample.geometry.spaces'\n"
        "print([m for m in heavy if m in sys.modules])\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    lines = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    ).stdout.splitlines()
    assert lines == ["[]", "['jax']"]


def test_every_public_name_resolves_to_its_module():
    for name in liesample.__all__:
        value = getattr(liesample, name)
        assert value is not None, name
    for short, module in liesample._SHORT_NAMES.items():
        assert getattr(liesample, short) is sys.modules[module] is sys.modules[f"liesample.{short}"]
    for name, module in liesample._ATTRIBUTES.items():
        assert getattr(liesample, name) is getattr(sys.modules[module], name)
    assert liesample.sample.__module__ == "liesample.run.runner"
    assert {"sample", "systems", "spaces", "__version__"} <= set(dir(liesample))
    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        liesample.no_such_name  # noqa: B018
