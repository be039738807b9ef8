"""The experiments of paper §6 on synthetic MERL renders (on Dask) and their report.

Groups of cases (:func:`cases`; each case is run and scored by
:func:`mi_dsbrdf.evaluation.experiment.run_case`, always with a leave-one-out model):

* point: MERL materials x a point light at 30/60/90 deg from the viewer
  (``--full``: 0, 30, 60, 90, 120 and every material), with and without priors (§6.1);
* probe: MERL materials x real light probes, with and without priors (§6.2);
* stiff: chrome (mirror-like), pink felt (near-Lambertian), a light at 120 deg
  (mostly unlit), a sun thousands of times brighter than its sky, a torus (non-convex).

Measured per case: the BRDF's Eq. 20 and Eq. 5 in both conventions, the light's
direction error, the illumination map's and the relit images' scale-invariant
log errors, the run time and whether every number is finite.

Resumable: each case writes ``out/experiments/<id>.json`` (and ``<id>.npz``, its
relit images) when it finishes, and a rerun skips the cases whose file exists.
Parallel on Dask: a LocalCluster of ``--workers`` single-threaded processes by
default, or ``--scheduler tcp://host:8786`` for a cluster (its workers need
this package installed, ``--data`` at the same path and one thread each,
``dask worker --nthreads 1``: Dr.Jit in several threads of one process crashed).

    .venv/bin/python benchmarks/experiments.py              # quick subset, 39 cases, 4-8 min on 2 workers
    .venv/bin/python benchmarks/experiments.py --full
    .venv/bin/python benchmarks/experiments.py --report     # -> docs/experiments.md, docs/experiments/*.png
    .venv/bin/python benchmarks/experiments.py --compare BEFORE_DIR   # markdown: BEFORE_DIR against --out, case by case
    .venv/bin/python benchmarks/experiments.py --groups point --materials M ... --out DIR   # point lights only
    .venv/bin/python benchmarks/experiments.py --posterior --out DIR   # their posterior band at each temperature

``--compare`` pairs two runs case by case (the code before a change, run with
``--out BEFORE_DIR`` from a worktree of it, against the code after).
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import sys

import numpy as np

from mi_dsbrdf.evaluation.benchmark_cases import (DATA, DOCS, OUT as OUT_ROOT, have_data, make_case, measure,
                                                  posterior_table, recovered_glossy, run_on_cluster, tonemap)

OUT = os.path.join(OUT_ROOT, "experiments")
QUICK_MATERIALS = ["blue-acrylic", "gold-metallic-paint", "red-fabric", "pvc"]
PROBES = ["probulator/grace.hdr", "probulator/ennis.hdr", "probulator/pisa.hdr", "probulator/uffizi.hdr",
          "probulator/wells.hdr"]
SUN_PROBE = "polyhaven/blouberg_sunrise_2_1k.hdr"


def cases(full=False, materials=None, data=DATA) -> list:
    """The case list: the quick subset, or with ``full`` every MERL material, angle and probe."""
    from mi_dsbrdf.brdf.measured import nbrdf_names
    mats = materials or (nbrdf_names(os.path.join(data, "merl", "merl_nbrdf_weights.npz")) if full
                         else QUICK_MATERIALS)
    angles = [0, 30, 60, 90, 120] if full else [30, 60, 90]
    probes = PROBES if full else PROBES[:1]
    out = []
    for m in mats:
        for a in angles:
            for p in (True, False):
                out.append(make_case("point", "point", m, p, angle=a))
        for probe in probes:
            for p in (True, False):
                out.append(make_case("probe", "probe", m, p, probe=probe))
    grace = PROBES[0]
    out += [make_case("stiff", "point", "chrome", angle=60), make_case("stiff", "probe", "chrome", probe=grace),
            make_case("stiff", "point", "pink-felt", angle=60), make_case("stiff", "probe", "pink-felt", probe=grace),
            make_case("stiff", "point", "gold-metallic-paint", angle=120),
            make_case("stiff", "probe", "gold-metallic-paint", probe=SUN_PROBE),
            make_case("stiff", "probe", "blue-acrylic", probe=grace, shape="torus")]
    ids = [c["id"] for c in out]
    assert len(ids) == len(set(ids)), "case ids must be unique"
    return out


# --- the report ----------------------------------------------------------------------

def load(results_dir) -> list:
    """The results of a folder, each with ``images_file`` (its .npz or None)."""
    out = []
    for path in sorted(glob.glob(os.path.join(results_dir, "*.json"))):
        with open(path) as f:
            r = json.load(f)
        npz = path[:-5] + ".npz"
        r["images_file"] = npz if os.path.exists(npz) else None
        out.append(r)
    return out


def _label(r) -> str:
    c = r["case"]
    where = "%d°" % c["angle"] if c["kind"] == "point" else os.path.splitext(os.path.basename(c["probe"]))[0]
    shape = "" if c.get("shape", "sphere") == "sphere" else " (%s)" % c["shape"]
    return "%s %s%s" % (c["material"], where, shape)


def _median(values) -> str:
    v = [x for x in values if x is not None]
    return "%.3f" % float(np.median(v)) if v else "–"


def _save(fig, fig_dir, name) -> None:
    import matplotlib.pyplot as plt
    fig.tight_layout()
    fig.savefig(os.path.join(fig_dir, name), dpi=110)
    plt.close(fig)


def _fmt(r, key, fmt) -> str:
    """``fmt % r[key]``, or a dash for a measure this case does not have."""
    return fmt % r[key] if key in r else "–"


def write_report(results_dir=OUT, docs_dir=DOCS) -> str:
    """``docs/experiments.md`` and ``docs/experiments/*.png`` (the paper's Fig. 5-9 style
    plots) from the results in ``results_dir``; returns the markdown's path."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rs = load(results_dir)
    fig_dir = os.path.join(docs_dir, "experiments")
    os.makedirs(fig_dir, exist_ok=True)
    by_id = {r["case"]["id"]: r for r in rs}
    group = {g: [r for r in rs if r["case"]["group"] == g] for g in ("point", "probe", "stiff")}
    md = ["# Experiments: recovery of MERL materials from synthetic images",
          "",
          "Generated by `.venv/bin/python benchmarks/experiments.py` (the quick subset; `--full` for every",
          "MERL material, angle and probe) and `.venv/bin/python benchmarks/experiments.py --report`.",
          "Every case renders a MERL material (its neural fit, with the `merl` plugin) on a %d px sphere" % (
              rs[0]["case"]["res"] if rs else 64),
          "(under a point light each pixel the mean of 8×8 rays across it, as a camera's; the tool sees",
          "4×4, `--pixel-rays`) and recovers it with a reflectance model that never saw it (leave-one-out",
          "bases and priors).",
          "Eq. 20 is the BRDF's log-RMSE on the MERL grid after the best overall scale; Eq. 5 uses the",
          "known light intensity instead. Both are given in the paper's convention, log(f + 1e-6) (\"paper\"),",
          "and the cosine-weighted one, log(1 + f cos θi) (\"cosine\"), which hardly sees diffuse and dark",
          "errors.",
          "Illumination error: the same log-RMSE after the best scale on the",
          "texels of the recovered map that a pixel sees, against the probe at that resolution. Relit",
          "error: that measure on the pixels of the material relit under two other probes (32×64 maps)",
          "against the measured material under them.", ""]

    # --- summary -------------------------------------------------------------------
    md += ["## Summary", "", "Eq. 20 observed: on the (θh, θd) the used pixels see under the true light "
           "(`Material.observed`).", "",
           "| cases | n | direction error (median / max) | Eq. 5, paper | Eq. 5, cosine | "
           "Eq. 20, paper | Eq. 20, cosine | Eq. 20 observed, paper | Eq. 20 observed, cosine | illumination | relit |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for g in ("point", "probe"):
        for priors in (True, False):
            sel = [r for r in group[g] if r["case"]["priors"] == priors]
            if not sel:
                continue
            d = [r.get("direction_error_deg") for r in sel if "direction_error_deg" in r]
            md.append("| %s, %s | %d | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
                g, "priors" if priors else "no priors", len(sel),
                "%.2f° / %.2f°" % (np.median(d), np.max(d)) if d else "–",
                _median([r.get("brdf_eq5_paper") for r in sel]), _median([r.get("brdf_eq5_cosine") for r in sel]),
                _median([r.get("brdf_eq20_paper") for r in sel]),
                _median([r["brdf_eq20_cosine"] for r in sel]),
                _median([r.get("brdf_eq20_observed_paper") for r in sel]),
                _median([r.get("brdf_eq20_observed_cosine") for r in sel]),
                _median([r.get("illumination_error") for r in sel]),
                _median([measure(r, "relight") for r in sel])))
    md.append("")

    # --- Fig. 5: sorted error per case ---------------------------------------------------
    panels = [(g, sorted([r for r in group[g] if r["case"]["priors"]], key=lambda r: r["brdf_eq20_cosine"]))
              for g in ("point", "probe")]
    panels = [p for p in panels if p[1]]
    if panels:
        fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 4), squeeze=False)
        for ax, (g, sel) in zip(axes[0], panels):
            ax.bar(range(len(sel)), [r["brdf_eq20_cosine"] for r in sel], color="C0")
            ax.set_xticks(range(len(sel)))
            ax.set_xticklabels([_label(r) for r in sel], rotation=70, ha="right", fontsize=7)
            ax.set_ylabel("BRDF error, Eq. 20 (cosine)")
            ax.set_title("%s light, with priors (sorted)" % g)
        _save(fig, fig_dir, "fig5_sorted_error.png")
        md += ["## Error per case (Fig. 5)", "", "![sorted error](experiments/fig5_sorted_error.png)", ""]

    # --- Fig. 6: direction errors --------------------------------------------------------
    d = [r["direction_error_deg"] for r in rs if "direction_error_deg" in r]
    if d:
        fig, ax = plt.subplots(figsize=(5, 3.5))
        ax.hist(d, bins=np.linspace(0, max(2.0, max(d) * 1.05), 21), color="C2")
        ax.set_xlabel("light direction error (deg)")
        ax.set_ylabel("cases")
        ax.set_title("point light, %d cases (median %.2f°, max %.2f°)" % (len(d), np.median(d), np.max(d)))
        _save(fig, fig_dir, "fig6_direction_error.png")
        md += ["## Light direction (Fig. 6)", "", "![direction error](experiments/fig6_direction_error.png)", ""]

    # --- Fig. 7: with vs without priors ---------------------------------------------------
    pairs = [(r, by_id.get(r["case"]["id"][:-len("priors")] + "nopriors")) for r in rs
             if r["case"]["priors"] and r["case"]["group"] in ("point", "probe")]
    pairs = [(a, b) for a, b in pairs if b is not None]
    if pairs:
        fig, ax = plt.subplots(figsize=(4.5, 4.5))
        for g, mk in (("point", "o"), ("probe", "s")):
            sel = [(a, b) for a, b in pairs if a["case"]["group"] == g]
            if sel:
                ax.scatter([b["brdf_eq20_cosine"] for a, b in sel], [a["brdf_eq20_cosine"] for a, b in sel], marker=mk,
                           label="%s (%d)" % (g, len(sel)))
        top = max(max(a["brdf_eq20_cosine"], b["brdf_eq20_cosine"]) for a, b in pairs) * 1.1
        ax.plot([0, top], [0, top], "k:", lw=1)
        ax.set_xlabel("Eq. 20 (cosine) without priors")
        ax.set_ylabel("Eq. 20 (cosine) with priors")
        ax.set_title("below the line: the priors help")
        ax.legend()
        _save(fig, fig_dir, "fig7_priors.png")
        wins = sum(a["brdf_eq20_cosine"] < b["brdf_eq20_cosine"] for a, b in pairs)
        md += ["## With and without priors (Fig. 7)", "",
               "The priors lower Eq. 20 (cosine) in %d of %d paired cases." % (wins, len(pairs)), "",
               "![priors](experiments/fig7_priors.png)", "",
               "| case | Eq. 20 (cosine) with priors | without |", "|---|---|---|"]
        md += ["| %s (%s) | %.3f | %.3f |" % (_label(a), a["case"]["group"], a["brdf_eq20_cosine"],
                                              b["brdf_eq20_cosine"]) for a, b in pairs]
        md.append("")

    # --- Fig. 8: illumination error against specularity ------------------------------------
    sel = [r for r in rs if r["case"]["kind"] == "probe" and r["case"]["priors"] and r["case"]["method"] == "dsbrdf"]
    if sel:
        fig, ax = plt.subplots(figsize=(5, 3.5))
        ax.scatter([r["specularity"] for r in sel], [r["illumination_error"] for r in sel])
        for r in sel:
            ax.annotate(_label(r), (r["specularity"], r["illumination_error"]), fontsize=6)
        ax.set_xscale("log")
        ax.set_xlabel("γ of the most specular lobe (θd = 0)")
        ax.set_ylabel("illumination error (log-RMSE, best scale)")
        _save(fig, fig_dir, "fig8_illumination_vs_specularity.png")
        md += ["## Illumination against specularity (Fig. 8)", "",
               "![illumination error](experiments/fig8_illumination_vs_specularity.png)", ""]

    # --- Fig. 9: relighting ---------------------------------------------------------------
    sel = [r for r in group["probe"] if r["case"]["priors"] and r["images_file"]][:4] or \
        [r for r in rs if r["images_file"]][:4]
    if sel:
        keys = sorted(sel[0]["relight"])
        fig, axes = plt.subplots(len(sel), 2 * len(keys), figsize=(2 * 2 * len(keys), 2 * len(sel)), squeeze=False)
        for row, r in zip(axes, sel):
            with np.load(r["images_file"]) as f:
                for j, k in enumerate(keys):
                    truth, rec = f[k].astype(np.float64)
                    ref = np.percentile(truth[truth.sum(axis=2) > 0], 99) if np.any(truth > 0) else 1.0
                    row[2 * j].imshow(tonemap(truth, ref))
                    row[2 * j + 1].imshow(tonemap(rec, ref))
                    row[2 * j].set_title("%s: measured" % k, fontsize=8)
                    row[2 * j + 1].set_title("recovered (%.3f)" % r["relight"][k], fontsize=8)
            row[0].set_ylabel(_label(r), fontsize=8)
            for ax in row:
                ax.set_xticks([])
                ax.set_yticks([])
        _save(fig, fig_dir, "fig9_relighting.png")
        md += ["## Relighting (Fig. 9)", "",
               "Each recovered material under two probes it was not recovered under, beside the measured",
               "material (the recovered one at the best overall scale; in brackets its relit error).", "",
               "![relighting](experiments/fig9_relighting.png)", ""]

    md += ["Error against run time: [`error_vs_time.md`](error_vs_time.md) (`benchmarks/error_vs_time.py`).", ""]

    # --- stiff and extreme cases -------------------------------------------------------------
    sel = group["stiff"]
    if sel:
        fig, ax = plt.subplots(figsize=(6, 3.8))
        for r in sel:
            t = np.asarray(r["trace"], np.float64)
            if t.size:
                ax.plot(np.arange(t.size), t / t[0], "o-", ms=3, label=_label(r))
        ax.set_yscale("log")
        ax.set_xlabel("logged round (light search / starts, then rounds)")
        ax.set_ylabel("−log posterior / first value")
        ax.legend(fontsize=7)
        _save(fig, fig_dir, "stiff_traces.png")
        md += ["## Stiff and extreme cases", "",
               "How each converges: logged rounds, the negative log posterior at the first and last",
               "of them, and whether every number of the result is finite.", "",
               "| case | rounds | −log posterior first → last | finite | Eq. 20, cosine | direction | "
               "illumination | s |",
               "|---|---|---|---|---|---|---|---|"]
        for r in sel:
            t = r["trace"]
            md.append("| %s | %d | %.4g → %.4g | %s | %.3f | %s | %s | %.0f |" % (
                _label(r), r["rounds"], t[0], t[-1], "yes" if r["finite"] else "**no**", r["brdf_eq20_cosine"],
                _fmt(r, "direction_error_deg", "%.2f°"), _fmt(r, "illumination_error", "%.3f"), r["seconds"]))
        md += ["", "![traces](experiments/stiff_traces.png)", ""]

    # --- all cases --------------------------------------------------------------------------
    md += ["## Every case", "", "| id | Eq. 20, paper | Eq. 20, cosine | Eq. 5, paper | Eq. 5, cosine | direction "
           "| illumination | relit | s |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rs:
        md.append("| %s | %s | %.3f | %s | %s | %s | %s | %.3f | %.0f |" % (
            r["case"]["id"], _fmt(r, "brdf_eq20_paper", "%.3f"), r["brdf_eq20_cosine"],
            _fmt(r, "brdf_eq5_paper", "%.3f"), _fmt(r, "brdf_eq5_cosine", "%.3f"),
            _fmt(r, "direction_error_deg", "%.2f°"),
            _fmt(r, "illumination_error", "%.3f"),
            measure(r, "relight"), r["seconds"]))
    path = os.path.join(docs_dir, "experiments.md")
    with open(path, "w") as f:
        f.write("\n".join(md) + "\n")
    return path


# --- two runs, case by case --------------------------------------------------------------

#: the measures --compare pairs: (key, label)
COMPARE_MEASURES = [("brdf_eq20_paper", "Eq. 20 paper"), ("brdf_eq20_cosine", "Eq. 20 cosine"),
                    ("illumination_error", "illumination"), ("direction_error_deg", "direction °"),
                    ("relight", "relit")]


def load_by_id(folder) -> dict:
    """{case id: result} of a folder."""
    return {os.path.basename(f)[:-5]: json.load(open(f)) for f in glob.glob(os.path.join(folder, "*.json"))}


def compare(before, after) -> str:
    """Markdown: the runs in ``before`` and ``after`` case by case, and their medians per group."""
    a, b = load_by_id(before), load_by_id(after)
    ids = sorted(set(a) & set(b))
    md = ["# Accuracy and time before and after a change", "",
          "`%s` against `%s`, case by case (`benchmarks/experiments.py --compare`). Lower is better;" % (
              before, after), "seconds are one core's (two cases at a time).", "",
          "## Medians per group", "", "| group | cases | " + " | ".join(
              "%s before → after" % label for _, label in COMPARE_MEASURES) + " | seconds, total |",
          "|---|---|" + "---|" * len(COMPARE_MEASURES) + "---|"]
    for group in ("probe", "point", "stiff"):
        sel = [i for i in ids if a[i]["case"]["group"] == group]
        if not sel:
            continue
        cells = []
        for key, _ in COMPARE_MEASURES:
            x = [measure(a[i], key) for i in sel if measure(a[i], key) is not None]
            y = [measure(b[i], key) for i in sel if measure(b[i], key) is not None]
            cells.append("%.3f → %.3f" % (np.median(x), np.median(y)) if x and y else "–")
        md.append("| %s | %d | %s | %.0f → %.0f |" % (group, len(sel), " | ".join(cells),
                                                      sum(a[i]["seconds"] for i in sel),
                                                      sum(b[i]["seconds"] for i in sel)))
    md += ["", "## Every case", "",
           "| case | " + " | ".join(label for _, label in COMPARE_MEASURES) + " | seconds |",
           "|---|" + "---|" * len(COMPARE_MEASURES) + "---|"]
    for i in ids:
        cells = []
        for key, _ in COMPARE_MEASURES:
            x, y = measure(a[i], key), measure(b[i], key)
            cells.append("–" if x is None or y is None else "%.3f → %.3f%s" % (
                x, y, " **worse**" if y > 1.1 * x + 0.01 else ""))
        md.append("| %s | %s | %.0f → %.0f |" % (i, " | ".join(cells), a[i]["seconds"], b[i]["seconds"]))
    return "\n".join(md) + "\n"


def posterior_summary(results_dir) -> str:
    """Markdown: the posterior band of the point-light cases with priors in
    ``results_dir`` against the truth at each temperature
    (:func:`~mi_dsbrdf.evaluation.benchmark_cases.posterior_table`; on the
    validation materials, the choice of
    ``mi_dsbrdf.inference.uncertainty.LIGHT_POSTERIOR_TEMPERATURE``), and whom the
    highlight flag fires on."""
    rows = [r for r in load(results_dir) if r["case"]["kind"] == "point" and r["case"].get("priors", True)]
    glossy = [r for r in rows if recovered_glossy(r)]
    return "%s\n\nThe highlight flag fires on %d of %d near-Lambertian materials recovered glossy and on %d of %d " \
        "other cases.\n" % (posterior_table(rows), sum(bool(r.get("flags")) for r in glossy), len(glossy),
                            sum(bool(r.get("flags")) for r in rows if r not in glossy), len(rows) - len(glossy))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--full", action="store_true", help="every MERL material, angle and probe")
    ap.add_argument("--groups", nargs="*", choices=["point", "probe", "stiff"])
    ap.add_argument("--materials", nargs="*", help="materials of the point and probe groups")
    ap.add_argument("--workers", type=int, default=2, help="local worker processes (one thread each)")
    ap.add_argument("--scheduler", help="address of a Dask scheduler (default: a local cluster)")
    ap.add_argument("--data", default=DATA)
    ap.add_argument("--out", default=OUT, help="the results folder (default %(default)s)")
    ap.add_argument("--report", action="store_true",
                    help="only write docs/experiments.md and docs/experiments/*.png from the results in --out")
    ap.add_argument("--docs", default=DOCS, help="where --report writes (default %(default)s)")
    ap.add_argument("--compare", metavar="BEFORE_DIR",
                    help="only print, as markdown, the results in BEFORE_DIR against those in --out, case by case")
    ap.add_argument("--posterior", action="store_true",
                    help="only print the posterior band's table of the point cases with priors in --out")
    args = ap.parse_args(argv)
    if args.posterior:
        print(posterior_summary(args.out))
        return
    if args.report:
        print("wrote", write_report(args.out, args.docs))
        return
    if args.compare:
        sys.stdout.write(compare(args.compare, args.out))
        return
    if not have_data(args.data):
        sys.exit("the experiments need the MERL fits under %s (see ../shared/data/README.md)" % args.data)
    todo = [c for c in cases(args.full, args.materials, args.data) if not args.groups or c["group"] in args.groups]
    s = run_on_cluster(todo, args.out, args.data, args.workers, args.scheduler)
    sys.exit(1 if s["failed"] else 0)


if __name__ == "__main__":
    main()
