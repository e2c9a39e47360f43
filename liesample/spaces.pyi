"""``liesample.spaces`` for type checkers: the import hook of ``liesample`` makes it
the module ``liesample.geometry.spaces``, so it has that module's names."""

from liesample.geometry.spaces import *  # noqa: F403
from liesample.geometry.spaces import __all__ as __all__
