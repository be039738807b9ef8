"""Point lights on the natural-light validation materials: the BRDF against the mean material.

The prior weights are shared by every kind of light, and a point light sees a
narrow band of theta_d: the reflectance prior carries more of the answer there.
This runs the validation materials (``benchmark_cases.VALIDATION_MATERIALS``;
with ``--set report`` the report set's, to check a choice) under a point light
at two angles, with a GMM weight and the leave-one-out models' GMM structure
(default: the shipped ones), and prints Eq. 20 (paper) beside the model's mean
material (psi = 0).

    .venv/bin/python benchmarks/point_validation.py                       # 40 cases, ~3 min on 2 cores
    .venv/bin/python benchmarks/point_validation.py --gmm full:2:0.01 --w-gmm 100
    .venv/bin/python benchmarks/point_validation.py --config light_gmm_volume=0   # the GMM without its volume terms
    .venv/bin/python benchmarks/point_validation.py --set report --config pixel_rays=1   # 24 cases

Adds its setting's summary (cases better than the mean material in both
conventions, median and worst ratio to it, the direction error, the time) to
``benchmarks/results/point_validation.json`` (``settings``, named by
:func:`~mi_dsbrdf.evaluation.benchmark_cases.setting_name`) and its cases to
``out/point_validation/<setting>.json``.
"""
from __future__ import annotations

import argparse
import json
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from mi_dsbrdf.evaluation.benchmark_cases import (CACHE, DATA, OUT as OUT_ROOT, REPORT_MATERIALS, RESULTS,
                                                  VALIDATION_MATERIALS, parse_config, setting_name)

#: the settings' summaries (the README and Config's docs quote it)
SUMMARY = os.path.join(RESULTS, "point_validation.json")
#: each setting's cases, <setting>.json
OUT = os.path.join(OUT_ROOT, "point_validation")
ANGLES = (20, 60)


def _run(args):
    import mi_dsbrdf  # noqa: F401
    from mi_dsbrdf.evaluation import experiment as ev
    material, angle, weights, gmm = args
    case = {"id": "point-validation", "kind": "point", "material": material, "angle": angle, "priors": True,
            "res": 64, "map": [8, 16], "rounds": 3, "iters": 15, "weights": weights}
    if gmm is not None:
        case["gmm"] = gmm
    r = ev.run_case(case, DATA, CACHE, threads=1)
    return {"material": material, "angle": angle, "direction_error_deg": r["direction_error_deg"],
            "brdf_eq20_paper": r["brdf_eq20_paper"], "brdf_eq20_cosine": r["brdf_eq20_cosine"],
            "mean_material_paper": r["baseline"]["brdf_eq20_paper"],
            "mean_material_cosine": r["baseline"]["brdf_eq20_cosine"], "seconds": r["seconds"]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--gmm", default=None, help="the leave-one-out models' GMM structure (default the build's)")
    ap.add_argument("--w-gmm", type=float, default=None, help="the GMM prior's weight (default Config's)")
    ap.add_argument("--config", nargs="*", help="other Config overrides, name=value (e.g. light_gmm_volume=0)")
    ap.add_argument("--set", choices=("validation", "report"), default="validation",
                    help="the materials: the validation set's (settings are chosen there) or the report set's")
    args = ap.parse_args(argv)
    weights = parse_config(args.config)
    if args.w_gmm is not None:
        weights["w_gmm"] = args.w_gmm
    name = setting_name(weights, args.gmm) + ("" if args.set == "validation" else "-report")
    materials = VALIDATION_MATERIALS if args.set == "validation" else REPORT_MATERIALS
    jobs = [(m, a, weights, args.gmm) for m in materials for a in ANGLES]
    with ProcessPoolExecutor(2) as pool:
        rows = list(pool.map(_run, jobs))
    print("| material | angle | %s: paper (mean material) | direction error deg |\n|---|---|---|---|" % name)
    for r in rows:
        print("| %s | %d | %.3f (%.3f) | %.2f |" % (r["material"], r["angle"], r["brdf_eq20_paper"],
                                                   r["mean_material_paper"], r["direction_error_deg"]))
    ratio = np.array([r["brdf_eq20_paper"] / r["mean_material_paper"] for r in rows])
    cosine = np.array([r["brdf_eq20_cosine"] / r["mean_material_cosine"] for r in rows])
    summary = {"wins": int((ratio < 1).sum()), "cases": len(rows), "median_ratio": float(np.median(ratio)),
               "worst_ratio": float(ratio.max()),
               "cosine_wins": int((cosine < 1).sum()), "cosine_median_ratio": float(np.median(cosine)),
               "direction_error_median_deg": float(np.median([r["direction_error_deg"] for r in rows])),
               "direction_error_max_deg": float(max(r["direction_error_deg"] for r in rows)),
               "median_seconds": float(np.median([r["seconds"] for r in rows]))}
    print("%s: BRDF (paper) better than the mean material in %d of %d, median ratio %.2f, worst %.2f; "
          "(cosine) in %d, median ratio %.2f; direction error median %.2f, at most %.2f deg; median %.1f s"
          % (name, summary["wins"], len(rows), summary["median_ratio"], summary["worst_ratio"],
             summary["cosine_wins"], summary["cosine_median_ratio"], summary["direction_error_median_deg"],
             summary["direction_error_max_deg"], summary["median_seconds"]))
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, name + ".json"), "w") as f:
        json.dump(rows, f, indent=1, sort_keys=True)
    old = json.load(open(SUMMARY)) if os.path.exists(SUMMARY) else {}
    settings = old.get("settings", {})
    settings[name] = {"summary": summary}
    with open(SUMMARY, "w") as f:
        json.dump({"command": "python benchmarks/point_validation.py [--set report] [--gmm S] [--w-gmm W] "
                              "[--config k=v ...] (a report run's setting ends in -report)",
                   "settings": settings}, f, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
