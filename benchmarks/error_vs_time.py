"""Error against run time: this tool beside Adam through Mitsuba's prb, 4 MERL materials x 2 probes.

Each (material, probe) pair is a synthetic case
(:func:`~mi_dsbrdf.evaluation.benchmark_cases.make_case`: 64x64 sphere, the
MERL material rendered under the probe at 64x128, a 32x64 map recovered,
leave-one-out model), run at several budgets by three methods:

* ``dsbrdf``: this tool, rounds x Levenberg-Marquardt iterations per block
  (1 x 5, 2 x 10, 3 x 15 = the default);
* ``dsbrdf-adam``: the same DSBRDF and envmap by Adam through ``prb``, 8 spp;
* ``principled-adam``: Mitsuba's tutorial recipe, ``principled`` + envmap by
  Adam through ``prb``, 8 spp;
* ``mean-constant``: doing nothing, the model's mean material under a constant
  map (no time; a dashed line in the figure).

Adam runs 50, 150 and 300 iterations. Every case runs in a single-threaded
Dask worker (two at a time), so the times are one core's. Measures, per run:
the BRDF's Eq. 20 in both conventions (the paper's log(f + 1e-6) and the
cosine-weighted log(1 + f cos theta_i)), the illumination map's and the relit
images' scale-invariant log errors (:mod:`mi_dsbrdf.evaluation.experiment`).

A run of this tool *dominates* an Adam run when it took no longer and its
error is no larger; the report lists every Adam run no run of this tool
dominates, per measure: where this tool's curve is not below.

    .venv/bin/python benchmarks/error_vs_time.py            # ~15 min on 2 cores; resumable
    .venv/bin/python benchmarks/error_vs_time.py --report   # redraw from the results

Writes out/error_vs_time/<id>.json (one a run) and docs/error_vs_time.{md,png}.
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import sys

import numpy as np

from mi_dsbrdf.evaluation.benchmark_cases import (CACHE, DATA, DOCS, OUT as OUT_ROOT, have_data, make_case, measure,
                                                  run_on_cluster)

OUT = os.path.join(OUT_ROOT, "error_vs_time")
MATERIALS = ["blue-acrylic", "gold-metallic-paint", "red-fabric", "pvc"]
PROBES = ["probulator/grace.hdr", "probulator/ennis.hdr"]
DSBRDF_BUDGETS = [(1, 5), (2, 10), (3, 15)]
ADAM_ITERS, ADAM_SPP = [50, 150, 300], 8
METHODS = ("dsbrdf", "dsbrdf-adam", "principled-adam")
BASELINE = "mean-constant"
MEASURES = {"brdf_eq20_paper": "BRDF Eq. 20, paper", "brdf_eq20_cosine": "BRDF Eq. 20, cosine",
            "illumination_error": "illumination", "relight": "relit images"}
COLOURS = {"dsbrdf": "C0", "dsbrdf-adam": "C1", "principled-adam": "C2"}


def cases() -> list:
    """Every run: per material and probe, this tool at each budget, doing nothing,
    and each Adam method at each number of iterations."""
    out = []
    for m in MATERIALS:
        for p in PROBES:
            for rounds, iters in DSBRDF_BUDGETS:
                out.append(make_case("budget", "probe", m, probe=p, rounds=rounds, iters=iters))
            out.append(make_case("budget", "probe", m, False, probe=p, method=BASELINE))
            for method in METHODS[1:]:
                for iters in ADAM_ITERS:
                    out.append(make_case("budget", "probe", m, False, probe=p, method=method, iters=iters,
                                         spp=ADAM_SPP))
    return out


def error(r, key) -> float:
    return float(measure(r, key))


def not_dominated(runs, key) -> list:
    """The Adam runs of one case that no ``dsbrdf`` run beats on ``key`` in no more time."""
    ours = [r for r in runs if r["case"]["method"] == "dsbrdf"]
    return [a for a in runs if a["case"]["method"] not in ("dsbrdf", BASELINE)
            and not any(o["seconds"] <= a["seconds"] and error(o, key) <= error(a, key) for o in ours)]


def _budget_label(case) -> str:
    """``3 x 15`` (rounds x iterations, this tool), ``150 it`` (Adam), ``–`` (doing nothing)."""
    if case["method"] == "dsbrdf":
        return "%d x %d" % (case["rounds"], case["iters"])
    return "–" if case["method"] == BASELINE else "%d it" % case["iters"]


def _by_budget(rs) -> dict:
    """The runs grouped by (method, budget size: rounds x iterations; 0 for doing nothing)."""
    out = {}
    for r in rs:
        c = r["case"]
        size = c.get("rounds", 1) * c.get("iters", 0) if c["method"] != BASELINE else 0
        out.setdefault((c["method"], size), []).append(r)
    return out


def write_report(results_dir=OUT, docs_dir=DOCS) -> str:
    """``docs/error_vs_time.{md,png}`` from the runs in ``results_dir``; returns the markdown's path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter, ScalarFormatter
    rs = [json.load(open(f)) for f in sorted(glob.glob(os.path.join(results_dir, "*.json")))]
    pairs = sorted({(r["case"]["material"], r["case"]["probe"]) for r in rs})
    fig, axes = plt.subplots(len(MEASURES), len(pairs), figsize=(2.6 * len(pairs), 2.3 * len(MEASURES)),
                             squeeze=False)
    misses = []
    for j, (m, p) in enumerate(pairs):
        runs = [r for r in rs if r["case"]["material"] == m and r["case"]["probe"] == p]
        for i, key in enumerate(MEASURES):
            ax = axes[i, j]
            for method in METHODS:
                sel = sorted([r for r in runs if r["case"]["method"] == method], key=lambda r: r["seconds"])
                ax.plot([r["seconds"] for r in sel], [error(r, key) for r in sel], "o-", ms=3,
                        color=COLOURS[method], label=method)
            for r in runs:
                if r["case"]["method"] == BASELINE:
                    ax.axhline(error(r, key), color="grey", ls="--", lw=1, label="mean material, constant map")
            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(ScalarFormatter())
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xticks([5, 10, 20, 40])
            ax.tick_params(labelsize=6)
            if i == 0:
                ax.set_title("%s\n%s" % (m, os.path.splitext(os.path.basename(p))[0]), fontsize=7)
            if j == 0:
                ax.set_ylabel(MEASURES[key], fontsize=7)
            if i == len(MEASURES) - 1:
                ax.set_xlabel("seconds (one core)", fontsize=7)
            for a in not_dominated(runs, key):
                misses.append((m, os.path.basename(p), MEASURES[key], a))
    axes[0, 0].legend(fontsize=6)
    fig.tight_layout()
    os.makedirs(docs_dir, exist_ok=True)
    fig.savefig(os.path.join(docs_dir, "error_vs_time.png"), dpi=110)
    plt.close(fig)
    n_adam = sum(r["case"]["method"] not in ("dsbrdf", BASELINE) for r in rs)
    md = ["# Error against run time", "",
          "Generated by `benchmarks/error_vs_time.py` (its docstring says what runs). Blue: this tool at",
          "3 budgets; orange: the DSBRDF by Adam through `prb`; green: `principled` by Adam through `prb`",
          "(Mitsuba's recipe); 8 spp, 50/150/300 iterations. One core per run. Materials and probes are",
          "the experiments' quick set; nothing here was tuned on them.", "",
          "![error against time](error_vs_time.png)", "",
          "## Against doing nothing", "",
          "Runs worse than the model's mean material under a constant map (the dashed line), per",
          "measure, out of all runs of the method:", "",
          "| method | " + " | ".join(MEASURES.values()) + " |", "|---|" + "---|" * len(MEASURES)]
    for method in METHODS:
        cells = []
        for key in MEASURES:
            worse = total = 0
            for m, p in pairs:
                base = [r for r in rs if r["case"]["material"] == m and r["case"]["probe"] == p
                        and r["case"]["method"] == BASELINE]
                for r in rs:
                    if r["case"]["material"] == m and r["case"]["probe"] == p and r["case"]["method"] == method:
                        total += 1
                        worse += bool(base) and error(r, key) > error(base[0], key)
            cells.append("%d / %d" % (worse, total))
        md.append("| %s | %s |" % (method, " | ".join(cells)))
    md += ["", "## Medians per method and budget", "",
           "Over the %d cases (material x probe); seconds of one core:" % len(pairs), "",
           "| method | budget | seconds | " + " | ".join(MEASURES.values()) + " |",
           "|---|---|---|" + "---|" * len(MEASURES)]
    for (method, _), runs in sorted(_by_budget(rs).items(), key=lambda kv: (METHODS.index(kv[0][0])
                                                                               if kv[0][0] in METHODS else 99,
                                                                               kv[0][1])):
        md.append("| %s | %s | %.1f | %s |" % (
            method, _budget_label(runs[0]["case"]), float(np.median([r["seconds"] for r in runs])),
            " | ".join("%.3f" % float(np.median([error(r, k) for r in runs])) for k in MEASURES)))
    md += ["", "## Where this tool's curve is not below", "",
           "An Adam run is listed under a measure when no run of this tool took no longer *and* erred no",
           "more. %d Adam runs x %d measures = %d comparisons; %d are listed." % (
               n_adam, len(MEASURES), n_adam * len(MEASURES), len(misses)), ""]
    if misses:
        md += ["| material | probe | measure | Adam run | its seconds | its error | best of ours in that time |",
               "|---|---|---|---|---|---|---|"]
        for m, p, label, a in misses:
            key = [k for k, v in MEASURES.items() if v == label][0]
            runs = [r for r in rs if r["case"]["material"] == m and os.path.basename(r["case"]["probe"]) == p
                    and r["case"]["method"] == "dsbrdf" and r["seconds"] <= a["seconds"]]
            best = min((error(r, key) for r in runs), default=None)
            md.append("| %s | %s | %s | %s %d it | %.1f | %.3f | %s |" % (
                m, p, label, a["case"]["method"], a["case"]["iters"], a["seconds"], error(a, key),
                "none that fast" if best is None else "%.3f" % best))
    md += ["", "## Every run", "",
           "| material | probe | method | budget | seconds | " + " | ".join(MEASURES.values()) + " |",
           "|---|---|---|---|---|" + "---|" * len(MEASURES)]
    for r in sorted(rs, key=lambda r: (r["case"]["material"], r["case"]["probe"], r["case"]["method"],
                                       r["seconds"])):
        c = r["case"]
        md.append("| %s | %s | %s | %s | %.1f | %s |" % (
            c["material"], os.path.basename(c["probe"]), c["method"], _budget_label(c), r["seconds"],
            " | ".join("%.3f" % error(r, k) for k in MEASURES)))
    path = os.path.join(docs_dir, "error_vs_time.md")
    with open(path, "w") as f:
        f.write("\n".join(md) + "\n")
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--report", action="store_true", help="only redraw the report from the results")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--data", default=DATA)
    ap.add_argument("--out", default=OUT)
    args = ap.parse_args(argv)
    if not args.report:
        if not have_data(args.data):
            sys.exit("this benchmark needs the MERL fits under %s (see ../shared/data/README.md)" % args.data)
        s = run_on_cluster(cases(), args.out, args.data, args.workers, cache=CACHE)
        if s["failed"]:
            sys.exit(1)
    print(write_report(args.out))


if __name__ == "__main__":
    main()
