"""BlackJAX-shaped samplers: ``init``, ``build_kernel``, ``as_top_level_api``.

Every sampler's ``info`` follows one contract, ``is_divergent``, ``acceptance_rate`` and
``energy`` plus its own fields (:mod:`liesample.samplers.contract`, which also holds the
:class:`~liesample.samplers.contract.Sampler` object and the ``help()``-friendly API factory).
"""

from liesample.samplers.spins_heat_bath import heisenberg_heat_bath
from liesample.samplers.spins_metropolis import heisenberg_metropolis
from liesample.samplers.spins_wolff import heisenberg_wolff
