"""The SALT-Euler example runs at small sizes and writes its two figures."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_salt_euler_example_runs(tmp_path):
    result = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "salt_euler.py"), "--quick", "--out",
         str(tmp_path)],
        check=False,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    for name in ("salt_euler_scenes.png", "salt_euler_energy.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    # Euler keeps h; the descent lowers it (the example prints both)
    line = [x for x in result.stdout.splitlines() if x.startswith("h: start")][0]
    start, euler, descent = (float(x.split()[-1].rstrip(",")) for x in
                             (line.split(",")[0], line.split(",")[1], line.split(",")[2]))
    assert abs(euler - start) < 1e-6 * start and descent < start
