"""Griffe extension for the API reference: one entry per parameter of a grouped NumPy-style item.

The docstrings document related parameters together, as numpydoc allows::

    coords, attrs
        Coordinates by dim name, and extra attributes for the tree.
    step_size, num_steps : float > 0, int ≥ 1
        ...

Griffe's NumPy parser splits the names but gives every one of them the first name's type and
default from the signature. This extension rewrites each such item of a ``Parameters`` or
``Other Parameters`` section, before it is parsed, into one item per name: a type written in
the docstring is kept (paired name by name when it lists one type per name, as in the second
item above), otherwise the parser takes each name's own annotation and default from the
signature; the text is repeated under each name, and the names after the first say which
entry they share it with.
"""

import re

import griffe

_SECTIONS = {"parameters", "other parameters"}
_GROUP = re.compile(r"^(?P<names>\w+(?:, \w+)+)(?:\s*:\s*(?P<type>.+))?$")
_DEFAULT = re.compile(r",\s+default(?: |: |=).*$")


def _top_level_split(text: str) -> list[str]:
    """``text`` split at the commas outside brackets and quotes, each part stripped."""
    parts, depth, start = [], 0, 0
    for index, char in enumerate(text):
        if char in "([{":
            depth += 1
        elif char in ")]}":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append(text[start:index])
            start = index + 1
    parts.append(text[start:])
    return [part.strip() for part in parts]


def _types(written: str | None, count: int) -> list[str | None]:
    """The type of each of ``count`` names, from the group's written type (or ``None``)."""
    if not written:
        return [None] * count
    # One default for several names cannot be right for each: the signature gives each its own.
    written = _DEFAULT.sub("", written)
    optional = written.endswith(", optional")
    if optional:
        written = written[: -len(", optional")]
    parts = _top_level_split(written)
    types = parts if len(parts) == count else [written] * count
    return [f"{kind}, optional" if optional else kind for kind in types]


def _split_item(header: re.Match, body: list[str]) -> list[str]:
    """The lines of one item per name for the grouped item ``header`` with text ``body``."""
    names = header["names"].split(", ")
    lines = []
    for position, (name, kind) in enumerate(zip(names, _types(header["type"], len(names)))):
        lines.append(f"{name} : {kind}" if kind else name)
        if position and body:
            indent = body[0][: len(body[0]) - len(body[0].lstrip())] or "    "
            lines.append(f"{indent}(Described with ``{names[0]}``.)")
        lines.extend(body)
    return lines


def split_grouped_parameters(text: str) -> str:
    """``text`` (a cleaned NumPy-style docstring) with its grouped parameter items split."""
    lines = text.splitlines()
    out, section, index = [], None, 0
    while index < len(lines):
        line = lines[index]
        following = lines[index + 1] if index + 1 < len(lines) else ""
        if line.strip() and re.fullmatch(r"-{3,}", following.strip()):
            section = line.strip().lower()
        header = _GROUP.match(line) if section in _SECTIONS else None
        if header is None:
            out.append(line)
            index += 1
            continue
        end = index + 1
        while end < len(lines) and (not lines[end].strip() or lines[end].startswith(" ")):
            end += 1
        while end > index + 1 and not lines[end - 1].strip():  # keep trailing blanks outside
            end -= 1
        out.extend(_split_item(header, lines[index + 1 : end]))
        index = end
    return "\n".join(out)


class GroupedParameters(griffe.Extension):
    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = split_grouped_parameters(obj.docstring.value)
