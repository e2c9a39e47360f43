"""`liesample demo` writes its report, plots and draws, and refuses bad parameters cleanly."""

import numpy as np
import pytest
import xarray as xr

from liesample import load_chains
from liesample.cli import main


def test_demo_writes_report_plots_and_netcdf(tmp_path, capsys):
    out = tmp_path / "demo"
    status = main(["demo", "--time", "100", "--chains", "2", "--output", str(out), "--no-progress"])
    assert status == 0
    printed = capsys.readouterr().out
    assert "E[μ₃²]" in printed and "ess_bulk" in printed and "Casimir" in printed
    for name in ("trace.png", "autocorrelation.png", "marginals.png", "sphere.png"):
        assert (out / name).stat().st_size > 10_000, name
    tree = xr.open_datatree(out / "draws.nc")
    assert tree["posterior"]["mu"].shape[:2] == (2, 200)
    assert not tree["sample_stats"]["diverging"].values.any()
    saved = load_chains(out / "draws.nc")  # the run file, verified
    assert list(saved.posterior["mu"].coords["component"].values) == ["μ₁", "μ₂", "μ₃"]
    np.testing.assert_array_equal(saved.posterior["mu"], tree["posterior"]["mu"])


def test_demo_refuses_an_output_that_is_a_file(tmp_path, capsys):
    existing = tmp_path / "file.txt"
    existing.write_text("mine")
    assert main(["demo", "--output", str(existing), "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert "is a file" in error and str(existing) in error and "Traceback" not in error
    assert existing.read_text() == "mine"


def test_demo_rejects_bad_parameters_without_traceback(tmp_path, capsys):
    status = main(["demo", "--step-size", "-1", "--output", str(tmp_path), "--no-progress"])
    assert status == 2
    assert "step_size must be > 0" in capsys.readouterr().err


def _demo_parser():
    import argparse

    from liesample.cli import _parser

    commands = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction))
    return commands.choices["demo"]


def test_every_demo_option_has_help_and_a_shown_default(capsys):
    import pytest

    from liesample.integrators import INTEGRATORS

    demo = _demo_parser()
    options = [a for a in demo._actions if a.option_strings and a.dest != "help"]
    assert len(options) >= 10
    assert all(a.help for a in options), [a.dest for a in options if not a.help]
    with pytest.raises(SystemExit):
        demo.parse_args(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    for action in options:
        assert action.option_strings[0] in text
        assert f"(default: {action.default})" in text or action.default is None
    assert "jax_enable_x64" in text and "float64" in text
    assert all(name in text for name in INTEGRATORS)


def test_demo_fails_when_every_step_diverges(tmp_path, capsys):
    """The explicit Euler–Heun scheme at the demo's step blows up on every chain: the demo says
    so and exits with a failure status instead of printing huge estimates as a result."""
    argv = ["demo", "--integrator", "euler_heun", "--time", "100", "--chains", "2"]
    status = main([*argv, "--output", str(tmp_path), "--no-progress"])
    assert status == 1
    assert "diverged" in capsys.readouterr().err


@pytest.mark.slow  # a table detail; the failing-run exit code runs by default
def test_isotropic_demo_leaves_out_the_constant_energy(tmp_path, capsys):
    """An isotropic body's h is constant on the orbit: no E[h] row (its R-hat is meaningless)."""
    argv = ["demo", "--inertia", "2", "2", "2", "--time", "100", "--chains", "2"]
    assert main([*argv, "--output", str(tmp_path), "--no-progress"]) == 0
    assert "E[h]" not in capsys.readouterr().out
