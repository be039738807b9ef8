"""Modelling error of the reflectance models on MERL (the paper's Fig. 2).

For every MERL material, the log-RMSE of Eq. 5 on a dense slice of the MERL
grid (every theta_h and theta_d, every 6th phi_d; ~10x the samples the fits
use) of

    Lambert + 1 Cook-Torrance lobe        10 variables
    Lambert + 3 Cook-Torrance lobes       24
    DSBRDF, 7 bases + chromaticity        13   (leave-one-out basis)
    DSBRDF, 10 bases + chromaticity       16   (leave-one-out basis)
    DSBRDF, full B-spline curves          42   (the model file's per-material fit)
    bivariate table (theta_h, theta_d)    8100 x 3 (the data averaged over phi_d)

The DSBRDF bases for a material are rebuilt (functional PCA) from the full
fits of the other 99 materials, so no material is scored on a basis that saw
it. Cook-Torrance models are fitted on a coarser slice (every 6th theta_d,
every 30th phi_d) to keep the run short. Writes

    benchmarks/results/model_error.json   per-material errors and medians
    docs/model_error.md                   table of medians and quartiles
    docs/model_error.png                  all materials, sorted (Fig. 2)

    .venv/bin/python benchmarks/model_error.py [--merl ../shared/data/merl/merl_nbrdf_weights.npz]
        [--workers 2] [--only NAME ...]
"""
import argparse
import json
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

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
    from mi_dsbrdf.evaluation.metrics import log_rmse
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
        return log_rmse(values, ev.values, ev.cos_i)

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
        write_report(d["materials"], sorted(d["materials"]), d["medians"])
        return
    from tqdm import tqdm
    from mi_dsbrdf.model.model_file import load_model
    names = [str(n) for n in load_model(args.model).arrays["fit_names"]]
    if args.only:
        names = args.only
    jobs = [(os.path.abspath(args.merl), os.path.abspath(args.model), n) for n in names]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers, mp_context=multiprocessing.get_context("spawn")) as ex:
        rows = dict(tqdm(ex.map(score, jobs), total=len(jobs), desc="materials", file=sys.stderr))
    seconds = time.perf_counter() - t0
    med = {k: float(np.median([rows[n][k] for n in names])) for k, _, _ in MODELS}
    for k, label, nv in MODELS:
        e = np.array([rows[n][k] for n in names])
        print("%-24s %6d variables  median %.4f  quartiles %.4f %.4f  max %.4f"
              % (label, nv, med[k], np.percentile(e, 25), np.percentile(e, 75), e.max()))
    if args.only:
        return
    res_dir = os.path.join(ROOT, "benchmarks", "results")
    os.makedirs(res_dir, exist_ok=True)
    with open(os.path.join(res_dir, "model_error.json"), "w") as f:
        json.dump({"command": "python benchmarks/model_error.py", "source": os.path.basename(args.merl),
                   "seconds": round(seconds, 1), "medians": med, "materials": rows}, f, indent=1, sort_keys=True)
    write_report(rows, names, med)


def write_report(rows, names, med):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    order = sorted(names, key=lambda n: rows[n]["dsbrdf_10"])
    fig, ax = plt.subplots(figsize=(11, 4.8))
    for (k, label, nv), mk in zip(MODELS, "v^osD."):
        ax.plot(range(len(order)), [rows[n][k] for n in order], mk + "-", ms=3, lw=0.8,
                label="%s (%d), median %.3f" % (label, nv, med[k]))
    ax.set_yscale("log")
    ax.set_xlabel("MERL material (sorted by DSBRDF-10 error)")
    ax.set_ylabel("log-RMSE, Eq. 5")
    ax.set_title("Modelling error on MERL (DSBRDF bases leave-one-out)")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(os.path.join(ROOT, "docs", "model_error.png"), dpi=110)
    lines = ["# Modelling error on MERL (paper Fig. 2)", "",
             "Regenerate: `.venv/bin/python benchmarks/model_error.py` (writes this file, "
             "`docs/model_error.png` and `benchmarks/results/model_error.json`).", "",
             "log-RMSE of Eq. 5 per material on a dense slice of the MERL grid; DSBRDF bases rebuilt "
             "without the scored material.", "",
             "| model | variables | median | 25 % | 75 % | max |", "|---|---:|---:|---:|---:|---:|"]
    for k, label, nv in MODELS:
        e = np.array([rows[n][k] for n in names])
        lines.append("| %s | %d | %.4f | %.4f | %.4f | %.4f |" % (label, nv, med[k], np.percentile(e, 25),
                                                                 np.percentile(e, 75), e.max()))
    worst = sorted(names, key=lambda n: -rows[n]["dsbrdf_10"])[:8]
    better = sum(rows[n]["dsbrdf_10"] < rows[n]["lambert_ct3"] for n in names)
    gain = sum(rows[n]["lambert_ct3"] < 0.9 * rows[n]["lambert_ct1"] for n in names)
    below = sum(rows[n]["dsbrdf_10"] < rows[n]["dsbrdf_full"] for n in names)
    lines += ["", "DSBRDF with 10 bases (16 variables) is below Lambert + 3 CT lobes (24) on %d of %d materials."
              % (better, len(names)),
              "", "Hardest materials for DSBRDF-10: " + ", ".join(
                  "%s (%.3f)" % (n, rows[n]["dsbrdf_10"]) for n in worst) + ".", "",
              "Caveats. The Cook-Torrance models are fitted by trust-region least squares on a coarse slice "
              "(every 6th theta_d, every 30th phi_d), from 3 starts (1 lobe) or 2 starts (3 lobes, one of them "
              "the 1-lobe fit); the extra lobes lower the error by more than 10 %% on only %d materials "
              "(the sharp-specular ones: metals, phenolics, acrylics), so the 3-lobe fits may be local optima. "
              "The DSBRDF fits minimise log(0.01 + rho cos theta_i), which keeps the diffuse colour, while the "
              "Cook-Torrance fits minimise Eq. 5 itself, which favours Cook-Torrance on this metric. "
              "The full B-spline fits are local optima too, with a "
              "curvature penalty: on %d materials the 16-variable basis refit ends below them. "
              "The bivariate table is the data averaged over phi_d, the best any (theta_h, theta_d) model can do."
              % (gain, below), "",
        "![modelling error](model_error.png)", ""]
    with open(os.path.join(ROOT, "docs", "model_error.md"), "w") as f:
        f.write("\n".join(lines))


if __name__ == "__main__":
    main()
