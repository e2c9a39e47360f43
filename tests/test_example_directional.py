"""The directional statistics example: geometric HMC on S² × R against the exact vMF posterior."""

import importlib.util
from pathlib import Path

import arviz_stats
import numpy as np
import pytest

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "directional_statistics.py"


# statistical; the same model (window adaptation, geometric HMC on S² × R) runs by default in
# the README's example and tests/test_geometric_samplers.py
@pytest.mark.slow
def test_directional_statistics_example_matches_the_exact_posterior(capsys):
    spec = importlib.util.spec_from_file_location("directional_statistics", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    tree, exact = module.main(
        seed=0, num_chains=4, num_adaptation=200, num_warmup=50, num_draws=300, progress=False
    )
    printed = capsys.readouterr().out
    assert "log_kappa" in printed and "mu[x]" in printed and "ess_bulk" in printed
    posterior = tree.posterior
    assert posterior["mu"].dims == ("chain", "draw", "mu_dim_0")
    assert posterior["mu"].shape == (4, 300, 3) and posterior["log_kappa"].shape == (4, 300)
    assert not np.any(np.asarray(tree.sample_stats["diverging"]))
    mu = np.asarray(posterior["mu"])
    quantities = {f"mu[{i}]": (mu[..., i], exact["direction"][i]) for i in range(3)}
    quantities["log_kappa"] = (np.asarray(posterior["log_kappa"]), exact["log_kappa"])
    for name, (draws, truth) in quantities.items():
        mcse = float(arviz_stats.mcse(draws, method="mean"))
        assert float(arviz_stats.rhat(draws)) < 1.05, name
        assert abs(draws.mean() - truth) < 5.0 * mcse, (name, draws.mean(), truth, mcse)
