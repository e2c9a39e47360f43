"""The SALT-Euler example runs at small sizes and writes its two figures."""

import re

import pytest

GIBBS_LINE = re.compile(r"^β = ([+-]\d+) \((\w+)\W.*?E\[h\][^=]*= ([\d.]+) ±", re.MULTILINE)


# --quick is a smoke run (40 draws from one start): the runner rightly warns that its chains
# have not converged
@pytest.mark.slow  # its Gibbs scene's adjusted sampling is what the condensation example tests
@pytest.mark.filterwarnings("ignore:the chains disagree")
def test_salt_euler_example_runs(tmp_path, capsys, run_example):
    assert run_example("salt_euler", ["--quick", "--out", str(tmp_path)]) == 0
    for name in ("salt_euler_scenes.png", "salt_euler_energy.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    # Euler keeps h; the descent lowers it (the example prints both)
    printed = capsys.readouterr().out
    line = next(x for x in printed.splitlines() if x.startswith("h: start"))
    start, euler, descent = (
        float(x.split()[-1].rstrip(","))
        for x in (line.split(",")[0], line.split(",")[1], line.split(",")[2])
    )
    assert abs(euler - start) < 1e-6 * start and descent < start
    # the Gibbs scene uses the recommended (Metropolis-adjusted) sampler; β > 0 lowers h from
    # the start, β < 0 raises it
    gibbs = {float(b): (name, float(h)) for b, name, h in GIBBS_LINE.findall(printed)}
    assert sorted(gibbs) == [-40.0, 40.0]
    assert {name for name, _ in gibbs.values()} == {"adjusted_lie_poisson"}
    assert gibbs[40.0][1] < start < gibbs[-40.0][1]
