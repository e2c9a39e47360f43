"""The built documentation site (``make docs`` writes it into site/) is what a reader gets: the
tutorial first, figures that load, rendered mathematics, the gallery, one API entry per
parameter, and nothing fetched from an outside host. Skipped when site/ was not built."""

import functools
import re
from html.parser import HTMLParser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SITE = ROOT / "site"

pytestmark = pytest.mark.skipif(
    not (SITE / "index.html").exists(), reason="site/ not built (run `make docs`)"
)


class _Page(HTMLParser):
    """The tags of one page with their attributes, and its text."""

    def __init__(self):
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))

    def handle_data(self, data):
        self.text.append(data)


@functools.cache  # each page is parsed once for all the tests
def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text())
    return page


def _page(name: str) -> _Page:
    return _parse(SITE / name / "index.html" if name else SITE / "index.html")


def _pages():
    return sorted(SITE.rglob("*.html"))


def test_the_first_page_is_the_tutorial():
    """The README's walk-through is the site's first page, with the guides reachable from it."""
    page = _page("")
    text = " ".join(page.text)
    assert "Two commands" in text and "Run in float64" in text
    links = {attrs.get("href", "") for tag, attrs in page.tags if tag == "a"}
    assert "mathematics/" in links  # the README's GitHub links lead to the site's own pages
    assert not any(
        link.startswith("https://github.com/liesample/liesample/blob/main/docs/") for link in links
    )


def test_at_least_eight_figures_that_resolve():
    found, missing = set(), []
    for path in _pages():
        for tag, attrs in _parse(path).tags:
            if tag != "img":
                continue
            target = (path.parent / attrs["src"]).resolve()
            if target.is_file() and target.is_relative_to(SITE):
                found.add(target)
            else:
                missing.append(f"{path.relative_to(SITE)}: {attrs['src']}")
    assert not missing, f"images that do not resolve to files in site/: {missing}"
    assert len(found) >= 8, sorted(found)


@pytest.mark.parametrize("name", ["mathematics", "zeitlin", "groups"])
def test_mathematics_is_rendered_as_mathml(name):
    page = _page(name)
    assert sum(tag == "math" for tag, _ in page.tags) >= 10
    # No formula left as LaTeX source (arithmatex's delimiters or a bare $$).
    text = " ".join(page.text)
    assert "$$" not in text and "\\(" not in text and "\\[" not in text


def test_the_gallery_shows_every_example_with_its_source():
    page = _page("gallery")
    headings = {attrs.get("id") for tag, attrs in page.tags if tag == "h2"}
    scripts = {path.stem for path in (ROOT / "examples").glob("*.py")}
    assert scripts <= {h.replace("-", "_") for h in headings if h}, scripts
    text = "".join(page.text)
    assert "def main(" in text  # the sources are on the page
    assert sum(tag == "img" for tag, _ in page.tags) >= 8


def _parameters(html: str, function: str) -> dict[str, str]:
    """``{name: type}`` of the Parameters list of ``function``'s API entry."""
    start = html.index(f'id="{function}"')
    end = html.find('class="doc doc-object doc-function"', start + 1)
    entry = html[start : end if end > 0 else None]
    section = entry[entry.index("Parameters:") :]
    section = section[: section.find("Returns:")] if "Returns:" in section else section
    items = re.findall(
        r"<b><code>(\w+)</code></b>\s*(?:\((<code>.*?</code>))?", section, flags=re.DOTALL
    )
    return {name: re.sub(r"<[^>]+>|\s+", "", kind) for name, kind in items}


def test_grouped_parameters_get_their_own_entries_and_types():
    """``liesample.sample`` documents ``algorithm, rng_key, initial_positions, num_draws`` in one
    numpydoc item; the reference shows each with its own annotation."""
    html = (SITE / "api" / "run" / "index.html").read_text()
    parameters = _parameters(html, "liesample.run.runner.sample")
    for name in ("algorithm", "rng_key", "initial_positions", "num_draws", "coords", "attrs"):
        assert name in parameters, sorted(parameters)
    assert parameters["algorithm"].startswith("SamplingAlgorithm")
    assert not parameters["rng_key"].startswith("SamplingAlgorithm")
    assert parameters["num_draws"].startswith("int")
    assert parameters["coords"] != parameters["attrs"]


def test_no_asset_from_an_outside_host():
    """The site reads offline: no script, style sheet, image or font from another host."""
    outside = re.compile(r"^(?:[a-z]+:)?//")
    offenders = []
    for path in _pages():
        for tag, attrs in _parse(path).tags:
            source = attrs.get("src") if tag in {"script", "img", "iframe"} else None
            if tag == "link" and attrs.get("rel") in {"stylesheet", "preload", "icon"}:
                source = attrs.get("href")
            if source and outside.match(source):
                offenders.append(f"{path.relative_to(SITE)}: <{tag}> {source}")
    for path in SITE.rglob("*.css"):
        offenders += [
            f"{path.relative_to(SITE)}: {url}"
            for url in re.findall(r"url\(['\"]?((?:https?:)?//[^)'\"]+)", path.read_text())
        ]
    assert not offenders, offenders
