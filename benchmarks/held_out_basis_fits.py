"""How well a build's basis and GMM draw materials they never saw (offline, ~5 min a model on 2 cores).

Each of the 100 MERL materials is held out of a build's stored full fits
(:func:`mi_dsbrdf.evaluation.experiment.loo_model`, the natural-light benchmarks'
leave-one-out models, cached beside theirs), fitted to its measurements in the other 99's basis
(:func:`mi_dsbrdf.model.fitting.fit_basis`, 10 coefficients and the lobes'
chromaticities) and priced by the other 99's GMM. Per material:

* ``paper``, ``cosine``: Eq. 5 of that basis fit in the paper's convention
  log(f + 1e-6) and in the cosine-weighted one log(1 + f cos theta_i);
* ``gmm_nll``: the GMM's -log p(psi) at the fit (Eq. 6, volume terms included);
* ``sigmas``: its Mahalanobis distance to the nearest component.

The last two are in each build's own coordinates: compare them between builds
with care (an anchored build packs the library tighter, so a fit that the data
leave free in a direction can sit many of its sigmas away and still cost the
image nothing). Used in the twenty-sixth session to compare the shipped build
with builds whose fits were anchored (``build-model --fit-anchor``), and in the
twenty-seventh with one whose unseen values were completed (``--complete-unseen``)::

    .venv/bin/python benchmarks/held_out_basis_fits.py mi_dsbrdf/data/model.npz \\
        benchmarks/results/natural_light/models/fit_anchor0.003.npz ...
    .venv/bin/python benchmarks/held_out_basis_fits.py --summary   # the stored results

Results: ``benchmarks/results/held_out_basis_fits.json`` (one entry per model
file, keyed by its path relative to the repository).
"""
from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
import json
import multiprocessing
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))
DATA = os.path.join(os.path.dirname(ROOT), "shared", "data")
OUT = os.path.join(ROOT, "benchmarks", "results", "held_out_basis_fits.json")


def held_out(args) -> dict:
    """One model file's per-material figures (runs in a worker process)."""
    from mi_dsbrdf.backend import one_blas_thread
    one_blas_thread()
    from experiments import CACHE
    from mi_dsbrdf.evaluation.experiment import loo_model
    from mi_dsbrdf.model.build import load_samples
    from mi_dsbrdf.model.fitting import fit_basis
    from mi_dsbrdf.model.model_file import load_model
    path, source = args
    rows = {}
    for name in load_model(path).arrays["fit_names"].tolist():
        m = loo_model(name, CACHE, fits_from=path)
        f = fit_basis(load_samples(source, name), m.basis)
        psi = f.variables
        rows[name] = {"paper": float(f.error), "cosine": float(f.error_cosine),
                      "gmm_nll": float(m.gmm.nll(psi)), "sigmas": float(m.gmm.mahalanobis(psi).min())}
    return rows


def summary(results, groups=None) -> str:
    """Markdown: per model file and group of materials, the median and mean of each figure."""
    lines = ["| model | materials | Eq. 5 paper: median, mean | Eq. 5 cosine: median, mean | GMM -log p: median, "
             "worst | sigmas: median, worst |", "|---|---|---|---|---|---|"]
    for model, rows in results.items():
        for group, names in (groups or {"all": None}).items():
            names = list(rows) if names is None else [n for n in names if n in rows]
            if not names:
                continue
            col = {k: np.array([rows[n][k] for n in names]) for k in ("paper", "cosine", "gmm_nll", "sigmas")}
            lines.append("| %s | %s (%d) | %.3f, %.3f | %.3f, %.3f | %.1f, %.1f | %.1f, %.1f |" % (
                model, group, len(names), np.median(col["paper"]), col["paper"].mean(),
                np.median(col["cosine"]), col["cosine"].mean(), np.median(col["gmm_nll"]), col["gmm_nll"].max(),
                np.median(col["sigmas"]), col["sigmas"].max()))
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("models", nargs="*", help="model files (build-model --out)")
    ap.add_argument("--summary", action="store_true", help="only print the stored results")
    ap.add_argument("--data", default=DATA)
    args = ap.parse_args()
    results = json.load(open(OUT)) if os.path.exists(OUT) else {}
    if not args.summary:
        source = os.path.join(args.data, "merl", "merl_nbrdf_weights.npz")
        if not os.path.exists(source):
            sys.exit("needs the MERL fits under %s (see ../shared/data/README.md)" % args.data)
        missing = [m for m in args.models if not os.path.isfile(m)]
        if missing or not args.models:
            sys.exit("give model files: %s" % (", ".join(missing) or "none given"))
        with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as ex:
            for path, rows in zip(args.models, ex.map(held_out, [(os.path.abspath(m), source) for m in args.models])):
                results[os.path.relpath(os.path.abspath(path), ROOT)] = rows
        with open(OUT, "w") as f:
            json.dump(results, f, indent=1, sort_keys=True)
    from natural_light import VALIDATION_MATERIALS        # nothing is read on the report set
    print(summary(results, {"all": None, "validation": VALIDATION_MATERIALS}))


if __name__ == "__main__":
    main()
