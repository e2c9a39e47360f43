"""``liesample.sharding`` for type checkers: the import hook of ``liesample`` makes it
the module ``liesample.run.sharding``, so it has that module's names."""

from liesample.run.sharding import *  # noqa: F403
from liesample.run.sharding import __all__ as __all__
