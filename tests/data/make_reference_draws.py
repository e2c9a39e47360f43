"""Write ``tests/data/reference_draws.npz``: the draws ``tests/test_draws_unchanged.py`` expects.

The reference is the code before the package was reorganised into layers (commit ``ebf7941``,
the parent of ``1be3165``). Generated with::

    git worktree add /tmp/old_tree ebf7941
    .venv/bin/python tests/data/make_reference_draws.py /tmp/old_tree
    git worktree remove --force /tmp/old_tree

The runs are those of ``tests/cases.py`` (``reference_runs``): every sampler row,
``lie_poisson_langevin`` on every system row and each integrator on the rigid body, 2 chains ×
20 draws from a fixed key, float64. ``tests/cases.py`` uses only top-level names that both trees
export, so the same rows build against the old tree. Rows the old tree cannot build (a sampler
or system newer than it) are left out and reported.
"""

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv):
    if len(argv) != 2:
        raise SystemExit(f"usage: {argv[0]} PATH_TO_REFERENCE_TREE")
    tree = Path(argv[1]).resolve()
    sys.path[:0] = [str(tree), str(HERE.parent)]  # the reference liesample first, then cases
    import jax

    jax.config.update("jax_enable_x64", True)
    import cases
    import numpy as np

    import liesample

    if Path(liesample.__file__).resolve().parent.parent != tree:
        raise SystemExit(f"liesample imported from {liesample.__file__}, not from {tree}")
    arrays, missing = {}, []
    for label, (build, starts) in cases.reference_runs().items():
        try:
            arrays.update(cases.reference_draws(label, build, starts))
        except (AttributeError, ImportError) as error:  # newer than the reference tree
            missing.append(f"{label} ({error})")
    np.savez_compressed(HERE / "reference_draws.npz", **arrays)
    import json

    from test_draws_unchanged import host

    (HERE / "reference_draws_host.json").write_text(json.dumps(host(), indent=1) + "\n")
    print(f"wrote {len(arrays)} arrays; left out: {missing or 'none'}")


if __name__ == "__main__":
    main(sys.argv)
