"""How far apart two runs of natural-light inference land when only rounding differs.

Natural-light inference divides the image by its usable pixels' mean
(:func:`~mi_dsbrdf.inference.envmap.image_level`), so the same image at
another exposure reaches the optimiser changed only in the last bits of each
pixel (an exposure of a power of two: not at all, which the suite checks).
This script recovers each case at the exposures in ``EXPOSURES`` and prints,
per case, each run's BRDF error (Eq. 20, both conventions), the map's error
(log(1 + L) after the best scale, against the probe on the seen texels), the
final negative log posterior, and how far ψ moved; then the spread over the
cases (the largest over smallest of each error and of the posterior within a
case), and, where the runs' posteriors differ, whether the lowest posterior
goes with the lowest error.

It measures the noise floor of every comparison of two settings: a change to
the code moves the optimiser's path at least as much as a rounding does, so a
per-case difference within this spread is not evidence either way (the twelfth
session's exposure fix moved the report set's BRDF up in 42 of 72 cases).
Relighting is not measured here (it follows the BRDF and the map).

    .venv/bin/python benchmarks/rounding_spread.py          # 20 cases x 3 exposures, ~12 min on 2 cores
    .venv/bin/python benchmarks/rounding_spread.py --report # only the table of the stored results

Validation materials, each under one validation probe (in turn). Writes
benchmarks/results/rounding_spread.json (each case as it ends; a case already
there is not run again: delete the file to start over).
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from natural_light import ROOT, VALIDATION_MATERIALS, VALIDATION_PROBES
from truth_posterior import run_saved, validation_case

OUT = os.path.join(ROOT, "benchmarks", "results", "rounding_spread.json")
#: the image's exposures: after the division by the image's level they differ only by rounding
EXPOSURES = (1.0, 1.7, 0.3)
MEASURES = ("brdf_eq20_paper", "brdf_eq20_cosine", "illumination_error")


def run(material, probe) -> dict:
    """Recover one case at every exposure of ``EXPOSURES``."""
    from mi_dsbrdf.config import Config
    from mi_dsbrdf.evaluation import experiment as ex
    from mi_dsbrdf.evaluation.metrics import material_errors, scale_invariant_log_error
    from mi_dsbrdf.inference import envmap
    model, samples, truth, img, ts, mask = validation_case(material, probe)   # mask: the app's pixels
    cfg = Config(map_size=(32, 64))
    small = ex.downsample(truth, *cfg.map_size)
    runs = []
    for exposure in EXPOSURES:
        rec = envmap.recover_envmap(ts, img * exposure, mask, model, cfg)
        errors = material_errors(rec.material, samples)
        runs.append(dict(exposure=exposure, psi=rec.psi.tolist(), neg_log_posterior=rec.log[-1]["neg_log_posterior"],
                         brdf_eq20_paper=errors["paper"], brdf_eq20_cosine=errors["cosine"],
                         illumination_error=scale_invariant_log_error(rec.illumination, small, rec.seen)))
    return dict(material=material, probe=probe, runs=runs)


def spread(row, key) -> float:
    """Largest over smallest of ``key`` over a case's runs."""
    v = [r[key] for r in row["runs"]]
    return max(v) / min(v)


def psi_move(row) -> float:
    """The largest distance of a run's psi from the first run's."""
    p = np.array([r["psi"] for r in row["runs"]])
    return float(np.linalg.norm(p[1:] - p[0], axis=1).max())


def lowest_posterior_ranks(rows, key, posterior_gap=0.005, error_gap=0.02) -> tuple:
    """(cases where the run with the lowest final posterior has the lowest ``key``,
    cases where it has a lower ``key`` than the run with the highest posterior,
    cases counted): only cases whose runs' posteriors differ by more than
    ``posterior_gap`` and whose ``key`` differs by more than ``error_gap`` (relative)."""
    lowest = lower = n = 0
    for r in rows:
        if spread(r, "neg_log_posterior") - 1 > posterior_gap and spread(r, key) - 1 > error_gap:
            best = min(r["runs"], key=lambda run: run["neg_log_posterior"])
            worst = max(r["runs"], key=lambda run: run["neg_log_posterior"])
            n += 1
            lowest += best[key] == min(run[key] for run in r["runs"])
            lower += best[key] < worst[key]
    return lowest, lower, n


def report(rows) -> str:
    md = ["| case | " + " | ".join("%s at %s" % (k, ", ".join("%g" % e for e in EXPOSURES)) for k in MEASURES)
          + " | -log posterior | ψ moved |", "|---|" + "---|" * (len(MEASURES) + 2)]
    for r in rows:
        cells = [", ".join("%.3f" % run[k] for run in r["runs"]) for k in MEASURES]
        post = ", ".join("%.0f" % run["neg_log_posterior"] for run in r["runs"])
        md.append("| %s × %s | %s | %s | %.2f |" % (r["material"], os.path.basename(r["probe"]), " | ".join(cells),
                                                   post, psi_move(r)))
    md += ["", "Over %d cases, largest / smallest within a case: median, 90th percentile, max" % len(rows), ""]
    for k in MEASURES + ("neg_log_posterior",):
        s = np.array([spread(r, k) for r in rows])
        md.append("- %s: %.3f, %.3f, %.3f" % (k, np.median(s), np.percentile(s, 90), s.max()))
    md += ["", "Where the runs' final posteriors differ by more than 0.5 % and an error by more than 2 %, "
           "the run with the lowest posterior has the lowest error / a lower error than the run with the "
           "highest posterior in:", ""]
    md += ["- %s: %d / %d of %d" % ((k,) + lowest_posterior_ranks(rows, k)) for k in MEASURES]
    return "\n".join(md) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--report", action="store_true", help="only print the table of the stored results")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    rows = []
    if args.report:
        with open(OUT) as f:
            rows = json.load(f)
    else:
        pairs = [(m, VALIDATION_PROBES[i % len(VALIDATION_PROBES)]) for i, m in enumerate(VALIDATION_MATERIALS)]
        for i, n, r in run_saved(run, OUT, pairs, args.workers, rows):
            print("[%d/%d] %s x %s: BRDF %s" % (i, n, r["material"], os.path.basename(r["probe"]), ", ".join(
                "%.3f" % x["brdf_eq20_paper"] for x in r["runs"])), flush=True)
    print(report(rows))
    print("rounding_spread finished")


if __name__ == "__main__":
    sys.exit(main())
