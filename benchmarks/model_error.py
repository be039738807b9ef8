"""Modelling error of the reflectance models on MERL (the paper's Fig. 2).

For every MERL material, the log-RMSE of Eq. 5 in both conventions (the paper's,
log(f + 1e-6), and the cosine-weighted log(1 + f cos theta_i); see
mi_dsbrdf/evaluation/metrics.py) on a dense slice of the MERL grid (every
theta_h and theta_d, every 6th phi_d; ~10x the samples the fits use) of

    Lambert + 1 Cook-Torrance lobe        10 variables
    Lambert + 3 Cook-Torrance lobes       24
    DSBRDF, 7 bases + chromaticity        13   (leave-one-out basis)
    DSBRDF, 10 bases + chromaticity       16   (leave-one-out basis)
    DSBRDF, full B-spline curves          42   (the model file's per-material fit)
    bivariate table (theta_h, theta_d)    8100 x 3 (the data averaged over phi_d)

The DSBRDF bases for a material are rebuilt (functional PCA) from the full
fits of the other 99 materials, so no material is scored on a basis that saw
it. Cook-Torrance models are fitted with the DSBRDF fits' objective on a coarser
slice (every 6th theta_d, every 30th phi_d) to keep the run short. Writes

    benchmarks/results/model_error.json   per-material errors and medians
    docs/model_error.md                   table of medians and quartiles
    docs/model_error.png                  all materials, sorted (Fig. 2)

    .venv/bin/python benchmarks/model_error.py [--merl ../shared/data/merl/merl_nbrdf_weights.npz]
        [--workers 2] [--only NAME ...]          # ~14 min on 2 cores
    .venv/bin/python benchmarks/model_error.py --report-only   # the docs again from the JSON
"""
import argparse
import json
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from mi_dsbrdf.backend import one_blas_thread

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MODELS = [("lambert_ct1", "Lambert + 1 CT lobe", 10), ("lambert_ct3", "Lambert + 3 CT lobes", 24),
          ("dsbrdf_7", "DSBRDF, 7 bases", 13), ("dsbrdf_10", "DSBRDF, 10 bases", 16),
          ("dsbrdf_full", "DSBRDF, full B-spline", 42), ("bivariate", "bivariate table", 8100 * 3)]


def score(job):
    source, model_file, name = job
    from mi_dsbrdf.model import baselines
    from mi_dsbrdf.model import build as build_model
    from mi_dsbrdf.model import fitting
    from mi_dsbrdf.brdf.dsbrdf import Material
    from mi_dsbrdf.model.fpca import fpca, l2_inner
    from mi_dsbrdf.brdf.measured import MeasuredBRDF, grid_angles
    from mi_dsbrdf.evaluation.metrics import CONVENTIONS, log_rmse
    from mi_dsbrdf.model import samples
    from mi_dsbrdf.model.model_file import load_model
    t0 = time.perf_counter()
    a = load_model(model_file).arrays
    names = [str(n) for n in a["fit_names"]]
    i = names.index(name)
    sub = samples.grid_subset(theta_d_step=1, phi_d_step=6)
    ev = build_model.load_samples(source, name, sub)
    fit = build_model.load_samples(source, name)
    coarse = build_model.load_samples(source, name, samples.grid_subset(theta_d_step=6, phi_d_step=30))

    def err(values):
        return {c: log_rmse(values, ev.values, ev.cos_i, c) for c in CONVENTIONS}

    out = {}
    p1, _ = baselines.fit_cook_torrance(coarse, 1)
    out["lambert_ct1"] = err(baselines.cook_torrance(p1, ev.theta_h, ev.theta_d, ev.phi_d, 1))
    p3, _ = baselines.fit_cook_torrance(coarse, 3, start=p1)
    out["lambert_ct3"] = err(baselines.cook_torrance(p3, ev.theta_h, ev.theta_d, ev.phi_d, 3))
    others = np.delete(a["fit_controls"], i, axis=0)
    pca = fpca(others)                                     # leave-one-out bases
    ctrl = a["fit_controls"][i]
    for k in (7, 10):
        basis = pca.basis(k)
        psi0 = np.array([l2_inner(ctrl - basis.mean, b) for b in basis.bases])
        f = fitting.fit_basis(fit, basis, psi0, a["fit_chroma"][i])
        out["dsbrdf_%d" % k] = err(f.material.eval(ev.theta_h, ev.theta_d))
    full = Material(ctrl[:, 0], ctrl[:, 1], a["fit_chroma"][i])
    out["dsbrdf_full"] = err(full.eval(ev.theta_h, ev.theta_d))
    if os.path.isdir(source):
        table = MeasuredBRDF.from_binary(os.path.join(source, name + ".binary"))
    else:
        table = MeasuredBRDF.from_nbrdf(source, name)
    biv = table.bivariate()
    th, td, _ = grid_angles()
    ih = np.searchsorted(th, ev.theta_h - 1e-12)
    jd = np.searchsorted(td, ev.theta_d - 1e-12)
    out["bivariate"] = err(biv[ih, jd].astype(np.float64))
    out["seconds"] = time.perf_counter() - t0
    return name, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--merl", default=os.path.join(ROOT, "..", "shared", "data", "merl", "merl_nbrdf_weights.npz"))
    ap.add_argument("--model", default=os.path.join(ROOT, "mi_dsbrdf", "data", "model.npz"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", nargs="*", help="score only these materials (no files written)")
    ap.add_argument("--report-only", action="store_true",
                    help="rewrite docs/model_error.{md,png} from benchmarks/results/model_error.json")
    args = ap.parse_args()
    if args.report_only:
        with open(os.path.join(ROOT, "benchmarks", "results", "model_error.json")) as f:
            d = json.load(f)
        write_report(d["materials"], sorted(d["materials"]), d["medians"], d.get("in_sample"))
        return
    from tqdm import tqdm
    from mi_dsbrdf.model.model_file import load_model
    a = load_model(args.model).arrays
    names = [str(n) for n in a["fit_names"]]
    in_sample = {"full": {"paper": a["fit_error"].tolist(), "cosine": a["fit_error_cosine"].tolist()},
                 "library": {"paper": a["library_error"].tolist(), "cosine": a["library_error_cosine"].tolist()}}
    if args.only:
        names = args.only
    jobs = [(os.path.abspath(args.merl), os.path.abspath(args.model), n) for n in names]
    t0 = time.perf_counter()
    one_blas_thread()
    with ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("spawn")) as ex:
        rows = dict(tqdm(ex.map(score, jobs), total=len(jobs), desc="materials", file=sys.stderr))
    seconds = time.perf_counter() - t0
    med = {c: {k: float(np.median([rows[n][k][c] for n in names])) for k, _, _ in MODELS} for c in ("paper", "cosine")}
    for k, label, nv in MODELS:
        print("%-24s %6d variables  median paper %.4f  cosine %.4f" % (label, nv, med["paper"][k], med["cosine"][k]))
    if args.only:
        return
    res_dir = os.path.join(ROOT, "benchmarks", "results")
    os.makedirs(res_dir, exist_ok=True)
    with open(os.path.join(res_dir, "model_error.json"), "w") as f:
        json.dump({"command": "python benchmarks/model_error.py", "source": os.path.basename(args.merl),
                   "seconds": round(seconds, 1), "medians": med, "in_sample": in_sample, "materials": rows},
                  f, indent=1, sort_keys=True)
    write_report(rows, names, med, in_sample)


def write_report(rows, names, med, library=None):
    """docs/model_error.{md,png} from per-material errors ``rows[name][model][convention]``.
    ``library``: in-sample errors of the model file ({"full"/"library": {convention: (M,)}})."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    conventions = ("paper", "cosine")
    titles = {"paper": "paper's convention, log(f + 1e-6)", "cosine": "cosine-weighted, log(1 + f cos θi)"}
    fig, axes = plt.subplots(1, 2, figsize=(15, 5))
    for ax, c in zip(axes, conventions):
        order = sorted(names, key=lambda n: rows[n]["dsbrdf_10"][c])
        for (k, label, nv), mk in zip(MODELS, "v^osD."):
            ax.plot(range(len(order)), [rows[n][k][c] for n in order], mk + "-", ms=3, lw=0.8,
                    label="%s (%d), median %.3f" % (label, nv, med[c][k]))
        ax.set_yscale("log")
        ax.set_xlabel("MERL material (sorted by DSBRDF-10 error)")
        ax.set_ylabel("log-RMSE, Eq. 5")
        ax.set_title(titles[c])
        ax.legend(fontsize=7, loc="upper left")
        ax.grid(alpha=0.3, which="both")
    fig.suptitle("Modelling error on MERL (DSBRDF bases leave-one-out)")
    fig.tight_layout()
    fig.savefig(os.path.join(ROOT, "docs", "model_error.png"), dpi=100)

    def stats(k, c):
        e = np.array([rows[n][k][c] for n in names])
        return "%.4f | %.4f–%.4f | %.4f" % (np.median(e), np.percentile(e, 25), np.percentile(e, 75), e.max())
    lines = ["# Modelling error on MERL (paper Fig. 2)", "",
             "Regenerate: `.venv/bin/python benchmarks/model_error.py` (writes this file, "
             "`docs/model_error.png` and `benchmarks/results/model_error.json`).", "",
             "Log-RMSE of Eq. 5 per material on a dense slice of the MERL grid, in both conventions: the "
             "paper's, log(f + 1e-6) − log(ρ + 1e-6), which weighs every decade of the BRDF alike (the dark "
             "half included), and the cosine-weighted log(1 + f cos θi) − log(1 + ρ cos θi) of graphics "
             "fitting, which hardly sees values below 0.1/sr. DSBRDF bases are rebuilt without the scored "
             "material (leave-one-out).", "",
             "| model | variables | paper: median | paper: 25–75 % | paper: max | cosine: median | "
             "cosine: 25–75 % | cosine: max |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for k, label, nv in MODELS:
        lines.append("| %s | %d | %s | %s |" % (label, nv, stats(k, "paper"), stats(k, "cosine")))
    lines.append("")
    for c in conventions:
        better = sum(rows[n]["dsbrdf_10"][c] < rows[n]["lambert_ct3"][c] for n in names)
        worst = sorted(names, key=lambda n: -rows[n]["dsbrdf_10"][c])[:6]
        lines += ["In the %s: DSBRDF with 10 bases (16 variables) is below Lambert + 3 CT lobes (24) on %d of %d "
                  "materials; its hardest: %s." % (titles[c], better, len(names), ", ".join(
                      "%s (%.3f)" % (n, rows[n]["dsbrdf_10"][c]) for n in worst)), ""]
    if library is not None:
        lines += ["In-sample errors stored in the model file (on the fits' own samples, every material in the "
                  "bases): full 42-variable fits median %.4f (paper) / %.4f (cosine); the 16-variable library "
                  "%.4f / %.4f." % (np.median(library["full"]["paper"]), np.median(library["full"]["cosine"]),
                                    np.median(library["library"]["paper"]),
                                    np.median(library["library"]["cosine"])), ""]
    gain = sum(rows[n]["lambert_ct3"]["paper"] < 0.9 * rows[n]["lambert_ct1"]["paper"] for n in names)
    below = sum(rows[n]["dsbrdf_10"]["paper"] < rows[n]["dsbrdf_full"]["paper"] for n in names)
    lines += ["Caveats. All models are fitted with one objective (`mi_dsbrdf.model.fit_problem.OBJECTIVE`: a "
              "paper-convention term plus a cosine-weighted one). The Cook-Torrance models are fitted by "
              "trust-region least squares on a coarse slice (every 6th theta_d, every 30th phi_d), from 3 starts "
              "(1 lobe) or 2 starts (3 lobes, one of them the 1-lobe fit); in the paper's convention the extra "
              "lobes lower the error by more than 10 %% on %d materials, so the 3-lobe fits may be local optima. "
              "The full B-spline fits are local optima too, with a curvature penalty: on %d materials the "
              "16-variable basis refit ends below them (paper convention). The bivariate table is the data "
              "averaged over phi_d, the best any (theta_h, theta_d) model can do." % (gain, below), "",
              "![modelling error](model_error.png)", ""]
    with open(os.path.join(ROOT, "docs", "model_error.md"), "w") as f:
        f.write("\n".join(lines))


if __name__ == "__main__":
    main()
