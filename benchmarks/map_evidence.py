"""Does marginalising the map favour the right material? (Levin et al.'s MAP_k, by Laplace.)

In blind deconvolution the joint MAP of a sharp image and a blur kernel
prefers no blur and a blurred image, and the kernel that maximises the
image's probability with the sharp image integrated out does not (Levin,
Weiss, Durand & Freeman, *Understanding and evaluating blind deconvolution
algorithms*, CVPR 2009). Here the material is the kernel and the map the
image: near-Lambertian materials come back glossy under a blurred map, the
joint MAP's failure. This script asks whether the evidence of a material,
the map integrated out,

    -log p(I | psi, c) ~ E(psi, c, x*) + 1/2 log det H(x*) - (n / 2) log 2 pi,

ranks the answers of a case by their BRDF better than the negative log
posterior E does. x* is the answer's log map and H the Hessian of E in the
seen texels' log radiance, approximated per channel:

* likelihood (Eq. 19): the Laplacian's Fisher information, 1 / b^2 per
  pixel and channel (its curvature is a spike at the kink), times the
  Jacobian of log(pixel + offset) in the log map, J^T J / b^2;
* gradient prior (Eq. 16): its iteratively-reweighted quadratic majoriser,
  weight * sum_i w_i alpha m2_i^(alpha/2 - 1) (D_i^T D_i), the weights at
  either the answer's own map (``own``) or, the same for every answer of a
  case, at the shipped answer's map (``fixed``: only the likelihood's part
  then differs between answers). The entropy prior's curvature is left out
  (its weight is 1 against the gradient prior's 3e4).

The n/2 log 2 pi is the same for every answer of a case (the seen texels are
the view's). Answers of each case: the shipped code's, each reflectance start
alone (``Config.second_route_highlight`` off: one route from one start) and
the truth's point (:func:`truth_posterior.truth_point`).

    .venv/bin/python benchmarks/map_evidence.py          # 8 validation cases, ~10 min on 2 cores

Validation cases only: near-Lambertian materials under the two outdoor probes
(where the starts' ends differ most) and two glossy ones under ``wells``.
Results in benchmarks/results/map_evidence.json (a case already there is not
run again).
"""
from __future__ import annotations

import argparse
import dataclasses
import os

import numpy as np
import scipy.sparse as sp

from experiments import CACHE, DATA
from natural_light import ROOT, VALIDATION_MATERIALS, VALIDATION_PROBES
from truth_posterior import case_posterior, recovered_point, run_saved, score, truth_point

OUT = os.path.join(ROOT, "benchmarks", "results", "map_evidence.json")
PEDESTRIAN, QUARRY, WELLS = VALIDATION_PROBES[1], VALIDATION_PROBES[2], VALIDATION_PROBES[0]
CASES = [("white-fabric", QUARRY), ("polyurethane-foam", PEDESTRIAN), ("blue-fabric", QUARRY),
         ("polyurethane-foam", QUARRY), ("white-fabric", PEDESTRIAN), ("neoprene-rubber", PEDESTRIAN),
         ("silver-metallic-paint", WELLS), ("gray-plastic", WELLS)]


def difference_operators(H, W) -> tuple:
    """Sparse (N, N) matrices, N = H W texels in row-major order, of the gradient
    prior's differences of one channel (d_phi, d_theta): :meth:`GradientPrior.differences`
    applied to every unit map (one channel each), so that they are the prior's own."""
    from mi_dsbrdf.inference.illumination_priors import GradientPrior
    N = H * W
    d_phi, d_theta, _ = GradientPrior.differences(np.eye(N).reshape(H, W, N))
    return sp.csr_matrix(d_phi.reshape(N, N)), sp.csr_matrix(d_theta.reshape(N, N))


def prior_hessian(post, weights_map, seen) -> np.ndarray:
    """(S, S) the gradient prior's reweighted quadratic majoriser in one channel of the
    S seen texels, its weights at ``weights_map`` (H, W, 3) (the same for every channel:
    the prior's magnitude sums the channels)."""
    H, W = seen.shape
    c = sp.diags(post.gradient.majoriser_weights(weights_map).reshape(-1))
    d_phi, d_theta = difference_operators(H, W)
    idx = seen.reshape(-1)
    return (d_phi.T @ c @ d_phi + d_theta.T @ c @ d_theta).tocsr()[idx][:, idx].toarray()


def likelihood_hessians(post, log_map, T, seen) -> list:
    """Three (S, S) Gauss-Newton matrices of the likelihood (Eq. 19) in each channel's
    seen texels' log radiance: J^T J * weight / b^2, J the Jacobian of log(pixel +
    offset) on ``post``'s usable pixels (the Laplacian's Fisher information is 1 / b^2)."""
    from mi_dsbrdf.inference.forward import apply_transport
    idx = seen.reshape(-1)
    L = np.where(seen[..., None], np.exp(log_map), 0.0).reshape(-1, 3)
    m = apply_transport(T, L)[post.keep]
    out = []
    for c in range(3):
        J = T[c][post.keep][:, idx].astype(np.float64) * L[idx, c][None] / (m[:, c] + post.offset)[:, None]
        out.append(J.T @ J * (post.weight / post.scale ** 2))
    return out


def half_log_dets(post, log_map, T, seen, weights_maps) -> list:
    """1/2 log det of the posterior's approximate Hessian in the seen texels' log
    radiance (the module doc), summed over the channels, once for each of
    ``weights_maps`` (the prior's weights at that map; None: at ``log_map``). The
    likelihood's part, the costly one, is built once."""
    Hls = likelihood_hessians(post, log_map, T, seen)
    out = []
    for weights_map in weights_maps:
        Hp = prior_hessian(post, log_map if weights_map is None else weights_map, seen)
        out.append(float(sum(0.5 * np.linalg.slogdet(Hl + Hp)[1] for Hl in Hls)))
    return out


def run(material, probe, data=DATA, cache=CACHE, map_size=(32, 64), res=64) -> dict:
    """Every answer of one case, scored (the module doc)."""
    from mi_dsbrdf.inference import envmap
    from mi_dsbrdf.inference.reflectance import reflectance_starts
    post, model, samples, small, seen, img, ts, mask = case_posterior(material, probe, data, cache, map_size, res)
    one_route = dataclasses.replace(post.cfg, second_route_highlight=None)
    points = []
    for name, cfg, starts in [("shipped", post.cfg, None)] + [("start%d" % i, one_route, [p]) for i, p in
                                                              enumerate(reflectance_starts(model))]:
        rec = envmap.recover_envmap(ts, img, mask, model, cfg, starts=starts)
        psi, logits, log_map = recovered_point(rec)
        points.append((name, psi, logits, log_map, post.transport(psi, logits)))
    points.append(("truth", *truth_point(post, model, samples, small, seen)))
    shipped_map = points[0][3]
    answers = []
    for name, psi, logits, x, T in points:
        row = score(post, samples, small, seen, psi, logits, x, T)
        own, fixed = half_log_dets(post, x, T, seen, [None, shipped_map])
        row.update(name=name, half_log_det_own=own, half_log_det_fixed=fixed)
        answers.append(row)
    return {"material": material, "probe": probe, "answers": answers}


def summary(rows) -> str:
    """Per case: the answer each criterion chooses among the shipped one and the
    starts' (not the truth's), with its BRDF Eq. 20 (paper); the spread of each
    criterion's terms over those answers."""
    md = ["| case | shipped | min E | min E + own | min E + fixed | E spread | own spread | fixed spread |",
          "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        a = [x for x in r["answers"] if x["name"] != "truth"]
        pick = [min(a, key=lambda x: x["neg_log_posterior"] + x.get(k, 0.0))
                for k in ("-", "half_log_det_own", "half_log_det_fixed")]

        def spread(k):
            return max(x[k] for x in a) - min(x[k] for x in a)
        md.append("| %s × %s | %.3f | " % (r["material"], os.path.splitext(os.path.basename(r["probe"]))[0],
                                          a[0]["brdf_eq20_paper"]) +
                  " | ".join("%s %.3f" % (p["name"], p["brdf_eq20_paper"]) for p in pick) +
                  " | %.0f | %.0f | %.0f |" % (spread("neg_log_posterior"), spread("half_log_det_own"),
                                               spread("half_log_det_fixed")))
    return "\n".join(md)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    assert {m for m, _ in CASES} <= set(VALIDATION_MATERIALS)
    rows = []
    for i, n, r in run_saved(run, OUT, CASES, args.workers, rows):
        print("[%d/%d] %s × %s" % (i, n, r["material"], os.path.basename(r["probe"])), flush=True)
        for x in r["answers"]:
            print("  %-8s -log posterior %8.0f  + own %8.0f  + fixed %8.0f  Eq. 20 %.3f  peak/off-peak %.2f" % (
                x["name"], x["neg_log_posterior"], x["half_log_det_own"], x["half_log_det_fixed"],
                x["brdf_eq20_paper"], x["highlight_ratio"]), flush=True)
    print(summary([r for r in rows if (r["material"], r["probe"]) in CASES]))


if __name__ == "__main__":
    main()
