"""MkDocs hook: files the site needs that live outside docs/, and links that differ there.

- The benchmark figures stay where ``make bench`` writes them, ``benchmarks/results/*.png``; the
  guides link them by that path (``../benchmarks/results/X.png``, which works on GitHub too)
  and the site publishes each as ``figures/benchmarks/X.png``.
- The README is the tutorial, the site's first page (``docs/index.md`` includes it). It links
  the guides by their GitHub address so that the links work on the package index; in the site
  those links go to the site's own pages.
- The code blocks are highlighted at build time by Pygments (``pymdownx.highlight``); its
  style sheet is written into the site as ``css/pygments.css`` (no script, no outside host).
"""

import re
from pathlib import Path

from mkdocs.structure.files import File
from pygments.formatters import HtmlFormatter

ROOT = Path(__file__).resolve().parents[2]
BENCHMARK_FIGURES = ROOT / "benchmarks" / "results"
OWN_PAGES = re.compile(r"\]\(https://github\.com/liesample/liesample/blob/main/docs/([^)\s]+)\)")
BENCHMARK_LINK = re.compile(r"\]\((?:\.\./)?benchmarks/results/([\w.-]+\.png)\)")


def on_files(files, config, **kwargs):
    for figure in sorted(BENCHMARK_FIGURES.glob("*.png")):
        files.append(
            File.generated(
                config, f"figures/benchmarks/{figure.name}", abs_src_path=str(figure)
            )
        )
    style = HtmlFormatter(style="default").get_style_defs(".highlight")
    files.append(File.generated(config, "css/pygments.css", content=style))
    return files


def on_page_markdown(markdown: str, page, **kwargs) -> str:
    depth = page.file.src_uri.count("/")
    up = "../" * depth
    markdown = OWN_PAGES.sub(lambda m: f"]({up}{m[1]})", markdown)
    return BENCHMARK_LINK.sub(lambda m: f"]({up}figures/benchmarks/{m[1]})", markdown)
