"""``liesample.diagnostics`` for type checkers: the import hook of ``liesample`` makes it
the module ``liesample.analysis.diagnostics``, so it has that module's names."""

from liesample.analysis.diagnostics import *  # noqa: F403
from liesample.analysis.diagnostics import __all__ as __all__
