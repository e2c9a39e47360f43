"""Griffe extension for the API reference: the docstrings cite code with Sphinx roles
(:func:`name`, :class:`name`, ...), which Markdown would print literally; each becomes a code
span of the name (a leading ``~`` dropped)."""

import re

import griffe

_ROLE = re.compile(r":(?:attr|class|data|exc|func|meth|mod|obj):`~?([^`]+)`")


class SphinxRoles(griffe.Extension):
    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = _ROLE.sub(r"`\1`", obj.docstring.value)
