"""Convergence checks on every posterior variable (liesample.analysis.convergence).

The vectorised R-hat and ESS agree with ArviZ's; through ``liesample.sample``, chains in mirror
modes, a split mixture and a flat (improper) target each raise the warning, naming the
variables, and a well-mixed run raises none. A variable larger than ``MAX_RANKED_ELEMENTS``
(a lattice) is ranked in part and screened whole: the ranked elements are bounded, and a
displaced element, a slowly mixing one, many displaced ones and a stuck chain are all reported.
"""

import re
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from arviz_stats.base import array_stats

import liesample
from liesample.analysis import convergence
from liesample.analysis.convergence import (
    MAX_RANKED_ELEMENTS,
    MAX_RHAT,
    convergence_warnings,
    rank_diagnostics,
    screen,
)
from liesample.spaces import Euclidean, Sphere


def _convergence_messages(record):
    return [str(w.message) for w in record if "convergence checks" in str(w.message)]


def _sample(sampler, starts, num_draws, **options):
    """``liesample.sample`` and its convergence messages. The warning tests with a given step
    run no warm-up (``num_warmup=0``, one compiled program fewer): their chains start in the
    modes they stay in, or drift from the start, so discarding steps first changes nothing the
    checks see."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        tree = liesample.sample(
            sampler, jax.random.key(3), starts, num_draws, progress_bar=False, **options
        )
    return tree, _convergence_messages(record)


@pytest.mark.parametrize("chains, draws", [(4, 200), (1, 101), (3, 5), (2, 4), (8, 51)])
def test_rank_diagnostics_agree_with_arviz(chains, draws):
    rng = np.random.default_rng(7)
    noise = rng.normal(size=(5, chains, draws))
    walk = np.cumsum(noise, axis=-1) * 0.3 + noise  # autocorrelated
    x = np.concatenate(
        [noise, walk, np.round(walk), walk + np.arange(chains)[:, None], -walk], axis=0
    )
    r_hat, bulk, tail = rank_diagnostics(x)
    with np.errstate(all="ignore"):
        expected = (
            array_stats.rhat(x),
            array_stats.ess(x, method="bulk"),
            array_stats.ess(x, method="tail", prob=(0.05, 0.95)),
        )
    for mine, theirs in zip((r_hat, bulk, tail), expected, strict=True):
        np.testing.assert_allclose(mine, theirs, rtol=1e-10, equal_nan=True)


def test_messages_name_elements_and_say_what_cannot_be_checked():
    rng = np.random.default_rng(0)
    iid = rng.normal(size=(4, 1000, 3))
    assert convergence_warnings({"mu": iid, "casimir": np.ones((4, 1000))}) == []
    modes = iid + 8.0 * np.array([1, 1, 1, -1])[:, None, None]
    (rhat, ess) = convergence_warnings({"mu": modes})
    assert rhat.startswith(f"R-hat > {MAX_RHAT:g} for 3 element(s): mu[")
    assert "ESS below 100 per chain" in ess
    # within law groups (one per mode) the same draws are well mixed
    assert convergence_warnings({"mu": modes}, groups=[0, 0, 0, 1]) == []
    assert convergence_warnings({"mu": modes}, groups=[[3], [0, 1, 2]]) == []
    (one,) = convergence_warnings({"mu": iid[:1]})
    assert "R-hat cannot be computed: the run has one chain" in one
    (alone,) = convergence_warnings({"mu": iid}, groups=[0, 1, 2, 3])
    assert "no two chains sample one law" in alone
    (few,) = convergence_warnings({"mu": iid[:, :3]})
    assert "cannot be checked with 3 draw(s)" in few
    broken = iid.copy()
    broken[0, 5, 1] = np.nan
    assert convergence_warnings({"mu": broken}) == [
        "1 element(s) hold non-finite draws and were not checked"
    ]
    complex_draws = iid + 1j * modes
    assert "U.imag[" in convergence_warnings({"U": complex_draws})[0]


def test_mirror_modes_on_the_sphere_warn():
    """An axial (Watson) law on S², κ = 50: chains started at ±e₃ stay in their modes."""

    def logdensity(x):
        return 50.0 * x[2] ** 2

    sampler = liesample.geometric_hmc(logdensity, Sphere(2), 0.1, 5)
    starts = jnp.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]] * 2)
    tree, messages = _sample(sampler, starts, 300, num_warmup=0)
    assert abs(float(tree.posterior["mu"].sel(component="z").mean())) < 0.5  # pooled: ~0
    assert len(messages) == 1 and "R-hat > 1.01" in messages[0] and "mu[2]" in messages[0]


@pytest.mark.slow
def test_rigid_body_chains_at_opposite_minima_warn():
    """β = 40, chains at ±e₃ (equal energies, so the energy's R-hat cannot see it): the pooled
    E[μ₃] of a 3/1 split is ~0.5, the exact one 0."""
    system = liesample.systems.rigid_body(inertia=(1.0, 2.0, 4.0))
    sampler = liesample.adjusted_lie_poisson(system, beta=40.0)
    starts = jnp.array([[0.0, 0.0, 1.0]] * 3 + [[0.0, 0.0, -1.0]])
    tree, messages = _sample(sampler, starts, 200, num_warmup=200)
    assert float(tree.posterior["mu"].sel(component="z").mean()) > 0.3
    assert len(messages) == 1 and "R-hat > 1.01" in messages[0] and "mu[2]" in messages[0]


def test_split_mixture_warns():
    """Equal Gaussians at ±8, chains split 3/1: the pooled mean is ~4, the exact one 0."""

    def logdensity(x):
        return jnp.logaddexp(-0.5 * (x[0] - 8.0) ** 2, -0.5 * (x[0] + 8.0) ** 2)

    sampler = liesample.geometric_hmc(logdensity, Euclidean((1,)), 0.5, 4)
    starts = jnp.array([[8.0], [8.0], [8.0], [-8.0]])
    tree, messages = _sample(sampler, starts, 300, num_warmup=0, var_name="x")
    assert float(tree.posterior["x"].mean()) > 3.0
    assert len(messages) == 1 and "R-hat > 1.01" in messages[0] and "x[0]" in messages[0]


def test_flat_target_warns():
    """A flat (improper) log-density: the chains drift apart."""
    sampler = liesample.geometric_hmc(lambda x: 0.0 * x.sum(), Euclidean((2,)), 0.5, 4)
    starts = jnp.zeros((4, 2))
    _, messages = _sample(sampler, starts, 300, num_warmup=0, var_name="x")
    assert len(messages) == 1 and "R-hat > 1.01" in messages[0] and "drift" in messages[0]


def test_well_mixed_run_is_quiet():
    """A standard Gaussian in R² by HMC (time 1.5, far from the resonance at π where each
    draw is nearly minus the last: that one the check reports): no convergence warning."""
    sampler = liesample.geometric_hmc(lambda x: -0.5 * jnp.sum(x**2), Euclidean((2,)), 0.5, 3)
    starts = jax.random.normal(jax.random.key(0), (4, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tree = liesample.sample(
            sampler, jax.random.key(3), starts, 500, num_warmup=100, progress_bar=False
        )
    assert tree.posterior["mu"].shape == (4, 500, 2)


# A lattice-sized variable: (30, 40) elements, 4 chains of 1000 iid standard normal draws. The
# rank R-hat of iid draws exceeds 1 by O(χ²₇/(7n)) with 8 split chains of n = 500 draws: the
# largest of 1200 elements stays near 1.003, well below MAX_RHAT, and every bulk and tail ESS
# near 4000, far above 400; the defects below move their element's R-hat to about 1.1 and its
# ESS to about 60 (AR(1) with ρ = 0.97: ESS ≈ 4000 (1 − ρ)/(1 + ρ)).
_LATTICE = (30, 40)


@pytest.fixture(scope="module")
def lattice_draws():
    return np.random.default_rng(11).normal(size=(4, 1000, *_LATTICE))


@pytest.fixture
def ranked_counts(monkeypatch):
    """The number of elements each call of ``rank_diagnostics`` receives."""
    counts = []

    def counted(x):
        counts.append(len(x))
        return rank_diagnostics(x)

    monkeypatch.setattr(convergence, "rank_diagnostics", counted)
    return counts


def test_a_large_variable_is_ranked_in_part(lattice_draws, ranked_counts):
    assert convergence_warnings({"x": lattice_draws}) == []
    assert ranked_counts == [MAX_RANKED_ELEMENTS]  # of 1200 varying elements
    small = lattice_draws[:, :, :2]  # 80 elements: all ranked, as before
    assert convergence_warnings({"x": small}) == [] and ranked_counts[-1] == 80


def test_a_large_variable_still_shows_one_displaced_or_slow_element(lattice_draws, ranked_counts):
    draws = lattice_draws.copy()
    draws[0, :, 17, 23] += 1.0  # one chain sits elsewhere at one site
    rho, noise = 0.97, draws[:, :, 4, 5]  # and one site mixes slowly (AR(1), unit variance)
    slow = np.empty_like(noise)
    slow[:, 0] = noise[:, 0]
    for t in range(1, noise.shape[1]):
        slow[:, t] = rho * slow[:, t - 1] + np.sqrt(1 - rho**2) * noise[:, t]
    draws[:, :, 4, 5] = slow
    rhat, ess = convergence_warnings({"x": draws})
    # the slow site may show in R-hat too (its chains have few independent draws each)
    named = lambda message: set(re.findall(r"x\[\d+,\d+\]", message))
    assert rhat.startswith(f"R-hat > {MAX_RHAT:g} for ")
    # 2 of 8 split chains shifted by one sd: the means vary by 3/14, R-hat ≈ √(1 + 3/14) ≈ 1.1
    assert 1.05 < float(re.search(r"x\[17,23\]: ([0-9.]+)", rhat)[1]) < 1.2
    assert named(rhat) <= {"x[17,23]", "x[4,5]"}
    assert ess.startswith("ESS below 100 per chain") and named(ess) <= {"x[17,23]", "x[4,5]"}
    assert "x[4,5]: bulk" in ess
    assert max(ranked_counts) <= MAX_RANKED_ELEMENTS


def test_a_large_variable_counts_every_displaced_element(lattice_draws):
    # more displaced sites than are ranked: the screened R-hat of the others reports them too
    draws = lattice_draws.copy()
    draws[0, :, :10] += 1.0  # 400 sites
    (rhat, *_) = convergence_warnings({"x": draws})
    assert rhat.startswith(f"R-hat > {MAX_RHAT:g} for 400 element(s): x[")


def test_a_stuck_chain_shows_in_a_large_variable(lattice_draws):
    draws = lattice_draws.copy()
    draws[2] = draws[2, :1]  # chain 2 never moves from its first draw
    (rhat, *_) = convergence_warnings({"x": draws})
    assert rhat.startswith(f"R-hat > {MAX_RHAT:g} for ")


def test_the_screen_is_plain_split_rhat_and_lag_one_autocorrelation():
    rng = np.random.default_rng(2)
    x = rng.normal(size=(3, 2, 100))
    r_hat, rho = screen(x)
    with np.errstate(all="ignore"):
        expected = array_stats.rhat(x, method="split")
    assert np.all(r_hat >= expected - 1e-12)  # the larger of values' and distances' R-hat
    halves = np.concatenate([x[..., :50], x[..., 50:]], axis=1)
    c = halves - halves.mean(-1, keepdims=True)
    np.testing.assert_allclose(
        rho, (c[..., 1:] * c[..., :-1]).sum((1, 2)) / (c * c).sum((1, 2)), rtol=1e-12
    )
    with pytest.raises(ValueError, match="draws >= 4"):
        screen(x[..., :3])
