"""BlackJAX-shaped samplers: ``init``, ``build_kernel``, ``as_top_level_api``."""

from liesample.samplers.spins_heat_bath import heisenberg_heat_bath
from liesample.samplers.spins_metropolis import heisenberg_metropolis
from liesample.samplers.spins_wolff import heisenberg_wolff
