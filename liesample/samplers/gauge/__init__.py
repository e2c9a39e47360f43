"""Samplers of lattice gauge fields (:func:`liesample.systems.wilson_gauge`): heat bath with
over-relaxation, and the Wilson (gradient) flow that smooths a field for its observables."""
