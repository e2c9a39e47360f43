"""Integrators: one-step maps on coadjoint orbits (each declaring its order, orbit preservation,
stability limit and form), adaptive substeps, the step-size bound, the bias model, the one
chain loop and semimartingale drivers."""

from liesample.integrators.orbit import (
    DEFAULT_INTEGRATOR,
    INTEGRATORS,
    Integrator,
    get_integrator,
)

__all__ = ["DEFAULT_INTEGRATOR", "INTEGRATORS", "Integrator", "get_integrator"]
