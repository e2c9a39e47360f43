"""The SALT-Euler example runs at small sizes and writes its two figures."""


def test_salt_euler_example_runs(tmp_path, capsys, run_example):
    assert run_example("salt_euler", ["--quick", "--out", str(tmp_path)]) == 0
    for name in ("salt_euler_scenes.png", "salt_euler_energy.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    # Euler keeps h; the descent lowers it (the example prints both)
    printed = capsys.readouterr().out
    line = [x for x in printed.splitlines() if x.startswith("h: start")][0]
    start, euler, descent = (float(x.split()[-1].rstrip(",")) for x in
                             (line.split(",")[0], line.split(",")[1], line.split(",")[2]))
    assert abs(euler - start) < 1e-6 * start and descent < start
