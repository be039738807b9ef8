"""Does the posterior prefer the true material? The recovered answer against the truth's best basis fit.

For each validation case (a MERL material under a probe, leave-one-out model,
as in ``natural_light.py``, inferred from the pixels the app uses:
:func:`~mi_dsbrdf.inference.pixels.usable_pixels`, since the twentieth session;
the run before, with the silhouette ring, is in
``benchmarks/results/truth_posterior_before_interior.json``) two points of the
negative log posterior (Eq. 18) are compared term by term, on the posterior the
app's colour pass minimises (each texel lit from ``Config.texel_samples``
squared directions; at texel centres before the twenty-first session, whose run
is ``benchmarks/results/truth_posterior_centres.json``):

* **recovered**: what :func:`~mi_dsbrdf.inference.envmap.recover_envmap` returns
  under the shipped :class:`~mi_dsbrdf.config.Config`;
* **truth**: the measured material's best fit in the leave-one-out basis
  (:func:`~mi_dsbrdf.model.fitting.fit_basis`: the closest the model can come to
  it in BRDF space) under the true map, at the level that matches the image,
  refined by an illumination block of ``REFINE_ITERS`` L-BFGS iterations with
  the material held (the best map the posterior allows that material).

Two more points (``--descend``, since the twenty-first session; stored as each
case's ``descent`` and ``descent_constant_map``): one colour pass of the shipped
alternation from the truth's point, and from the truth's material under a
constant map (as the starts begin). The first says whether the truth lies in a
basin with a lower posterior than the recovered answer that the search misses;
the second whether the material alone, without the true map, leads there.

If the truth's posterior is lower, the search missed it (more iterations or
better starts would help). If it is higher, the objective itself prefers the
recovered answer; the likelihood column says whether the image alone does:
with model error (the DSBRDF has no phi_d and ten coefficients) the basis
material closest to the BRDF need not be the one that renders closest to the
image.

    .venv/bin/python benchmarks/truth_posterior.py --probes polyhaven/quarry_01_1k.hdr   # 12 cases, ~5 min
    .venv/bin/python benchmarks/truth_posterior.py              # all 36 validation cases, ~15 min on 2 cores
    .venv/bin/python benchmarks/truth_posterior.py --descend    # both descents from each stored case's truth, ~8 min
    .venv/bin/python benchmarks/truth_posterior.py --report --results benchmarks/results/truth_posterior_second_route.json   # -> docs/truth_posterior.md
    .venv/bin/python benchmarks/truth_posterior.py --fits-from MODEL --materials ...   # another build's models

Validation materials and probes only. Each case is added to
benchmarks/results/truth_posterior.json as it ends; a case already there is
not run again (delete the file to start over).
"""
from __future__ import annotations

import argparse
import functools
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from experiments import CACHE, DATA
from natural_light import DOCS, NEAR_LAMBERTIAN, ROOT, VALIDATION_MATERIALS, VALIDATION_PROBES

OUT = os.path.join(ROOT, "benchmarks", "results", "truth_posterior.json")
DOC = os.path.join(DOCS, "truth_posterior.md")
#: L-BFGS iterations of the illumination block that fits the true map to the truth's basis fit
REFINE_ITERS = 300


def validation_case(material, probe, data=DATA, cache=CACHE, map_size=(32, 64), res=64, fits_from=None) -> tuple:
    """One case as ``natural_light.py`` makes it: (leave-one-out model, the measured
    material's MERL samples, the probe at twice ``map_size``, the image (res, res, 3)
    rendered from its texel centres, the ``dsbrdf`` view at ``map_size``, the pixels
    the app infers from (:func:`~mi_dsbrdf.inference.pixels.usable_pixels`; every
    script that takes its case from here since the twenty-first session)).
    ``fits_from``: the leave-one-out model from that model file's full fits
    (:func:`~mi_dsbrdf.evaluation.experiment.loo_model`), default the shipped one's."""
    import drjit as dr
    from mi_dsbrdf.app.io import read_image
    from mi_dsbrdf.brdf.measured import MeasuredBRDF
    from mi_dsbrdf.evaluation import experiment as ex
    from mi_dsbrdf.inference.pixels import usable_pixels
    from mi_dsbrdf.model.samples import samples_from_table
    dr.set_thread_count(1)
    nbrdf = os.path.join(data, "merl", "merl_nbrdf_weights.npz")
    model = ex.loo_model(material, cache, fits_from=fits_from)
    samples = samples_from_table(MeasuredBRDF.from_nbrdf(nbrdf, material))
    H, W = map_size
    truth = ex.downsample(read_image(os.path.join(data, "envmaps", probe)), 2 * H, 2 * W)
    img = ex.render(ex.texels({"type": "merl", "nbrdf": nbrdf, "material": material}, res, (2 * H, 2 * W)),
                    truth.reshape(-1, 3))
    ts = ex.texels({"type": "dsbrdf"}, res, (H, W))
    return model, samples, truth, img, ts, usable_pixels(ts.mask, img)


def case_posterior(material, probe, data=DATA, cache=CACHE, map_size=(32, 64), res=64, fits_from=None) -> tuple:
    """One validation case as the points are scored: (the posterior of the colour
    pass, which the app's answer minimises last: the app's pixels, each texel lit
    from ``Config.texel_samples`` squared directions; the leave-one-out model, the
    measured material's samples, the true map at ``map_size``, the seen texels
    (H, W), the image, the view, the pixels)."""
    from mi_dsbrdf.config import Config
    from mi_dsbrdf.evaluation import experiment as ex
    from mi_dsbrdf.inference.objective import Posterior
    model, samples, truth, img, ts, mask = validation_case(material, probe, data, cache, map_size, res, fits_from)
    cfg = Config(map_size=tuple(map_size))
    # scored on the colour pass's forward model since the twenty-first session (texel centres before, where
    # a lobe sharper than the texel spacing is aliased and the descent's end scored above its start)
    post = Posterior(ts.with_map_size(tuple(map_size), cfg.texel_samples), img, mask, model, cfg)
    return post, model, samples, ex.downsample(truth, *map_size), ~post.view.unseen.reshape(map_size), img, ts, mask


def score(post, samples, small, seen, psi, logits, log_map, T) -> dict:
    """The negative log posterior term by term at (psi, logits, log map) whose
    transport is ``T``, the BRDF's Eq. 20 (paper) and highlight ratio, the map's error."""
    from mi_dsbrdf.evaluation.metrics import highlight_ratio, log_rmse_scale_invariant, scale_invariant_log_error
    from mi_dsbrdf.inference import envmap
    bins = post.entropy.bins_for(log_map, seen)
    total, lik, terms = envmap.posterior_at(post, psi, logits, log_map, T, seen, bins)
    values = post.material(psi, logits).eval(samples.theta_h, samples.theta_d)
    L = np.where(seen[..., None], np.exp(log_map), 0.0)
    return dict(neg_log_posterior=total, likelihood=lik, **terms,
                brdf_eq20_paper=log_rmse_scale_invariant(values, samples.values, samples.cos_i, "paper")[0],
                highlight_ratio=highlight_ratio(values, samples.theta_h, samples.theta_d),
                illumination_error=scale_invariant_log_error(L, small, seen))


def recovered_point(rec) -> tuple:
    """(psi, logits, log map (H, W, 3), unseen texels at ``envmap.BLACK``) of a
    :class:`~mi_dsbrdf.inference.result.Recovery`: the point its posterior is scored at."""
    from mi_dsbrdf.brdf.chromaticity import chroma_logits
    from mi_dsbrdf.inference import envmap
    return rec.psi, chroma_logits(rec.chromaticity), np.log(np.maximum(rec.illumination, 1e-300)).clip(envmap.BLACK)


def best_map(post, T, start, seen, iters=REFINE_ITERS) -> tuple:
    """A material's best map from ``start`` (H, W, 3, any units): the start at the
    level that matches the image through the transport ``T``, refined by an
    illumination block of ``iters`` L-BFGS iterations with the material held.
    Returns (log map (H, W, 3), the entropy prior's bins it was refined with)."""
    from mi_dsbrdf.backend import single_blas_thread
    from mi_dsbrdf.inference import envmap
    from mi_dsbrdf.inference.forward import apply_transport
    level = np.median(post.observed[post.keep] / np.maximum(apply_transport(T, start.reshape(-1, 3))[post.keep],
                                                            1e-300))
    x = np.where(seen[..., None], np.log(np.maximum(start * level, 1e-300)), envmap.BLACK).clip(envmap.BLACK)
    bins = post.entropy.bins_for(x, seen)
    return single_blas_thread(envmap.illumination_block)(post, x, T, seen, bins, False, iters), bins


def truth_point(post, model, samples, small, seen) -> tuple:
    """The truth's point: (psi, logits, log map, transport) of the measured material's
    best basis fit under its best map from the true map (:func:`best_map`)."""
    from mi_dsbrdf.brdf.chromaticity import chroma_logits
    from mi_dsbrdf.model.fitting import fit_basis
    fit = fit_basis(samples, model.basis).material
    psi, logits = fit.psi, chroma_logits(fit.chromaticity)
    T = post.transport(psi, logits)
    return psi, logits, best_map(post, T, small, seen)[0], T


def run(material, probe, data=DATA, cache=CACHE, map_size=(32, 64), res=64, fits_from=None) -> dict:
    """Recover one case and score both points (see the module doc)."""
    from mi_dsbrdf.inference import envmap
    from mi_dsbrdf.evaluation.metrics import highlight_ratio
    post, model, samples, small, seen, img, ts, mask = case_posterior(material, probe, data, cache, map_size, res,
                                                                      fits_from)
    rec = envmap.recover_envmap(ts, img, mask, model, post.cfg)
    seen = rec.seen                         # the recovery's seen texels (those of the view: every pixel is used)
    psi, logits, log_map = recovered_point(rec)
    recovered = score(post, samples, small, seen, psi, logits, log_map, post.transport(psi, logits))
    return {"material": material, "probe": probe, "truth_highlight_ratio":
            highlight_ratio(samples.values, samples.theta_h, samples.theta_d),
            "recovered": recovered, "truth_fit": score(post, samples, small, seen,
                                                       *truth_point(post, model, samples, small, seen))}


def descend(material, probe, data=DATA, cache=CACHE, map_size=(32, 64), res=64) -> dict:
    """Where the search goes from the truth: one colour pass of the shipped alternation
    (:func:`~mi_dsbrdf.inference.envmap.alternate`, as recover_envmap runs it) from
    the truth's point (truth_point; "descent") and from the truth's material under a
    constant map at the image's level, as the starts begin ("descent_constant_map"),
    each end scored as run scores both points. If the first stays near the truth's
    BRDF at a posterior below the recovered answer's, the truth is a basin the
    search misses; the second says whether the material alone leads there."""
    from mi_dsbrdf.backend import single_blas_thread
    from mi_dsbrdf.inference import envmap
    post, model, samples, small, seen = case_posterior(material, probe, data, cache, map_size, res)[:5]
    psi, logits, x, T = truth_point(post, model, samples, small, seen)
    out = {}
    for name, log_map in (("descent", x), ("descent_constant_map", envmap.constant_log_map(post, T, map_size))):
        rounds = []
        p, z, m, _, _ = single_blas_thread(envmap.alternate)(post, "colour", tuple(map_size), psi, logits, log_map,
                                                             post.cfg, rounds.append)
        out[name] = dict(score(post, samples, small, seen, p, z, m, post.transport(p, z)), rounds=len(rounds))
    return out


def run_saved(fn, path, pairs, workers, rows):
    """Run ``fn(material, probe)`` on every (material, probe) of ``pairs`` not yet in the JSON list at ``path``,
    in ``workers`` processes (Dr.Jit in two threads of one process can crash),
    appending each result to ``rows`` (first the stored ones) and rewriting the file
    whole as each ends. Yields (i, how many run, result)."""
    if os.path.exists(path):
        with open(path) as f:
            rows.extend(json.load(f))
    done = {(r["material"], r["probe"]) for r in rows}
    jobs = [(m, p) for m, p in pairs if (m, p) not in done]
    if not jobs:
        return
    with ProcessPoolExecutor(workers) as pool:
        for i, r in enumerate(pool.map(fn, *zip(*jobs)), 1):
            rows.append(r)
            save_rows(rows, path)
            yield i, len(jobs), r


def save_rows(rows, path) -> None:
    """Rewrite the JSON list at ``path`` whole, atomically (a cut-off run keeps the file before)."""
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(rows, f, indent=1)
    os.replace(tmp, path)


def report(rows, source=OUT) -> str:
    md = ["# Does the posterior prefer the true material?", "",
          "Generated by `python benchmarks/truth_posterior.py --report --results %s` "
          "(see the script's doc). Validation cases only. Per case: the " % os.path.relpath(source, ROOT) +
          "negative log posterior's terms at the recovered answer and at the measured material's best fit in the "
          "leave-one-out basis under the true map (refined for that material by %d L-BFGS iterations); "
          "Eq. 20 (paper), the highlight ratio (measured in brackets) and the map's log(1 + L) error." % REFINE_ITERS,
          ""]
    n = len(rows)
    lower = sum(r["truth_fit"]["neg_log_posterior"] < r["recovered"]["neg_log_posterior"] for r in rows)
    lik = sum(r["truth_fit"]["likelihood"] < r["recovered"]["likelihood"] for r in rows)
    better = sum(r["truth_fit"]["brdf_eq20_paper"] < r["recovered"]["brdf_eq20_paper"] for r in rows)
    md += ["The truth's fit has the better BRDF (Eq. 20 paper) in %d of %d cases; its posterior is lower than the "
           "recovered answer's in %d (the search missed it) and higher in %d (the objective prefers the recovered "
           "answer); its likelihood alone is lower in %d of %d." % (better, n, lower, n - lower, lik, n), ""]
    flat = [r for r in rows if r["truth_highlight_ratio"] < NEAR_LAMBERTIAN]
    if flat:
        md += ["Near-Lambertian materials (%d cases): the truth's posterior lower in %d, its likelihood lower in %d."
               % (len(flat), sum(r["truth_fit"]["neg_log_posterior"] < r["recovered"]["neg_log_posterior"]
                                 for r in flat),
                  sum(r["truth_fit"]["likelihood"] < r["recovered"]["likelihood"] for r in flat)), ""]
    went = [r for r in rows if "descent" in r]
    if went:
        def lower(r, a, b):
            return r[a]["neg_log_posterior"] < r[b]["neg_log_posterior"]
        md += ["Descent from the truth (`--descend`, %d cases): one colour pass of the shipped alternation from "
               "the truth's point ends with a posterior below the recovered answer's in %d, below the truth's own "
               "point in %d; its BRDF (Eq. 20 paper) is below the recovered answer's in %d and within 10 %% of the "
               "truth fit's in %d. Of the %d cases whose descent ends below the recovered answer's posterior (a "
               "basin the search missed), its BRDF is below the recovered answer's in %d; of the %d whose truth "
               "point's posterior is below the recovered answer's, in %d." % (
                   len(went), sum(lower(r, "descent", "recovered") for r in went),
                   sum(lower(r, "descent", "truth_fit") for r in went),
                   sum(r["descent"]["brdf_eq20_paper"] < r["recovered"]["brdf_eq20_paper"] for r in went),
                   sum(r["descent"]["brdf_eq20_paper"] < 1.1 * r["truth_fit"]["brdf_eq20_paper"] for r in went),
                   sum(lower(r, "descent", "recovered") for r in went),
                   sum(lower(r, "descent", "recovered") and r["descent"]["brdf_eq20_paper"]
                       < r["recovered"]["brdf_eq20_paper"] for r in went),
                   sum(lower(r, "truth_fit", "recovered") for r in went),
                   sum(lower(r, "truth_fit", "recovered") and r["descent"]["brdf_eq20_paper"]
                       < r["recovered"]["brdf_eq20_paper"] for r in went)), ""]
    else:
        md += ["This run has no descents from the truth (`--descend` adds them to `%s`, which holds the twenty-first "
               "session's)." % os.path.relpath(OUT, ROOT), ""]
    flat_start = [r for r in went if "descent_constant_map" in r]
    if flat_start:
        missed = [r for r in flat_start if lower(r, "descent", "recovered")]
        md += ["From the truth's material under a constant map at the image's level (as the starts begin; %d "
               "cases) the same colour pass ends below the recovered answer's posterior in %d, with the better "
               "BRDF in %d; of the %d basins the search missed, it reaches a posterior within 5 %% of the "
               "descent's in %d: the material, not the map, is what the starts lack." % (
                   len(flat_start), sum(lower(r, "descent_constant_map", "recovered") for r in flat_start),
                   sum(lower(r, "descent_constant_map", "recovered") and r["descent_constant_map"]["brdf_eq20_paper"]
                       < r["recovered"]["brdf_eq20_paper"] for r in flat_start), len(missed),
                   sum(r["descent_constant_map"]["neg_log_posterior"] < 1.05 * r["descent"]["neg_log_posterior"]
                       for r in missed)), ""]
    md += ["| material | probe | point | -log posterior | likelihood | gmm | gradient | Eq. 20 paper | highlight "
           "(measured) | map |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for key in ("recovered", "truth_fit", "descent", "descent_constant_map"):
            if key not in r:
                continue
            p = r[key]
            md.append("| %s | %s | %s | %.0f | %.0f | %.0f | %.0f | %.3f | %.2f (%.2f) | %.3f |" % (
                r["material"], os.path.splitext(os.path.basename(r["probe"]))[0], key.replace("_", " "),
                p["neg_log_posterior"], p["likelihood"], p["gmm"], p["gradient"], p["brdf_eq20_paper"],
                p["highlight_ratio"], r["truth_highlight_ratio"], p["illumination_error"]))
    return "\n".join(md) + "\n"


def add_descents(args) -> None:
    """descend() on every stored case of ``args.materials`` x ``args.probes`` that has
    not had it, in ``args.workers`` processes, both ends stored in the case's row as it ends."""
    with open(OUT) as f:
        rows = json.load(f)
    todo = [r for r in rows if r["material"] in args.materials and r["probe"] in args.probes
            and "descent_constant_map" not in r]
    with ProcessPoolExecutor(args.workers) as pool:
        for i, (r, d) in enumerate(zip(todo, pool.map(descend, [r["material"] for r in todo],
                                                      [r["probe"] for r in todo])), 1):
            r.update(d)
            save_rows(rows, OUT)
            print("[%d/%d] %-24s %-28s -log posterior recovered %8.0f truth fit %8.0f descent %8.0f | Eq. 20 %.3f "
                  "%.3f %.3f | from a constant map %8.0f %.3f" % (
                                     i, len(todo), r["material"], os.path.basename(r["probe"]),
                                     r["recovered"]["neg_log_posterior"], r["truth_fit"]["neg_log_posterior"],
                                     r["descent"]["neg_log_posterior"], r["recovered"]["brdf_eq20_paper"],
                                     r["truth_fit"]["brdf_eq20_paper"], r["descent"]["brdf_eq20_paper"],
                                     r["descent_constant_map"]["neg_log_posterior"],
                                     r["descent_constant_map"]["brdf_eq20_paper"]), flush=True)
    print(report(rows))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--materials", nargs="*", default=VALIDATION_MATERIALS)
    ap.add_argument("--probes", nargs="*", default=VALIDATION_PROBES)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--report", action="store_true", help="write docs/truth_posterior.md from the results")
    ap.add_argument("--results", default=OUT, metavar="FILE",
                    help="with --report: the stored run to write it from (default %s; the current code's is "
                         "truth_posterior_second_route.json)" % os.path.relpath(OUT, ROOT))
    ap.add_argument("--fits-from", default=None, metavar="MODEL",
                    help="leave-one-out models from this model file's fits (build-model --complete-unseen, ...); "
                         "results in benchmarks/results/truth_posterior-trial-<file name>.json, no report written")
    ap.add_argument("--descend", action="store_true",
                    help="add to each stored case where one colour pass goes from the truth's point (descend)")
    args = ap.parse_args(argv)
    if args.fits_from is not None:
        if args.report or args.descend:
            sys.exit("--fits-from runs and prints its cases; --report and --descend are the shipped model's")
        if not os.path.isfile(args.fits_from):
            sys.exit("--fits-from: no model file %s" % args.fits_from)
    if args.report:
        if not os.path.isfile(args.results):
            sys.exit("--results: no stored run %s" % args.results)
        with open(args.results) as f:
            text = report(json.load(f), args.results)
        with open(DOC, "w") as f:
            f.write(text)
        print(text)
        return
    if not os.path.exists(os.path.join(DATA, "merl", "merl_nbrdf_weights.npz")):
        sys.exit("needs the MERL fits under %s (see ../shared/data/README.md)" % DATA)
    if args.descend:
        return add_descents(args)
    rows, out, fn = [], OUT, run
    if args.fits_from is not None:
        out = os.path.join(os.path.dirname(OUT), "truth_posterior-trial-%s.json"
                           % os.path.splitext(os.path.basename(args.fits_from))[0])
        fn = functools.partial(run, fits_from=os.path.abspath(args.fits_from))
    for i, n, r in run_saved(fn, out, [(m, p) for p in args.probes for m in args.materials], args.workers, rows):
        a, b = r["recovered"], r["truth_fit"]
        print("[%d/%d] %-24s %-28s -log posterior recovered %8.0f truth fit %8.0f | likelihood %7.0f %7.0f"
              " | Eq. 20 %.3f %.3f" % (i, n, r["material"], os.path.basename(r["probe"]),
                                      a["neg_log_posterior"], b["neg_log_posterior"], a["likelihood"],
                                      b["likelihood"], a["brdf_eq20_paper"], b["brdf_eq20_paper"]), flush=True)
    print(report(rows, out))


if __name__ == "__main__":
    main()
