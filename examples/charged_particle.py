"""The charged particle in three scenes (paper, ``sec:brownian-particle``; MATH.md §3).

1. **Cyclotron and drift** (constant ``B = ẑ``, ``V = −E·q``, no noise): the orbit is a
   cycloid — gyration at ``ω = eB/m`` plus the ``E×B`` drift ``E×B/B²`` — and with the derived
   friction switched on it spirals down while drifting.
2. **Magnetic bottle** (``A = ½(−q₂ g, q₁ g, 0)``, ``g = 1 + q₃²/2``, ``B = curl A``): the particle
   gyrates around the axis and is reflected where the field is strong; ``|p|`` is conserved.
3. **Brownian particle** (quadratic ``V``, ``β = 1``, ``σ = 1``, with and without a strong
   field): the ``q``-marginal is the same Gibbs law whatever the field.

Run: ``python examples/charged_particle.py [output.png]``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.figure import Figure

from liesample.systems.charged_particle import charged_particle, charged_particle_path

jax.config.update("jax_enable_x64", True)


def bottle_potential(q):
    g = 1.0 + 0.5 * q[2] ** 2
    return 0.5 * jnp.array([-q[1] * g, q[0] * g, 0.0])


def main(output="charged_particle.png", num_steps=4000, seed=0):
    """Simulate the three scenes, write a figure to ``output`` and return a summary."""
    key = jax.random.key(seed)
    field = np.array([0.0, 0.0, 2.0])
    electric = jnp.array([0.3, 0.0, 0.0])
    drift_system = charged_particle(lambda q: -electric @ q, magnetic_field=field)
    z0 = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0])
    cycloid = charged_particle_path(
        drift_system, key, z0, step_size=0.01, num_steps=num_steps, sigma=0.0
    ).states
    damped = charged_particle_path(
        drift_system, key, z0, step_size=0.01, num_steps=num_steps, sigma=0.0, theta=0.2
    ).states

    bottle = charged_particle(
        lambda q: 0.0 * q[0], vector_potential=bottle_potential, charge=3.0, dimension=3
    )
    mirror = charged_particle_path(
        bottle,
        key,
        np.array([0.4, 0.0, 0.0, 0.0, 0.6, 0.5]),
        step_size=0.01,
        num_steps=2 * num_steps,
        sigma=0.0,
    )
    speed = np.linalg.norm(np.asarray(mirror.states[:, 3:]), axis=1)

    stiffness = jnp.array([1.0, 4.0])
    brownian = {}
    for label, matrix in (("no field", None), ("strong field", [[0.0, 4.0], [-4.0, 0.0]])):
        kwargs = {"magnetic_field": matrix} if matrix is not None else {"dimension": 2}
        system = charged_particle(lambda q: 0.5 * jnp.sum(stiffness * q * q), **kwargs)
        brownian[label] = np.asarray(
            charged_particle_path(
                system,
                jax.random.fold_in(key, 1),
                np.zeros(4),
                step_size=0.05,
                num_steps=25 * num_steps,
                beta=1.0,
                sigma=1.0,
                thinning=5,
            ).states[:, :2]
        )

    figure = Figure(figsize=(14, 4.2), layout="constrained")
    drift_axes, bottle_axes, law_axes = figure.subplots(1, 3)
    drift_axes.plot(cycloid[:, 0], cycloid[:, 1], lw=0.9, label="no friction: cycloid")
    drift_axes.plot(damped[:, 0], damped[:, 1], lw=0.9, label="derived friction θ = 0.2")
    drift_axes.set(
        xlabel="q₁",
        ylabel="q₂",
        title="gyration + E×B drift (B = 2ẑ, E = 0.3x̂)",
    )
    drift_axes.legend(fontsize=8)
    states = np.asarray(mirror.states)
    bottle_axes.plot(states[:, 0], states[:, 2], lw=0.5)
    bottle_axes.set(
        xlabel="q₁",
        ylabel="q₃ (axis of the bottle)",
        title=f"magnetic bottle: |p| kept to {np.ptp(speed) / speed[0]:.0e} (relative)",
    )
    for label, samples in brownian.items():
        law_axes.hist(samples[:, 1], bins=60, density=True, histtype="step", label=label)
    grid = np.linspace(-2.0, 2.0, 200)
    law_axes.plot(grid, np.sqrt(4.0 / (2 * np.pi)) * np.exp(-2.0 * grid**2), "k--", lw=1)
    law_axes.set(
        xlabel="q₂", ylabel="density", title="Gibbs marginal N(0, 1/4), with and without field"
    )
    law_axes.legend(fontsize=8)
    figure.savefig(output, dpi=120)
    return {
        "output": str(output),
        "bottle_speed_drift": float(np.ptp(speed) / speed[0]),
        "bottle_converged": bool(mirror.converged),
        "q2_variance": {label: float(np.var(s[:, 1])) for label, s in brownian.items()},
    }


if __name__ == "__main__":
    print(main(Path(sys.argv[1]) if len(sys.argv) > 1 else "charged_particle.png"))
