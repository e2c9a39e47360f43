"""What a fresh install carries: the version from the metadata, the typing marker, the licence."""

import tomllib
from importlib.metadata import version
from pathlib import Path

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
