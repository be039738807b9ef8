"""Is the search the limit? Every library material as a start, where a basin near the truth was missed.

``truth_posterior.py --descend`` found validation cases where one colour pass
from the truth's point ends below the shipped answer's posterior with a better
BRDF: a basin the search misses. This script asks whether a wider search finds
better answers there, and whether the objective would rank them right. For each
such case (default: every stored case of ``truth_posterior.json`` whose descent
ended below the current code's answer in ``truth_posterior_second_route.json``):

* **shipped**: :func:`~mi_dsbrdf.inference.envmap.recover_envmap` under the
  shipped :class:`~mi_dsbrdf.config.Config`;
* **wide**: the second route alone (the starts judged on the colour pass's
  posterior, no grey pass) from the shipped starts *and* the 99 library
  materials of the leave-one-out model as starts; the lowest posterior among the
  starts runs the colour pass.

Each answer is scored on the colour pass's posterior (term by term, as
``truth_posterior.py`` scores), the BRDF (Eq. 20, both conventions), relighting
under two other probes (:func:`~mi_dsbrdf.evaluation.experiment.relight`) and a
**held-out likelihood**: the pixels split into a checkerboard, the map refitted
(an illumination block, the material held) on one half and the likelihood
(Eq. 19) taken on the other, both ways and summed. If the wider search's lower
posteriors came from a map that explains pixels it was fitted to and no others,
the held-out likelihood would say so.

    .venv/bin/python benchmarks/wider_starts.py              # the missed-basin cases, ~16 min on 2 cores
    .venv/bin/python benchmarks/wider_starts.py --materials blue-fabric white-fabric   # these x the validation probes

Validation cases only. Results in benchmarks/results/wider_starts.json (a case
already there is not run again; delete the file to start over).
"""
from __future__ import annotations

import argparse
import json
import os

import numpy as np

from experiments import CACHE, DATA
from natural_light import ROOT, VALIDATION_MATERIALS, VALIDATION_PROBES
from truth_posterior import OUT as TRUTH_POSTERIOR, case_posterior, recovered_point, run_saved, score

OUT = os.path.join(ROOT, "benchmarks", "results", "wider_starts.json")
#: the current code's points of the truth_posterior cases (its recovered answers)
CURRENT = os.path.join(ROOT, "benchmarks", "results", "truth_posterior_second_route.json")
#: L-BFGS iterations of the illumination block fitted to each half of the pixels
HELD_OUT_ITERS = 60


def missed_basins() -> list:
    """(material, probe) of the stored cases whose descent from the truth ended below
    the current code's answer (truth_posterior.json's ``descent`` against
    truth_posterior_second_route.json's ``recovered``)."""
    with open(TRUTH_POSTERIOR) as f:
        descents = {(r["material"], r["probe"]): r["descent"]["neg_log_posterior"] for r in json.load(f)
                    if "descent" in r}
    with open(CURRENT) as f:
        current = json.load(f)
    return [(r["material"], r["probe"]) for r in current
            if descents.get((r["material"], r["probe"]), np.inf) < r["recovered"]["neg_log_posterior"]]


def held_out_likelihood(post, img, mask, model, ts, psi, logits, log_map, seen, T) -> float:
    """Eq. 19 of each half of a checkerboard of the pixels under the map refitted
    (HELD_OUT_ITERS L-BFGS iterations from ``log_map``, the material held) to the
    other half, summed over the two halves; on ``post``'s pixels and offset (``T``:
    the material's transport on them)."""
    from mi_dsbrdf.backend import single_blas_thread
    from mi_dsbrdf.inference import envmap
    from mi_dsbrdf.inference.forward import apply_transport
    from mi_dsbrdf.inference.objective import Posterior
    H, W = mask.shape
    board = (np.add.outer(np.arange(H), np.arange(W)) % 2).astype(bool)
    half = board.reshape(-1)[post.view.texels.pixels]            # the checkerboard on post's pixels
    total = 0.0
    for side in (False, True):
        fit = Posterior(ts.with_map_size(seen.shape, post.cfg.texel_samples), img, mask & (board != side), model,
                        post.cfg)
        x = single_blas_thread(envmap.illumination_block)(fit, log_map, fit.transport(psi, logits), seen,
                                                          fit.entropy.bins_for(log_map, seen), False,
                                                          HELD_OUT_ITERS)
        L = np.where(seen[..., None], np.exp(x), 0.0).reshape(-1, 3)
        total += post.likelihood(apply_transport(T, L), post.observed, post.keep & (half == side))
    return float(total)


def run(material, probe, data=DATA, cache=CACHE, map_size=(32, 64), res=64) -> dict:
    """Both answers of one case, scored (see the module doc)."""
    from mi_dsbrdf.config import Config
    from mi_dsbrdf.evaluation.experiment import relight
    from mi_dsbrdf.evaluation.metrics import log_rmse_scale_invariant
    from mi_dsbrdf.inference import envmap
    from mi_dsbrdf.inference.reflectance import reflectance_starts
    post, model, samples, small, _, img, ts, mask = case_posterior(material, probe, data, cache, map_size, res)
    shipped_starts = reflectance_starts(model)
    names = ["mean"] + ["gmm%d" % i for i in range(len(shipped_starts) - 1)] + list(model.library)
    wide = Config(map_size=tuple(map_size), start_on_colour_posterior=True, grey_rounds=0,
                  second_route_highlight=None)
    merl = {"type": "merl", "nbrdf": os.path.join(data, "merl", "merl_nbrdf_weights.npz"), "material": material}
    out = {"material": material, "probe": probe}
    for name, cfg, starts in (("shipped", post.cfg, None),
                              ("wide", wide, shipped_starts + [p for p, _ in model.library.values()])):
        rec = envmap.recover_envmap(ts, img, mask, model, cfg, starts=starts)
        _, logits, log_map = recovered_point(rec)
        T = post.transport(rec.psi, logits)
        row = score(post, samples, small, rec.seen, rec.psi, logits, log_map, T)
        values = rec.material.eval(samples.theta_h, samples.theta_d)
        row["brdf_eq20_cosine"] = log_rmse_scale_invariant(values, samples.values, samples.cos_i, "cosine")[0]
        row["relight"] = float(np.mean(list(relight({"probe": probe}, rec.material, merl, data)[0].values())))
        row["held_out_likelihood"] = held_out_likelihood(post, img, mask, model, ts, rec.psi, logits, log_map,
                                                         rec.seen, T)
        if name == "wide":
            found = [r["neg_log_posterior"] for r in rec.log if r["pass"] == "start"]
            row["start"] = names[int(np.argmin(found))]
        out[name] = row
    return out


def summary(rows) -> str:
    """A markdown table of the cases and the counts: where the wide search's answer
    has the lower posterior, likelihood, held-out likelihood, the better BRDF
    (Eq. 20 paper, cosine) and relighting, and the lower highlight ratio (peak /
    off-peak of the BRDF)."""
    keys = [("neg_log_posterior", "posterior"), ("likelihood", "likelihood"),
            ("held_out_likelihood", "held-out likelihood"), ("brdf_eq20_paper", "BRDF Eq. 20 paper"),
            ("brdf_eq20_cosine", "BRDF Eq. 20 cosine"), ("relight", "relit"), ("highlight_ratio", "highlight ratio")]
    md = ["| case | start | " + " | ".join(n + " (shipped / wide)" for _, n in keys) + " |",
          "|---|---|" + "---|" * len(keys)]
    for r in rows:
        a, b = r["shipped"], r["wide"]
        md.append("| %s × %s | %s | " % (r["material"], os.path.splitext(os.path.basename(r["probe"]))[0],
                                         b["start"]) +
                  " | ".join(("%.0f / %.0f" if a[k] > 50 else "%.3f / %.3f") % (a[k], b[k]) for k, _ in keys) + " |")
    md += ["", "Of %d cases, the wide search's answer is lower in: " % len(rows) +
           ", ".join("%s %d" % (n, sum(r["wide"][k] < r["shipped"][k] for r in rows)) for k, n in keys) + "."]
    return "\n".join(md)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--materials", nargs="*", help="validation materials to run under every validation probe "
                                                   "(default: the missed-basin cases)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    cases = missed_basins() if not args.materials else [(m, p) for p in VALIDATION_PROBES for m in args.materials]
    if set(m for m, _ in cases) - set(VALIDATION_MATERIALS):
        ap.error("validation materials only: %s" % sorted(set(m for m, _ in cases) - set(VALIDATION_MATERIALS)))
    rows = []
    for i, n, r in run_saved(run, OUT, cases, args.workers, rows):
        a, b = r["shipped"], r["wide"]
        print("[%d/%d] %-24s %-28s -log posterior %8.0f %8.0f | held-out %7.0f %7.0f | Eq. 20 %.3f %.3f | "
              "relit %.3f %.3f" % (i, n, r["material"], os.path.basename(r["probe"]), a["neg_log_posterior"],
                                   b["neg_log_posterior"], a["held_out_likelihood"], b["held_out_likelihood"],
                                   a["brdf_eq20_paper"], b["brdf_eq20_paper"], a["relight"], b["relight"]),
              flush=True)
    print(summary([r for r in rows if (r["material"], r["probe"]) in cases]))


if __name__ == "__main__":
    main()
