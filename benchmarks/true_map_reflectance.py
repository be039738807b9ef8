"""Is a near-Lambertian material's highlight the map's doing or the objective's? Its reflectance under the true map.

For each near-Lambertian validation case (measured peak / off-peak below
``natural_light.NEAR_LAMBERTIAN``; leave-one-out model, as in
``natural_light.py``), three points of the negative log posterior (Eq. 18):

* **recovered**: :func:`~mi_dsbrdf.inference.envmap.recover_envmap` under the
  shipped :class:`~mi_dsbrdf.config.Config` (the map free);
* **true map**: the reflectance blocks alone
  (:func:`~mi_dsbrdf.inference.reflectance.reflectance_block`, ``ROUNDS`` of
  them from every reflectance start, the map's scale free, chromaticities
  free from the second) with the true map held; the start that ends lowest;
* **its best map**: that material with the map refined by an illumination
  block of ``REFINE_ITERS`` L-BFGS iterations from the true map: the best map
  the posterior allows it.

If the material recovered under the true map has no highlight, and the
recovered answer (with a highlight) has the lower posterior than that material
under its best map, the objective prefers the highlight: a better search will
not remove it. The likelihood column says whether the image alone does, and the
mean |log| error by brightness quartile of the pixels where.

    .venv/bin/python benchmarks/true_map_reflectance.py          # 18 cases, ~15 min on 2 cores
    .venv/bin/python benchmarks/true_map_reflectance.py --materials white-fabric --probes polyhaven/quarry_01_1k.hdr

Validation materials and probes only. Writes
benchmarks/results/true_map_reflectance.json (each case as it ends; a case
already there is not run again: delete the file to start over) and prints a
markdown table.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from experiments import CACHE, DATA
from natural_light import HIGHLIGHT_LIMIT, NEAR_LAMBERTIAN, ROOT, VALIDATION_MATERIALS, VALIDATION_PROBES
from truth_posterior import recovered_point, run_saved, validation_case

OUT = os.path.join(ROOT, "benchmarks", "results", "true_map_reflectance.json")
#: reflectance blocks from each start under the true map
ROUNDS = 4
#: L-BFGS iterations of the illumination block that gives the true map's material its best map
REFINE_ITERS = 300


def near_lambertian(materials, data=DATA) -> list:
    """The ``materials`` whose measured peak / off-peak is below NEAR_LAMBERTIAN."""
    from mi_dsbrdf.brdf.measured import MeasuredBRDF
    from mi_dsbrdf.evaluation.metrics import highlight_ratio
    from mi_dsbrdf.model.samples import samples_from_table
    nbrdf = os.path.join(data, "merl", "merl_nbrdf_weights.npz")
    out = []
    for m in materials:
        s = samples_from_table(MeasuredBRDF.from_nbrdf(nbrdf, m))
        if highlight_ratio(s.values, s.theta_h, s.theta_d) < NEAR_LAMBERTIAN:
            out.append(m)
    return out


def run(material, probe, data=DATA, cache=CACHE, map_size=(32, 64), res=64) -> dict:
    """Recover one case and score the three points (see the module doc)."""
    from mi_dsbrdf.backend import single_blas_thread
    from mi_dsbrdf.config import Config
    from mi_dsbrdf.evaluation import experiment as ex
    from mi_dsbrdf.evaluation.metrics import highlight_ratio, log_rmse_scale_invariant, scale_invariant_log_error
    from mi_dsbrdf.inference import envmap
    from mi_dsbrdf.inference.forward import apply_transport
    from mi_dsbrdf.inference.objective import Posterior
    from mi_dsbrdf.inference.reflectance import image_chroma_logits, reflectance_block, reflectance_starts
    model, samples, truth, img, ts, mask = validation_case(material, probe, data, cache, map_size, res)
    H, W = map_size
    cfg = Config(map_size=(H, W))
    rec = envmap.recover_envmap(ts, img, mask, model, cfg)
    # the colour pass's posterior (its texel sampling and pixels), as recover_envmap builds it
    post = Posterior(ts.with_map_size((H, W), cfg.texel_samples), img, mask, model, cfg,
                     max_pixels=cfg.map_pairs // (H * W))
    seen, small = rec.seen, ex.downsample(truth, H, W)
    brightness = post.observed.mean(axis=1)
    quartile = np.searchsorted(np.quantile(brightness[post.keep], [0.25, 0.5, 0.75]), brightness)

    def point(psi, logits, log_map):
        T = post.transport(psi, logits)
        bins = post.entropy.bins_for(log_map, seen)
        total, lik, terms = envmap.posterior_at(post, psi, logits, log_map, T, seen, bins)
        values = post.material(psi, logits).eval(samples.theta_h, samples.theta_d)
        L = np.where(seen[..., None], np.exp(log_map), 0.0)
        image = apply_transport(T, L)
        err = np.abs(np.log(image + post.offset) - np.log(post.observed + post.offset)).mean(axis=1)
        return dict(neg_log_posterior=total, likelihood=lik, **terms,
                    brdf_eq20_paper=log_rmse_scale_invariant(values, samples.values, samples.cos_i, "paper")[0],
                    highlight_ratio=highlight_ratio(values, samples.theta_h, samples.theta_d),
                    illumination_error=scale_invariant_log_error(L, small, seen),
                    abs_log_error_by_quartile=[float(err[post.keep & (quartile == q)].mean()) for q in range(4)])

    recovered = point(*recovered_point(rec))
    L0 = np.where(seen[..., None], small, 0.0).reshape(-1, 3)
    logits0 = image_chroma_logits(post.observed, post.keep, post.R)
    ends = []
    for p0 in reflectance_starts(model):
        psi, logits, L = p0, logits0, L0
        for r in range(ROUNDS):
            step = single_blas_thread(reflectance_block)(post, psi, logits, L, cfg.block_iters, fit_scale=True,
                                                         fit_chroma=r > 0)
            psi, logits, L = step.psi, step.logits, step.L
        ends.append((post.reflectance_terms(psi, logits, L)[0], psi, logits, L))
    _, psi, logits, L = min(ends, key=lambda e: e[0])
    x = np.where(seen[..., None], np.log(np.maximum(L.reshape(H, W, 3), 1e-300)), envmap.BLACK)
    true_map = point(psi, logits, x)
    x = single_blas_thread(envmap.illumination_block)(post, x, post.transport(psi, logits), seen,
                                                      post.entropy.bins_for(x, seen), False, REFINE_ITERS)
    best_map = point(psi, logits, x)
    return {"material": material, "probe": probe, "truth_highlight_ratio":
            highlight_ratio(samples.values, samples.theta_h, samples.theta_d),
            "recovered": recovered, "true_map": true_map, "best_map": best_map}


def table(rows) -> str:
    """Markdown: per case and point, the posterior's main terms, Eq. 20 (paper), the
    highlight ratio and the mean |log| error of the brighter three quartiles."""
    n = len(rows)
    clean = sum(r["true_map"]["highlight_ratio"] < HIGHLIGHT_LIMIT * r["truth_highlight_ratio"] for r in rows)
    prefers = sum(r["recovered"]["neg_log_posterior"] < r["best_map"]["neg_log_posterior"] for r in rows)
    lik = sum(r["recovered"]["likelihood"] < r["best_map"]["likelihood"] for r in rows)
    md = ["Under the true map the reflectance comes back without a highlight in %d of %d near-Lambertian cases; "
          "the recovered answer's posterior is lower than that material's under its best map in %d, its "
          "likelihood alone in %d." % (clean, n, prefers, lik), "",
          "| material | probe | point | -log posterior | likelihood | gmm | gradient | Eq. 20 paper | highlight "
          "(measured) | mean abs log error, brighter 3/4 |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for key in ("recovered", "true_map", "best_map"):
            p = r[key]
            md.append("| %s | %s | %s | %.0f | %.0f | %.0f | %.0f | %.3f | %.2f (%.2f) | %.4f |" % (
                r["material"], os.path.splitext(os.path.basename(r["probe"]))[0], key.replace("_", " "),
                p["neg_log_posterior"], p["likelihood"], p["gmm"], p["gradient"], p["brdf_eq20_paper"],
                p["highlight_ratio"], r["truth_highlight_ratio"], np.mean(p["abs_log_error_by_quartile"][1:])))
    return "\n".join(md) + "\n"


def near_lambertian_cases(doc, argv=None) -> tuple:
    """The command line of a script over the near-Lambertian validation cases
    (``--materials``, ``--probes``, ``--workers``): (its arguments, the (material,
    probe) pairs). Exits with a message without the MERL data."""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("--materials", nargs="*", help="default: the near-Lambertian validation materials")
    ap.add_argument("--probes", nargs="*", default=VALIDATION_PROBES)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    if not os.path.exists(os.path.join(DATA, "merl", "merl_nbrdf_weights.npz")):
        sys.exit("needs the MERL fits under %s (see ../shared/data/README.md)" % DATA)
    materials = args.materials or near_lambertian(VALIDATION_MATERIALS)
    return args, [(m, p) for p in args.probes for m in materials]


def main(argv=None):
    args, pairs = near_lambertian_cases(__doc__, argv)
    rows = []
    for i, n, r in run_saved(run, OUT, pairs, args.workers, rows):
        print("[%d/%d] %-20s %-28s highlight recovered %.2f, true map %.2f (measured %.2f) | -log posterior "
              "recovered %.0f, true map's material at its best map %.0f" % (
                  i, n, r["material"], os.path.basename(r["probe"]), r["recovered"]["highlight_ratio"],
                  r["true_map"]["highlight_ratio"], r["truth_highlight_ratio"],
                  r["recovered"]["neg_log_posterior"], r["best_map"]["neg_log_posterior"]), flush=True)
    print(table(rows))


if __name__ == "__main__":
    main()
