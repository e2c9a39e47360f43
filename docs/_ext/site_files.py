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
OWN_PAGES = re.compile(
    r'href="https://github\.com/liesample/liesample/blob/main/docs/([^"#]+\.md)(#[^"]*)?"'
)
BENCHMARK_LINK = re.compile(r"\]\((?:\.\./)?benchmarks/results/([\w.-]+\.png)\)")


def on_files(files, config, **kwargs):
    for figure in sorted(BENCHMARK_FIGURES.glob("*.png")):
        files.append(
            File.generated(config, f"figures/benchmarks/{figure.name}", abs_src_path=str(figure))
        )
    style = HtmlFormatter(style="default").get_style_defs(".highlight")
    files.append(File.generated(config, "css/pygments.css", content=style))
    return files


def on_page_markdown(markdown: str, page, **kwargs) -> str:
    up = "../" * page.file.src_uri.count("/")
    return BENCHMARK_LINK.sub(lambda m: f"]({up}figures/benchmarks/{m[1]})", markdown)


def on_page_content(html: str, page, files, **kwargs) -> str:
    """The README's links to the guides on GitHub, as links to the site's own pages (the README
    arrives through pymdownx.snippets, after ``on_page_markdown``, hence on the HTML)."""

    def local(match: re.Match) -> str:
        target = files.get_file_from_path(match[1])
        if target is None:  # not a page of the site: keep the GitHub address
            return match[0]
        return f'href="{target.url_relative_to(page.file)}{match[2] or ""}"'

    return OWN_PAGES.sub(local, html)
