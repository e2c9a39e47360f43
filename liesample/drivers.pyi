"""``liesample.drivers`` for type checkers: the import hook of ``liesample`` makes it
the module ``liesample.integrators.drivers``, so it has that module's names."""

from liesample.integrators.drivers import *  # noqa: F403
from liesample.integrators.drivers import __all__ as __all__
