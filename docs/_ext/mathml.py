"""MkDocs hook: the pages' LaTeX, rendered as MathML when the site is built.

The guides write mathematics as LaTeX, ``$…$`` inline and ``$$…$$`` displayed.
``pymdownx.arithmatex`` (generic mode) leaves each formula in the HTML as
``<span class="arithmatex">\\(…\\)</span>`` or ``<div class="arithmatex">\\[…\\]</div>``; this hook
replaces each by the MathML that ``latex2mathml`` makes of it. Browsers draw MathML themselves,
so the pages need no script and no outside host to show their formulas.
"""

import html
import re

from latex2mathml.converter import convert

_FORMULA = re.compile(
    r'<(?P<tag>span|div) class="arithmatex">\s*'
    r"(?:\\\((?P<inline>.*?)\\\)|\\\[(?P<display>.*?)\\\])\s*</(?P=tag)>",
    flags=re.DOTALL,
)


def _mathml(match: re.Match) -> str:
    display = match["display"] is not None
    latex = html.unescape(match["display"] if display else match["inline"])
    mathml = convert(latex.strip(), display="block" if display else "inline")
    kind = "math-display" if display else "math-inline"
    tag = "div" if display else "span"
    return f'<{tag} class="{kind}">{mathml}</{tag}>'


def on_page_content(html_text: str, **kwargs) -> str:
    return _FORMULA.sub(_mathml, html_text)
