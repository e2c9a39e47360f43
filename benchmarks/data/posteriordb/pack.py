"""Rebuild this folder's ``<posterior>.json`` files from a git clone of stan-dev/posteriordb.

    .venv/bin/python benchmarks/data/posteriordb/pack.py /path/to/posteriordb [commit]

For each posterior: the data, the Stan program, and a summary of the reference draws (per
parameter: mean, sd, posteriordb's bulk/tail ESS and R-hat, the MCSE of the mean as
``sd / sqrt(bulk ESS)``) plus two draws of each reference chain (its first and last), which
``tests/test_posteriordb_models.py`` evaluates the models at. The full draws (10 chains x 1000)
are not kept. A record larger than ``GZIP_ABOVE`` characters is written gzipped
(``<posterior>.json.gz``). A posterior whose posteriordb entry names another posterior's
reference draws (``reference_posterior_name``) gets those.
"""

from __future__ import annotations

import gzip
import io
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent
sys.path.insert(0, str(OUT.parents[2]))

from benchmarks.posteriordb_models import POSTERIORS  # the one list

PDB = "posterior_database"
GZIP_ABOVE = 200_000  # characters: a larger record (diamonds' 5000 x 25 design) is gzipped


def main(repo: str, commit: str = "HEAD") -> None:
    def show(path):
        command = ["git", "-C", repo, "show", f"{commit}:{path}"]
        return subprocess.run(command, check=True, capture_output=True).stdout

    def unzip_json(path):
        archive = zipfile.ZipFile(io.BytesIO(show(path)))
        return json.loads(archive.read(archive.namelist()[0]))

    resolved = subprocess.run(
        ["git", "-C", repo, "rev-parse", commit], check=True, capture_output=True, text=True
    ).stdout.strip()
    for name in POSTERIORS:
        post = json.loads(show(f"{PDB}/posteriors/{name}.json"))
        data = unzip_json(f"{PDB}/data/data/{post['data_name']}.json.zip")
        stan = show(f"{PDB}/models/stan/{post['model_name']}.stan").decode()
        # posteriordb names the posterior whose draws are this one's reference (the centred
        # eight schools points to the non-centred one: the same law of (mu, tau, theta)).
        reference = post.get("reference_posterior_name") or name
        chains = unzip_json(f"{PDB}/reference_posteriors/draws/draws/{reference}.json.zip")
        info = json.loads(show(f"{PDB}/reference_posteriors/draws/info/{reference}.info.json"))
        names = list(chains[0])
        draws = np.array([[chain[k] for k in names] for chain in chains])  # (chain, key, draw)
        flat = draws.transpose(1, 0, 2).reshape(len(names), -1)
        diagnostics = info["diagnostics"]
        order = [diagnostics["diagnostic_information"]["names"].index(k) for k in names]

        def column(field, diagnostics=diagnostics, order=order):
            return np.asarray(diagnostics[field])[order]

        ess = column("effective_sample_size_bulk")
        mean, sd = flat.mean(1), flat.std(1, ddof=1)
        record = {
            "posterior": name,
            "model_name": post["model_name"],
            "data_name": post["data_name"],
            "source": f"github.com/stan-dev/posteriordb@{resolved}",
            "reference_posterior": reference,
            "stan_code": stan,
            "data": data,
            "reference": {
                "method": info["inference"],
                "num_chains": len(chains),
                "num_draws": int(flat.shape[1]),
                "names": names,
                "mean": mean.tolist(),
                "sd": sd.tolist(),
                "ess_bulk": ess.tolist(),
                "ess_tail": column("effective_sample_size_tail").tolist(),
                "mcse_mean": (sd / np.sqrt(ess)).tolist(),
                "r_hat": column("r_hat").tolist(),
            },
            "draws_sample": {
                k: draws[:, i, [0, -1]].reshape(-1).tolist() for i, k in enumerate(names)
            },
        }
        text = json.dumps(record, indent=1) + "\n"
        if len(text) > GZIP_ABOVE:
            (OUT / f"{name}.json.gz").write_bytes(gzip.compress(text.encode(), mtime=0))
        else:
            (OUT / f"{name}.json").write_text(text)
        print(name, len(names), "parameters")


if __name__ == "__main__":
    main(*sys.argv[1:])
