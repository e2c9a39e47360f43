"""``liesample.accuracy`` for type checkers: the import hook of ``liesample`` makes it
the module ``liesample.integrators.accuracy``, so it has that module's names."""

from liesample.integrators.accuracy import *  # noqa: F403
from liesample.integrators.accuracy import __all__ as __all__
