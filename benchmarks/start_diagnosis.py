"""Why near-Lambertian materials come back with a highlight: the search or the objective?

Each validation case with a near-Lambertian truth (measured peak / off-peak <
``natural_light.NEAR_LAMBERTIAN``) under the validation probes is recovered
from every reflectance start alone (``case["start"]``: the mean material and
each GMM mean) and from all of them (the shipped choice). Printed per run: the
final negative log posterior term by term, the BRDF's Eq. 20 (paper), its
highlight ratio, the map and relit errors. If a start that lands on the right
material ends at a *higher* posterior than the one chosen, the posterior itself
prefers the highlight (the objective, not the search, is wrong), and the terms
say which part of it does.

    .venv/bin/python benchmarks/start_diagnosis.py --probes polyhaven/pedestrian_overpass_1k.hdr   # ~6 min
    .venv/bin/python benchmarks/start_diagnosis.py --config gmm_volume=0    # the GMM without its volume terms
    .venv/bin/python benchmarks/start_diagnosis.py --gmm-only               # the GMM's -log p by highlight class
    .venv/bin/python benchmarks/start_diagnosis.py --report                 # -> docs/start_diagnosis.md

Validation materials and probes only (the choice of a fix may rest on it).
Writes benchmarks/results/start_diagnosis.json, one entry per setting.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from experiments import CACHE, DATA, make_case
from natural_light import NEAR_LAMBERTIAN, VALIDATION_MATERIALS, VALIDATION_PROBES, parse_config, setting_name

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "start_diagnosis.json")
DOC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "docs", "start_diagnosis.md")


def measured_highlight_ratio(name, data=DATA) -> float:
    """Peak / off-peak (metrics.highlight_ratio) of a MERL material's measured BRDF."""
    from mi_dsbrdf.brdf.measured import MeasuredBRDF
    from mi_dsbrdf.evaluation.metrics import highlight_ratio
    from mi_dsbrdf.model.samples import samples_from_table
    s = samples_from_table(MeasuredBRDF.from_nbrdf(os.path.join(data, "merl", "merl_nbrdf_weights.npz"), name))
    return highlight_ratio(s.values, s.theta_h, s.theta_d)


def near_lambertian(materials, data=DATA) -> list:
    """The materials whose measured BRDF has peak / off-peak below NEAR_LAMBERTIAN."""
    return [m for m in materials if measured_highlight_ratio(m, data) < NEAR_LAMBERTIAN]


#: classes of the measured peak / off-peak ratio (metrics.highlight_ratio)
HIGHLIGHT_CLASSES = [(0, 1.5), (1.5, 5), (5, 50), (50, np.inf)]


def gmm_by_highlight(data=DATA) -> list:
    """The shipped model's GMM -log p of its library materials' psi (in-sample),
    median per class of measured highlight ratio, with the volume terms (the
    density) and without (``volume=0``): [(lo, hi, n, with, without), ...]."""
    from mi_dsbrdf.model import model_file
    model = model_file.shipped_model()
    ratio, dens, plain = [], [], []
    for name in model.library:
        ratio.append(measured_highlight_ratio(name, data))
        psi = model.library[name][0]
        dens.append(model.gmm.nll(psi))
        plain.append(model.gmm.nll(psi, volume=0))
    ratio, dens, plain = map(np.array, (ratio, dens, plain))
    out = []
    for lo, hi in HIGHLIGHT_CLASSES:
        sel = (ratio >= lo) & (ratio < hi)
        out.append((lo, hi, int(sel.sum()), float(np.median(dens[sel])), float(np.median(plain[sel]))))
    return out


def _run(args):
    import mi_dsbrdf  # noqa: F401
    from mi_dsbrdf.evaluation import experiment as ev
    material, probe, start, config = args
    case = make_case("start-diagnosis", "probe", material, True, probe=probe, weights=config)
    if start is not None:
        case["start"] = start
    r = ev.run_case(case, DATA, CACHE, threads=1)
    return {"material": material, "probe": probe, "start": "all" if start is None else start,
            "terms": r["terms"], "brdf_eq20_paper": r["brdf_eq20_paper"],
            "mean_material_paper": r["baseline"]["brdf_eq20_paper"], "highlight_ratio": r["highlight_ratio"],
            "truth_highlight_ratio": r["truth_highlight_ratio"], "illumination_error": r["illumination_error"],
            "relight": float(np.mean(list(r["relight"].values()))), "seconds": r["seconds"]}


def gmm_table(by_class) -> str:
    """Markdown of :func:`gmm_by_highlight`."""
    return "\n".join(["| measured highlight ratio | materials | GMM -log p (median) | without the volume terms |",
                      "|---|---|---|---|"] + ["| %g-%g | %d | %.1f | %.1f |" % tuple(c) for c in by_class])


def tables(rows, cases) -> str:
    """Markdown: every run's posterior terms and errors, then per case the start
    with the lowest posterior against the one with the best BRDF."""
    keys = ["likelihood", "gmm", "gradient", "entropy", "hue"]
    out = ["| material | probe | start | -log posterior | %s | Eq. 20 paper (mean material) | highlight "
           "(measured) | map | relit |" % " | ".join(keys), "|---" * (8 + len(keys)) + "|"]
    for r in rows:
        t = r["terms"]
        out.append("| %s | %s | %s | %.0f | %s | %.3f (%.3f) | %.2f (%.2f) | %.3f | %.3f |" % (
            r["material"], os.path.basename(r["probe"]).split(".")[0], r["start"], t["neg_log_posterior"],
            " | ".join("%.0f" % t.get(k, 0.0) for k in keys), r["brdf_eq20_paper"], r["mean_material_paper"],
            r["highlight_ratio"], r["truth_highlight_ratio"], r["illumination_error"], r["relight"]))
    out += ["", "| material | probe | lowest posterior: start, Eq. 20 | best BRDF: start, Eq. 20 | its posterior "
            "higher by | of which likelihood | GMM |", "|---|---|---|---|---|---|---|"]
    for x in cases:
        out.append("| %s | %s | %s, %.3f | %s, %.3f | %.0f | %.0f | %.0f |" % (
            x["material"], os.path.basename(x["probe"]).split(".")[0], x["map_start"], x["brdf"][0],
            x["best_brdf_start"], x["brdf"][1], x["posterior_gap"], x["likelihood_gap"], x["gmm_gap"]))
    return "\n".join(out)


def write_report(path=DOC) -> None:
    """docs/start_diagnosis.md from every setting in the results file."""
    results = json.load(open(OUT))
    parts = ["# Each reflectance start alone: the near-Lambertian validation materials",
             "", "Generated by `python benchmarks/start_diagnosis.py --report` from "
             "`benchmarks/results/start_diagnosis.json` (see the script's doc). `start`: the index into "
             "`reflectance_starts` (0 the mean material, then the GMM's means), `all` the shipped choice among them.",
             "", "The shipped GMM's -log p of the library's psi by measured highlight ratio:", "",
             gmm_table(next(iter(results.values()))["gmm_by_highlight"])]
    for name, entry in sorted(results.items()):
        parts += ["", "## Setting `%s` (`%s`)" % (name, entry["command"]), "", tables(entry["rows"], entry["cases"])]
    with open(path, "w") as f:
        f.write("\n".join(parts) + "\n")
    print("wrote", path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--probes", nargs="*", default=VALIDATION_PROBES)
    ap.add_argument("--materials", nargs="*", help="default: the near-Lambertian validation materials")
    ap.add_argument("--config", nargs="*", help="Config overrides, name=value (e.g. gmm_volume=1)")
    ap.add_argument("--gmm-only", action="store_true", help="only the GMM's -log p of the library by class")
    ap.add_argument("--report", action="store_true", help="write docs/start_diagnosis.md from the results file")
    args = ap.parse_args(argv)
    if args.report:
        return write_report()
    config = parse_config(args.config)
    import mi_dsbrdf  # noqa: F401
    from mi_dsbrdf.model import model_file
    by_class = gmm_by_highlight()
    logdet = [float(np.linalg.slogdet(c)[1]) for c in model_file.shipped_model().gmm.covariances]
    print("shipped GMM: log det of the components' covariances", " ".join("%.1f" % v for v in logdet))
    print(gmm_table(by_class))
    if args.gmm_only:
        return
    from mi_dsbrdf.evaluation.experiment import loo_model
    from mi_dsbrdf.inference.reflectance import reflectance_starts
    mats = args.materials or near_lambertian(VALIDATION_MATERIALS)
    # each leave-one-out model has its own number of GMM components (BIC's choice)
    n_starts = {m: len(reflectance_starts(loo_model(m, CACHE))) for m in mats}
    jobs = [(m, p, s, config) for m in mats for p in args.probes for s in [None] + list(range(n_starts[m]))]
    with ProcessPoolExecutor(2) as pool:
        rows = list(pool.map(_run, jobs))
    lines = []
    for m in mats:
        for p in args.probes:
            runs = [r for r in rows if r["material"] == m and r["probe"] == p and r["start"] != "all"]
            chosen = min(runs, key=lambda r: r["terms"]["neg_log_posterior"])
            best = min(runs, key=lambda r: r["brdf_eq20_paper"])
            lines.append({"material": m, "probe": p, "map_start": chosen["start"], "best_brdf_start": best["start"],
                          "posterior_gap": best["terms"]["neg_log_posterior"] - chosen["terms"]["neg_log_posterior"],
                          "likelihood_gap": best["terms"]["likelihood"] - chosen["terms"]["likelihood"],
                          "gmm_gap": best["terms"].get("gmm", 0.0) - chosen["terms"].get("gmm", 0.0),
                          "brdf": [chosen["brdf_eq20_paper"], best["brdf_eq20_paper"]]})
    print(tables(rows, lines))
    results = json.load(open(OUT)) if os.path.exists(OUT) else {}
    results[setting_name(config)] = {"command": "python benchmarks/start_diagnosis.py " + " ".join(argv or sys.argv[1:]),
                                     "rows": rows, "cases": lines, "gmm_by_highlight": by_class}
    with open(OUT, "w") as f:
        json.dump(results, f, indent=1, sort_keys=True)
    print("wrote", OUT, "(setting %s)" % setting_name(config))
    write_report()


if __name__ == "__main__":
    main()
