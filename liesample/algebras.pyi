"""``liesample.algebras`` for type checkers: the import hook of ``liesample`` makes it
the module ``liesample.geometry.algebras``, so it has that module's names."""

from liesample.geometry.algebras import *  # noqa: F403
