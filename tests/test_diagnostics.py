"""Tests for liesample.analysis.diagnostics and liesample.analysis.plots on synthetic chains with
known answers."""

from collections import namedtuple

import numpy as np
import pytest
import xarray as xr
from scipy import integrate, stats
from scipy.signal import lfilter

from liesample import diagnostics as diag
from liesample.analysis import plots

Info = namedtuple("Info", ["energy", "casimir_error", "nonfinite", "acceptance_rate"])


def ar1(rng, phi, shape):
    """Stationary AR(1) x_t = phi x_{t-1} + sqrt(1 - phi^2) eps_t along the last axis (var 1)."""
    eps = rng.standard_normal(shape)
    s = np.sqrt(1.0 - phi**2)
    eps[..., 0] /= s  # x_0 = eps_0 ~ N(0, 1): the chain starts in stationarity
    return lfilter([s], [1.0, -phi], eps, axis=-1)


def tau_ar1(phi):
    return (1.0 + phi) / (1.0 - phi)


def tau_indicator(phi, p):
    """Integrated autocorrelation time of 1{x_t <= q_p} for the Gaussian AR(1).

    Cov(1{x_0<=q}, 1{x_k<=q}) = Phi_2(q, q; r) - p^2 with r = phi^k, and
    d/dr Phi_2(q, q; r) = exp(-q^2 / (1 + r)) / (2 pi sqrt(1 - r^2)).
    """
    q = stats.norm.ppf(p)

    def dens(s):
        return np.exp(-q * q / (1.0 + s)) / (2.0 * np.pi * np.sqrt(1.0 - s * s))

    rho = []
    k = 1
    while phi**k > 1e-15:
        rho.append(integrate.quad(dens, 0.0, phi**k)[0] / (p * (1.0 - p)))
        k += 1
    return 1.0 + 2.0 * sum(rho)


def make_run(rng, chains=3, draws=50):
    mu = rng.standard_normal((chains, draws, 3))
    mu /= np.linalg.norm(mu, axis=-1, keepdims=True)
    nonfinite = np.zeros((chains, draws), bool)
    nonfinite[1, -5:] = True
    info = Info(
        energy=rng.standard_normal((chains, draws)),
        casimir_error=np.abs(rng.standard_normal((chains, draws))) * 1e-12,
        nonfinite=nonfinite.astype(np.int8),  # not bool on purpose: stored as bool
        acceptance_rate=rng.uniform(size=(chains, draws)),
    )
    return mu, info


# --------------------------------------------------------------------------- to_datatree


def test_to_datatree_groups_dims_coords_and_netcdf_roundtrip(tmp_path):
    rng = np.random.default_rng(0)
    mu, info = make_run(rng)
    dt = diag.to_datatree(
        mu, info, step_size=0.05, thinning=10, attrs={"sampler": "lpl", "unused": None}
    )
    assert set(dt.children) == {"posterior", "sample_stats"}
    post = dt["posterior"]
    assert post["mu"].dims == ("chain", "draw", "component")
    assert post["mu"].shape == (3, 50, 3)
    assert list(post["component"].values) == ["x", "y", "z"]
    np.testing.assert_array_equal(post["mu"].values, mu)

    ss = dt["sample_stats"]
    assert set(ss.data_vars) == {"energy", "diverging", "acceptance_rate", "casimir_error"}
    assert ss["diverging"].dtype == bool
    assert ss["diverging"].dims == ("chain", "draw")
    assert int(ss["diverging"].sum()) == 5
    np.testing.assert_array_equal(ss["energy"].values, info.energy)
    assert dt.attrs["step_size"] == 0.05
    assert dt.attrs["thinning"] == 10
    assert dt.attrs["sampler"] == "lpl"
    assert "unused" not in dt.attrs
    assert ss.attrs["step_size"] == 0.05

    path = tmp_path / "x.nc"
    dt.to_netcdf(path, engine="h5netcdf")  # the engine liesample declares
    back = xr.open_datatree(path)
    try:
        assert back["sample_stats"]["diverging"].dtype == bool
        np.testing.assert_array_equal(back["posterior"]["mu"].values, mu)
        np.testing.assert_array_equal(
            back["sample_stats"]["casimir_error"].values, info.casimir_error
        )
        assert list(back["posterior"]["component"].values) == ["x", "y", "z"]
        assert back.attrs["sampler"] == "lpl"
    finally:
        back.close()


def test_to_datatree_without_info_and_dict_info_and_other_event_shapes(tmp_path):
    rng = np.random.default_rng(1)
    dt = diag.to_datatree(rng.standard_normal((2, 10, 3)))
    assert list(dt.children) == ["posterior"]
    dt.to_netcdf(tmp_path / "no_info.nc", engine="h5netcdf")

    # dict info without acceptance_rate; event shape (4,) gets integer coordinates
    info = {"energy": np.zeros((2, 10)), "nonfinite": np.zeros((2, 10), bool)}
    dt = diag.to_datatree(rng.standard_normal((2, 10, 4)), info, var_name="m")
    assert list(dt["posterior"]["component"].values) == [0, 1, 2, 3]
    assert set(dt["sample_stats"].data_vars) == {"energy", "diverging"}

    # scalar event and two event axes
    dt = diag.to_datatree(rng.standard_normal((2, 10)), event_dims=())
    assert dt["posterior"]["mu"].dims == ("chain", "draw")
    dt = diag.to_datatree(
        rng.standard_normal((2, 10, 3, 3)), event_dims=("row", "col"), coords={"row": list("abc")}
    )
    assert dt["posterior"]["mu"].dims == ("chain", "draw", "row", "col")
    assert list(dt["posterior"]["row"].values) == ["a", "b", "c"]


def test_to_datatree_names_h_apart_from_hmc_energy_and_writes_booleans_as_integers(tmp_path):
    """``energy_name="hamiltonian"`` keeps ``h`` of a momentum-free sampler away from ArviZ's
    HMC-energy diagnostics (BFMI refuses the tree instead of reporting a number); a boolean
    attribute is stored as 1/0, which NetCDF can hold and which keeps its truth value."""
    import arviz_stats

    rng = np.random.default_rng(2)
    mu, info = make_run(rng)
    dt = diag.to_datatree(mu, info, energy_name="hamiltonian", attrs={"adapted": False})
    assert "energy" not in dt.sample_stats
    np.testing.assert_array_equal(dt.sample_stats["hamiltonian"].values, info.energy)
    with pytest.raises(KeyError, match="energy"):
        arviz_stats.bfmi(dt)
    assert arviz_stats.bfmi(diag.to_datatree(mu, info))["energy"].shape == (3,)
    dt.to_netcdf(tmp_path / "x.nc", engine="h5netcdf")
    back = xr.open_datatree(tmp_path / "x.nc")
    try:
        assert back.attrs["adapted"] == 0 and not back.attrs["adapted"]
    finally:
        back.close()
    with pytest.raises(ValueError, match="energy_name must be a non-empty string"):
        diag.to_datatree(mu, info, energy_name="")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"positions": np.zeros(5)}, "positions"),
        ({"positions": np.zeros((0, 5, 3))}, "positions"),
        ({"positions": np.zeros((2, 5, 3)), "event_dims": ()}, "event_dims"),
        ({"positions": np.zeros((2, 5, 3)), "info": {"energy": np.zeros((2, 4))}}, "energy"),
        ({"positions": np.zeros((2, 5, 3)), "coords": {"component": ["a"]}}, "coords"),
        ({"positions": np.zeros((2, 5, 3)), "thinning": 0}, "thinning"),
    ],
)
def test_to_datatree_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        diag.to_datatree(**kwargs)


# --------------------------------------------------------------------------- expectation_table


@pytest.mark.parametrize("phi", [0.5, 0.8, 0.9])
def test_ess_matches_ar1_integrated_autocorrelation_time(phi):
    rng = np.random.default_rng(20240)
    chains, draws = 4, 20_000
    x = ar1(rng, phi, (chains, draws))
    df = diag.expectation_table({"x": x}, {"x": 0.0}, wall_time=2.0)
    row = df.loc["x"]
    expected_bulk = chains * draws / tau_ar1(phi)
    assert row["ess_bulk"] == pytest.approx(expected_bulk, rel=0.15)
    assert row["ess_per_second"] == pytest.approx(row["ess_bulk"] / 2.0)
    assert row["r_hat"] == pytest.approx(1.0, abs=0.01)
    # mcse of the mean: sd / sqrt(ESS) with sd = 1
    assert row["mcse"] == pytest.approx(np.sqrt(tau_ar1(phi) / (chains * draws)), rel=0.15)
    if phi <= 0.8:  # tail ESS is the ESS of the 5%/95% quantile indicators
        expected_tail = chains * draws / tau_indicator(phi, 0.05)
        assert row["ess_tail"] == pytest.approx(expected_tail, rel=0.15)


def test_z_scores_have_the_normal_false_alarm_rate():
    rng = np.random.default_rng(7)
    n_sets, phi = 200, 0.8
    x = ar1(rng, phi, (n_sets, 4, 1000))
    names = [f"rep{i}" for i in range(n_sets)]
    df = diag.expectation_table(dict(zip(names, x, strict=True)), dict.fromkeys(names, 0.0))
    z = df["z"].to_numpy()
    assert np.all(np.isfinite(z))
    frac = np.mean(np.abs(z) > 2)
    # Binomial(200, 0.0455): sd 1.5%; [1%, 10%] is about +-3.5 sd
    assert 0.01 <= frac <= 0.10
    assert np.std(z) == pytest.approx(1.0, abs=0.2)
    # a biased estimate is flagged
    df_bad = diag.expectation_table({"x": x[0]}, {"x": 0.3})
    assert df_bad.loc["x", "z"] < -4


def test_expectation_table_columns_and_missing_exact():
    rng = np.random.default_rng(3)
    df = diag.expectation_table({"a": rng.standard_normal((1, 100)), "b": np.ones((2, 50))})
    assert list(df.columns) == [
        "estimate",
        "exact",
        "mcse",
        "z",
        "ess_bulk",
        "ess_tail",
        "r_hat",
        "ess_per_second",
    ]
    assert list(df.index) == ["a", "b"]
    assert np.isnan(df.loc["a", "exact"]) and np.isnan(df.loc["a", "z"])
    assert np.isnan(df.loc["a", "ess_per_second"])
    assert df.loc["b", "estimate"] == 1.0
    text = diag.format_table(df)
    lines = text.splitlines()
    assert lines[0].split()[:3] == ["quantity", "estimate", "exact"]
    assert len(lines) == 4 and len({len(line) for line in lines[:2]}) == 1
    assert lines[2].startswith("a ")


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (({"x": np.zeros((2, 3))},), "draws"),  # fewer than 4 draws
        (({"x": np.zeros(10)},), "draws"),  # not (chains, draws)
        (({},), "draws"),
        (({"x": np.zeros((2, 10))}, {"y": 0.0}), "exact"),
        (({"x": np.zeros((2, 10))}, None, 0.0), "wall_time"),
    ],
)
def test_expectation_table_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        diag.expectation_table(*args)


# --------------------------------------------------------------------------- autocovariance


def test_autocovariance_matches_direct_sum():
    rng = np.random.default_rng(11)
    x = rng.standard_normal((3, 40, 2)) + 0.5
    c = diag.autocovariance(x, 10)
    y = x - x.mean(axis=(0, 1))
    direct = [np.mean(np.sum(y[:, : 40 - k] * y[:, k:], axis=-1)) for k in range(11)]
    np.testing.assert_allclose(c, direct, rtol=1e-12, atol=1e-14)
    raw = [np.mean(np.sum(x[:, : 40 - k] * x[:, k:], axis=-1)) for k in range(11)]
    np.testing.assert_allclose(diag.autocovariance(x, 10, center=False), raw, rtol=1e-12)


def test_autocovariance_of_ar1_is_phi_to_the_k():
    rng = np.random.default_rng(5)
    phi, chains, draws, max_lag = 0.7, 8, 20_000, 15
    x = ar1(rng, phi, (chains, draws))
    c = diag.autocovariance(x, max_lag)
    k = np.arange(max_lag + 1)
    # Bartlett: var(c_k) ~ (1/N) sum_j (rho_j^2 + rho_{j+k} rho_{j-k}) <= (1/N)(1+phi^2)/(1-phi^2)
    se = np.sqrt((1 + phi**2) / (1 - phi**2) / (chains * draws))
    np.testing.assert_allclose(c, phi**k, atol=4 * se)

    # the inner-product form is the sum of per-component autocovariances
    x3 = np.stack([ar1(rng, p, (chains, 2000)) for p in (0.2, 0.5, 0.9)], axis=-1)
    per_component = sum(diag.autocovariance(x3[..., i], 30) for i in range(3))
    np.testing.assert_allclose(diag.autocovariance(x3, 30), per_component, rtol=1e-12)

    # center=False: same on zero-mean data, but really uncentered on shifted data
    np.testing.assert_allclose(diag.autocovariance(x, max_lag, center=False), c, atol=2e-3)
    shifted = diag.autocovariance(x + 2.0, max_lag, center=False)
    np.testing.assert_allclose(shifted, c + 4.0, atol=0.05)


@pytest.mark.parametrize(
    ("x", "max_lag", "match"),
    [
        (np.zeros(10), 2, "x"),
        (np.zeros((2, 10, 3, 1)), 2, "x"),
        (np.zeros((2, 10)), 10, "max_lag"),
        (np.zeros((2, 10)), -1, "max_lag"),
    ],
)
def test_autocovariance_bad_input(x, max_lag, match):
    with pytest.raises(ValueError, match=match):
        diag.autocovariance(x, max_lag)


# --------------------------------------------------------------------------- health checks


def test_casimir_drift_and_nonfinite_count():
    err = np.array([[0.0, 1e-10, 3e-12], [2e-9, 1e-11, 5e-12]])
    info = {"casimir_error": err, "nonfinite": np.array([[0, 0, 0], [0, 1, 1]], bool)}
    assert diag.casimir_drift(info) == {"max": 2e-9, "final": 5e-12}
    assert diag.count_nonfinite(info) == 2
    nt = Info(
        energy=None, casimir_error=err, nonfinite=np.zeros((2, 3), bool), acceptance_rate=None
    )
    assert diag.count_nonfinite(nt) == 0
    assert diag.casimir_drift(nt)["max"] == 2e-9
    with pytest.raises(ValueError, match="casimir_error"):
        diag.casimir_drift({"energy": err})
    with pytest.raises(ValueError, match="nonfinite"):
        diag.count_nonfinite({"energy": err})
    with pytest.raises(TypeError, match="info"):
        diag.count_nonfinite(42)


# --------------------------------------------------------------------------- plots


def _is_big_png(path):
    data = path.read_bytes()
    return data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


def test_plots_write_pngs(tmp_path):
    rng = np.random.default_rng(2)
    mu, _ = make_run(rng, chains=4, draws=300)

    p = plots.plot_traces(mu, tmp_path / "traces.png", max_draws=200)
    assert _is_big_png(p)

    t = np.linspace(0.0, 3.0, 31)
    est = np.exp(-2 * t) + 0.02 * rng.standard_normal(t.size)
    p = plots.plot_autocorrelation(
        t, (est, np.full(t.size, 0.02)), tmp_path / "acf.png", exact=np.exp(-2 * t)
    )
    assert _is_big_png(p)
    p = plots.plot_autocorrelation(
        t, est, tmp_path / "acf_callable.png", exact=lambda s: np.exp(-2 * s), title="ACF"
    )
    assert _is_big_png(p)

    uniform = [lambda g: np.full_like(g, 0.5)] * 2 + [None]
    p = plots.plot_marginals(mu.reshape(-1, 3), tmp_path / "marg.png", exact_densities=uniform)
    assert _is_big_png(p)

    kappa, mean_dir = 3.0, np.array([0.0, 0.0, 1.0])
    pts = rng.standard_normal((4000, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    p = plots.plot_sphere_density(
        pts, tmp_path / "sub" / "sphere.png", logdensity_fn=lambda u: kappa * u @ mean_dir
    )
    assert p.parent.name == "sub" and _is_big_png(p)
    assert _is_big_png(plots.plot_sphere_density(pts, tmp_path / "sphere_only.png"))

    rows = [
        {"integrator": name, "seconds": s, "abs_bias": c * s**-1.0}
        for name, c in (("splitting", 1.0), ("midpoint", 3.0))
        for s in (0.1, 0.3, 1.0, 3.0)
    ] + [{"integrator": "midpoint", "seconds": 5.0, "abs_bias": 0.0}]
    p = plots.plot_accuracy_cost(rows, tmp_path / "cost.png")
    assert _is_big_png(p)


def test_plots_bad_input(tmp_path):
    with pytest.raises(ValueError, match="positions"):
        plots.plot_traces(np.zeros(5), tmp_path / "a.png")
    with pytest.raises(ValueError, match="empirical"):
        plots.plot_autocorrelation(np.arange(3), np.zeros(4), tmp_path / "b.png")
    with pytest.raises(ValueError, match="exact_densities"):
        plots.plot_marginals(np.zeros((10, 3)), tmp_path / "c.png", exact_densities=[None])
    with pytest.raises(ValueError, match="unit_vectors"):
        plots.plot_sphere_density(np.zeros((10, 2)), tmp_path / "d.png")
    with pytest.raises(ValueError, match="rows"):
        plots.plot_accuracy_cost([{"seconds": 1.0}], tmp_path / "e.png")
    assert not list(tmp_path.iterdir())


def test_sphere_density_histogram_is_normalised_per_steradian(tmp_path, monkeypatch):
    """The empirical panel must estimate density per steradian: 1/(4π) for uniform points."""
    captured = []
    original = plots.Figure.colorbar

    def spy(self, mappable, *args, **kwargs):
        captured.append(np.asarray(mappable.get_array()))
        return original(self, mappable, *args, **kwargs)

    monkeypatch.setattr(plots.Figure, "colorbar", spy)
    rng = np.random.default_rng(4)
    pts = 2.5 * rng.standard_normal((200_000, 3))  # any radius: projected to the unit sphere
    plots.plot_sphere_density(
        pts, tmp_path / "s.png", logdensity_fn=lambda u: 0.0 * u[..., 0], bins=(24, 12)
    )
    empirical, exact = captured
    np.testing.assert_allclose(exact, 1 / (4 * np.pi), rtol=1e-12)
    assert np.mean(empirical) == pytest.approx(1 / (4 * np.pi), rel=1e-9)
    assert np.std(empirical) / np.mean(empirical) < 0.1
