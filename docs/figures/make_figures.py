"""Regenerate the figures of the guides and the gallery that are checked in under docs/figures/.

Run from the repository root (about a few minutes on 2 cores, each script once):

    .venv/bin/python docs/figures/make_figures.py            # every figure
    .venv/bin/python docs/figures/make_figures.py binder_3d  # only the named ones

Each figure is drawn by the command the README or the example's docstring gives (``liesample
demo``, ``examples/<name>.py``), with the arguments listed in ``FIGURES`` below, into a scratch
folder; the PNGs are then stored here with a 256-colour palette, so each stays small. The
examples that print rather than draw (``OUTPUTS``) have their printout kept as ``<name>.txt``;
the gallery page (``docs/_ext/gallery.py``) shows both beside each script's source. The
benchmark figures (``benchmarks/results/*.png``) are not copied: the docs build publishes them
from where ``make bench`` writes them (``docs/_ext/figures.py``).
"""

import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
PYTHON = sys.executable

# name -> (command, {file the command writes (relative to its scratch folder): file kept here}).
# "{out}" in a command is the scratch folder.
FIGURES = {
    "demo": (
        [
            PYTHON,
            "-m",
            "liesample.cli",
            "demo",
            "--output",
            "{out}",
            "--time",
            "1000",
            "--no-progress",
        ],
        {
            "sphere.png": "demo_sphere.png",
            "autocorrelation.png": "demo_autocorrelation.png",
        },
    ),
    "topology_o3": (
        [PYTHON, "examples/topology_o3.py", "--plot", "{out}/topology_o3.png"],
        {"topology_o3.png": "topology_o3.png"},
    ),
    "binder_3d": (
        [
            PYTHON,
            "examples/binder_3d.py",
            "--sizes",
            "6,10",
            "--betas",
            "0.66,0.675,0.69,0.705,0.72",
            "--draws",
            "1000",
            "--warmup",
            "200",
            "--plot",
            "{out}/binder.png",
        ],
        {"binder.png": "binder_3d.png"},
    ),
    "vortex_scenes": (
        [PYTHON, "examples/vortex_scenes.py", "--out", "{out}"],
        {
            "vortex_dissipation.png": "vortex_dissipation.png",
            "vortex_scenes.png": "vortex_scenes.png",
        },
    ),
    "onsager_clusters": (
        [PYTHON, "examples/onsager_clusters.py", "--draws", "400", "--plot", "{out}/onsager.png"],
        {"onsager.png": "onsager_clusters.png"},
    ),
    "stochastic_pendulum": (
        [PYTHON, "examples/stochastic_pendulum.py", "{out}/pendulum.png"],
        {"pendulum.png": "stochastic_pendulum.png"},
    ),
    "charged_particle": (
        [PYTHON, "examples/charged_particle.py", "{out}/charged.png"],
        {"charged.png": "charged_particle.png"},
    ),
    "salt_euler": (
        [PYTHON, "examples/salt_euler.py", "--size", "12", "--out", "{out}"],
        {
            "salt_euler_scenes.png": "salt_euler_scenes.png",
            "salt_euler_energy.png": "salt_euler_energy.png",
        },
    ),
    "condensation": (
        [PYTHON, "examples/condensation.py", "--output", "{out}"],
        {
            "condensation_spectra.png": "condensation_spectra.png",
            "condensation_vorticity.png": "condensation_vorticity.png",
        },
    ),
}


# name -> command: examples that print their results; the printout is kept as <name>.txt.
OUTPUTS = {
    "custom_system": [PYTHON, "examples/custom_system.py"],
    "directional_statistics": [PYTHON, "examples/directional_statistics.py"],
    "numpyro_directional": [PYTHON, "examples/numpyro_directional.py"],
    "numpyro_magnetic_hmc": [PYTHON, "examples/numpyro_magnetic_hmc.py"],
}


MAX_BYTES = 150_000  # a figure checked in stays small


def shrink(source: Path, target: Path) -> None:
    """Store ``source`` at ``target`` as a palette PNG: 256 colours (the plots have few), fewer
    while the file is over ``MAX_BYTES`` (the smooth maps of the vorticity)."""
    from PIL import Image  # matplotlib's own dependency; only this script needs it

    with Image.open(source) as image:
        rgb = image.convert("RGB")
    colours = 256
    rgb.quantize(colors=colours).save(target, optimize=True)
    while target.stat().st_size > MAX_BYTES and colours > 16:
        colours //= 2
        rgb.quantize(colors=colours).save(target, optimize=True)


def make(name: str) -> None:
    command, files = FIGURES[name]
    with tempfile.TemporaryDirectory() as scratch:
        argv = [part.replace("{out}", scratch) for part in command]
        print(f"{name}: {' '.join(argv)}", flush=True)
        subprocess.run(argv, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
        for produced, kept in files.items():
            shrink(Path(scratch) / produced, HERE / kept)
            print(f"  {kept}: {(HERE / kept).stat().st_size // 1024} kB", flush=True)


def record(name: str) -> None:
    """Run the example ``name`` and keep what it prints as ``<name>.txt``."""
    print(f"{name}: {' '.join(OUTPUTS[name])}", flush=True)
    result = subprocess.run(OUTPUTS[name], cwd=ROOT, check=True, capture_output=True, text=True)
    (HERE / f"{name}.txt").write_text(result.stdout)


def main(names: list[str]) -> None:
    unknown = sorted(set(names) - set(FIGURES) - set(OUTPUTS))
    if unknown:
        sys.exit(f"unknown names {unknown}; choose from {sorted(FIGURES) + sorted(OUTPUTS)}")
    for name in names or [*FIGURES, *OUTPUTS]:
        if name in FIGURES:
            make(name)
        else:
            record(name)


if __name__ == "__main__":
    main(sys.argv[1:])
