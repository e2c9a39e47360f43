"""``liesample.symplectic`` for type checkers: the import hook of ``liesample`` makes it
the module ``liesample.dynamics.symplectic``, so it has that module's names."""

from liesample.dynamics.symplectic import *  # noqa: F403
