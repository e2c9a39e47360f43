"""MkDocs hook: the gallery page, one section per script of examples/, made from the scripts.

Each section holds the script's docstring, its source, and what it makes: the figures that
``docs/figures/make_figures.py`` drew from it and keeps in docs/figures/, or the printout it
keeps there as ``<name>.txt``. Nothing is run at build time (the tests run the examples); the
page is written anew from the scripts at every build, so it cannot fall behind them.
"""

import ast
import importlib.util
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
FIGURES = ROOT / "docs" / "figures"
SOURCE = "https://github.com/liesample/liesample/blob/main/examples"

INTRO = """# Gallery

Every script of the repository's `examples/` folder: what it shows (its docstring), its
source, and the figures or the printout it makes. Run one from a checkout with
`.venv/bin/python examples/<name>.py` (its docstring gives the options). The figures and
printouts here were made by `docs/figures/make_figures.py`, which runs each script with the
arguments it lists (some smaller than the defaults, to keep it short).
"""


def _figures_by_example() -> dict[str, list[str]]:
    """The PNGs each example makes, as ``docs/figures/make_figures.py`` declares them."""
    spec = importlib.util.spec_from_file_location("make_figures", FIGURES / "make_figures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return {name: list(files.values()) for name, (_, files) in module.FIGURES.items()}


def _escape(text: str) -> str:
    """``text`` with Markdown's emphasis characters taken literally (``se(2)*``)."""
    return text.replace("*", "\\*").replace("_", "\\_")


def _fence_indented_blocks(text: str) -> str:
    """``text`` with each block indented by four spaces after a blank line fenced as code.

    The docstrings show commands and formulas as indented blocks; Markdown would read one that
    follows a list as the list's continuation, so each is fenced explicitly."""
    lines, out, index = text.splitlines(), [], 0
    while index < len(lines):
        starts_block = lines[index].startswith("    ") and (index == 0 or not lines[index - 1])
        if not starts_block:
            out.append(lines[index])
            index += 1
            continue
        end = index
        while end < len(lines) and (lines[end].startswith("    ") or not lines[end].strip()):
            end += 1
        while not lines[end - 1].strip():
            end -= 1
        out += ["```text", *(line[4:] for line in lines[index:end]), "```"]
        index = end
    return "\n".join(out)


def _section(script: Path, figures: list[str]) -> str:
    docstring = ast.get_docstring(ast.parse(script.read_text())) or ""
    title, _, body = docstring.partition("\n")
    parts = [
        f"## {script.stem}",
        f"**{_escape(title.strip())}** ([`examples/{script.name}`]({SOURCE}/{script.name}))",
        _fence_indented_blocks(body.strip("\n")),
    ]
    for figure in figures:
        if (FIGURES / figure).exists():
            parts.append(f"![{script.stem}: {figure}](figures/{figure})")
    printout = FIGURES / f"{script.stem}.txt"
    if printout.exists():
        parts.append(f"What it prints:\n\n```text\n{printout.read_text().rstrip()}\n```")
    source = script.read_text().rstrip()
    parts.append(
        f'??? example "Source: examples/{script.name}"\n\n    ```python\n'
        + "\n".join(f"    {line}" if line else "" for line in source.splitlines())
        + "\n    ```"
    )
    return "\n\n".join(parts)


def gallery_markdown() -> str:
    figures = _figures_by_example()
    sections = [
        _section(script, figures.get(script.stem, [])) for script in sorted(EXAMPLES.glob("*.py"))
    ]
    return INTRO + "\n\n" + "\n\n".join(sections) + "\n"


def on_files(files, config, **kwargs):
    files.append(File.generated(config, "gallery.md", content=gallery_markdown()))
    return files
