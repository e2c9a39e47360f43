"""``liesample.stability`` for type checkers: the import hook of ``liesample`` makes it
the module ``liesample.integrators.stability``, so it has that module's names."""

from liesample.integrators.stability import *  # noqa: F403
from liesample.integrators.stability import __all__ as __all__
