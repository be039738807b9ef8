"""Joint MAP estimate of reflectance and an illumination map (paper §5).

The negative log posterior (Eq. 18,
:class:`~mi_dsbrdf.inference.objective.Posterior`) of the DSBRDF variables
(psi, chromaticity) and the log illumination map x = log L is minimised by
alternating two blocks:

* illumination (:func:`illumination_block`): reflectance fixed, the image is
  linear in L (I = T L, T from
  :meth:`~mi_dsbrdf.inference.forward.TexelSum.transport`), so each evaluation
  is a product with T; L-BFGS-B on x with the likelihood (Eq. 19) and the
  entropy and gradient priors (Eq. 13-16). Texels no observed pixel sees are
  masked and left black.
* reflectance (:func:`~mi_dsbrdf.inference.reflectance.reflectance_block`):
  illumination fixed, Levenberg-Marquardt on psi, the chromaticity variables
  and the map's overall log scale.

Units: inference sees the image divided by its usable pixels' mean
(:func:`~mi_dsbrdf.inference.pixels.image_level`) and scales the map back, so that
the answer does not depend on the image's units (the map's log bounds and
``BLACK`` are constants).

Start: chromaticity from the image's colour
(:func:`~mi_dsbrdf.inference.reflectance.image_chroma_logits`) and, for each of
:func:`~mi_dsbrdf.inference.reflectance.reflectance_starts` (psi = 0 and the
GMM means), a constant map at the image's level refined by a short grey
illumination block and a short reflectance block; the lowest posterior starts
the rounds (:func:`alternate`). The start runs on the map at half its
resolution (:func:`map_sizes`, ``Config.map_levels``); its map moves up by
:func:`~mi_dsbrdf.inference.latlong.resample`.
Rounds continue until the negative log posterior changes by less than ``tol``
(relative). Two passes: grey illumination first (one map shared by the
channels: the grey-world assumption; the lobes keep the image's colour), then
colour from that start (chromaticities and map colour free), unless the
image is grey (:mod:`mi_dsbrdf.inference.scene_needs` decides).

Second route (``Config.second_route_highlight``, not in the paper): an answer
with a highlight is checked against a second inference, whose starts are
judged on the colour pass's own posterior (the full map, texels lit from
``texel_samples`` squared directions) and which has no grey pass; the lower
posterior wins, and a last row ``{"pass": "answer", "answer_route": 0 or 1}``
repeats the winner's figures. The coarse start at texel centres misjudges
lobes sharper than the texel spacing (:func:`route`).

Colour split (not in the paper): one image shows only the product of the
light's colour and the material's. Given the chromaticity and light-colour
priors (``Config.w_chromaticity``, ``w_light_colour``; on by default), every
colour round from the second first moves along that product
(:func:`colour_split`), which neither block can do alone, and keeps the move
only if the posterior falls.

Highlight pairs (``Config.highlight_texels``, ``highlight_check``; not in the
paper): where integrating each pixel's mirror direction over its area changes
the answer's image by ``highlight_check`` or more
(:func:`~mi_dsbrdf.inference.lobes.highlight_change`), a lobe is sharper than a
pixel's footprint, and the last pass goes on with the highlight pairs
(:mod:`~mi_dsbrdf.inference.highlights`; rows ``{"pass": "highlights"}``).
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.optimize import minimize

from mi_dsbrdf.backend import single_blas_thread
from mi_dsbrdf.brdf.chromaticity import chroma_logits, softmax_chroma
from mi_dsbrdf.brdf.dsbrdf import Material
from mi_dsbrdf.config import Config
from mi_dsbrdf.errors import InputError
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.inference.objective import Posterior
from mi_dsbrdf.inference.pixels import image_level
from mi_dsbrdf.inference.latlong import BLACK, resample
from mi_dsbrdf.inference.lobes import highlight_change
from mi_dsbrdf.inference.reflectance import image_chroma_logits, reflectance_block, reflectance_starts
from mi_dsbrdf.inference.result import Recovery
from mi_dsbrdf.inference.uncertainty import highlight_doubt, illumination_spread, laplace
from mi_dsbrdf.model.priors import LOG_CHROMA_BASIS

#: upper bound of the log radiance of a texel
LOG_MAX = 30.0
#: the largest move of the colour split (colour_split) in log chromaticity
SPLIT_LIMIT = 2.0
#: the start's blocks run this fraction of a round's iterations (at least START_MIN_ITERS)
START_FRACTION, START_MIN_ITERS = 0.5, 5
def start_iters(iters) -> int:
    return max(int(iters * START_FRACTION), START_MIN_ITERS)


@single_blas_thread
def recover_envmap(texels: TexelSum, observed, mask, model, config: Config = None, colour=True,
                   progress=None, starts=None) -> Recovery:
    """MAP estimate of the material and the illumination map of one image.

    Parameters
    ----------
    texels : the view at ``config.map_size`` (its BSDF is not used: the
        posterior brings its own)
    observed : (H, W, 3) float radiance; mask : (H, W) bool usable pixels
    model : :class:`~mi_dsbrdf.model.model_file.ReflectanceModel`
    config : :class:`~mi_dsbrdf.config.Config` (default ``Config()``)
    colour : run the colour pass after the grey one
    progress : called with each logged row
    starts : the psi (k,) to start from (default
        :func:`~mi_dsbrdf.inference.reflectance.reflectance_starts`: the mean
        material and the GMM's means); one start skips the choice among them
    """
    cfg = config or Config()
    # the image's units: the method is invariant to them (light x material), this
    # code's constants are not (the map's log bounds and the BLACK of unseen texels;
    # L-BFGS-B's first step runs to those bounds). Inference sees the image at a
    # mean of one, and the map is scaled back at the end
    exposure = image_level(observed, mask)
    observed = np.asarray(observed, dtype=np.float64) / exposure
    posteriors = {}

    # every map size works on the same pixels, the full map's budget (Config.map_pairs):
    # the coarse start has fewer texels, but it only chooses among the starts
    max_pixels = cfg.map_pairs // (cfg.map_size[0] * cfg.map_size[1])

    def posterior(size, pass_name, highlights=0):
        samples, pass_cfg = cfg.texel_samples, cfg
        if pass_name in ("start", "grey"):
            if cfg.grey_texel_samples is not None:
                samples = cfg.grey_texel_samples
            # the start and the grey pass hold the lobes at the image's colour and the
            # map grey: the colour-split priors are constants there, and left out (a
            # constant would move Levenberg-Marquardt's relative stopping test)
            pass_cfg = cfg.with_colour_split(False)
        key = (size, samples, highlights, pass_cfg)
        if key not in posteriors:
            posteriors[key] = Posterior(view(size, samples, highlights), observed, mask, model, pass_cfg,
                                        max_pixels=max_pixels)
        return posteriors[key]

    # a view's shadow rays and bounces are traced once, for every pass that shares it
    views = {} if texels.highlights is not None else {
        (texels.map_size, int(round(texels.per_texel ** 0.5)), 0): texels}

    def view(size, samples, highlights):
        key = (tuple(size), samples, highlights)
        if key not in views:
            views[key] = (view(size, samples, 0).with_highlights(highlights) if highlights
                          else texels.with_map_size(size, samples))
        return views[key]

    rows = []
    t0 = time.perf_counter()

    def log(row):
        rows.append(dict(row, seconds=time.perf_counter() - t0))
        if progress:
            progress(rows[-1])

    end = route(posterior, model, starts, cfg, log, colour, on_colour=False, grey_pass=True)
    # the second route (Config.second_route_highlight): an answer with a highlight is
    # checked against the inference that judges the starts on the colour pass's
    # posterior and has no grey pass; the lower posterior of the two (the same
    # posterior: both end in the colour pass) is the answer
    second = colour and cfg.second_route_highlight is not None
    loser = None
    if second and Material.from_basis(model.basis, end[0], softmax_chroma(end[1])).highlight_ratio() \
            > cfg.second_route_highlight:
        first_last = rows[-1]
        other = route(posterior, model, starts, cfg, lambda row: log(dict(row, route=1)), True, on_colour=True,
                      grey_pass=False)
        won = int(other[4] < end[4])             # a tie keeps the first route's answer
        # the answer's row last, so that the log's last row is the answer's posterior
        # (Recovery.neg_log_posterior) whichever route it came from
        log({**{k: v for k, v in (rows[-1] if won else first_last).items() if k not in ("route", "seconds")},
             "pass": "answer", "answer_route": won})
        end, loser = (end, other)[won], (end, other)[1 - won]
    # the highlight pairs where they change the answer's image (module doc)
    route_end = end[4]                  # the routes' posterior, to compare the other mode with
    last_pass = "colour" if colour else "grey"
    last = posterior(cfg.map_size, last_pass)
    change, used_pairs = None, 0
    if cfg.highlight_texels:
        psi, logits, log_map, seen = end[:4]
        change = highlight_change(last.view.texels, np.nonzero(last.keep)[0], last.material(psi, logits),
                                  np.where(seen[..., None], np.exp(log_map), 0.0).reshape(-1, 3),
                                  cfg.highlight_texels)
        if change >= cfg.highlight_check:
            last = posterior(cfg.map_size, last_pass, cfg.highlight_texels)
            end = alternate(last, last_pass, cfg.map_size, *end[:3], cfg,
                            lambda row: log(dict(row, **{"pass": "highlights", "highlight_change": change})))
            used_pairs = cfg.highlight_texels
    psi, logits, log_map, seen, _ = end
    chroma = softmax_chroma(logits)
    # the material's posterior with the map at its MAP, on the last pass's posterior
    t_posterior = time.perf_counter()
    posterior_of_material = laplace(last, psi, logits, np.where(seen[..., None], np.exp(log_map), 0.0).reshape(-1, 3),
                                    fit_chroma=colour)
    material = Material.from_basis(model.basis, psi, chroma, name="recovered")
    other_material = gap = None
    if loser is not None:
        # the other route's answer: a second mode of the same posterior
        other_material = Material.from_basis(model.basis, loser[0], softmax_chroma(loser[1]), name="other mode")
        gap = float(loser[4] - route_end)
        posterior_of_material = dataclasses.replace(posterior_of_material, alternatives=(
            (other_material.parameters() - material.parameters(), gap),))
    spread = illumination_spread(last, log_map, last.transport(psi, logits), seen)
    material = material.with_covariance(posterior_of_material.factor())
    return Recovery(material=material, psi=psi, highlight_doubt=highlight_doubt(material),
                    chromaticity=chroma, illumination=np.where(seen[..., None], np.exp(log_map) * exposure, 0.0),
                    seen=seen, log=rows, laplace=posterior_of_material, illumination_spread=spread,
                    posterior_seconds=time.perf_counter() - t_posterior, other_mode=other_material,
                    other_mode_gap=gap, highlight_change=change, highlight_texels=used_pairs)


def route(posterior, model, starts, cfg, log, colour, on_colour, grey_pass) -> tuple:
    """One inference from the starts to the last pass's end: the start stage (on the
    coarse map, or with ``on_colour`` on the colour pass's posterior), the grey pass
    (if ``grey_pass``), the colour pass (if ``colour``). ``posterior(size,
    pass_name)`` gives each stage's :class:`~mi_dsbrdf.inference.objective.Posterior`.
    Returns the last pass's (psi, logits, log map, seen (H, W), negative log
    posterior)."""
    passes = (["grey"] if grey_pass else []) + (["colour"] if colour else [])
    sizes = map_sizes(cfg.map_size, cfg.map_levels, len(passes))
    # on_colour: the starts are judged on the colour pass's posterior (the full map,
    # each texel lit from texel_samples^2 directions), by an illumination block with
    # the material held; else on the coarse map at texel centres, by an illumination
    # block and a reflectance block
    post = posterior(sizes[-1], "colour") if on_colour else posterior(sizes[0], "start")
    start_size = sizes[-1] if on_colour else sizes[0]
    logits0 = image_chroma_logits(post.observed, post.keep, post.R)
    # each reflectance start with the constant map that matches the image's median
    # level, refined by one grey illumination block and one reflectance block (or,
    # on_colour, an illumination block alone); the lowest posterior goes on. The
    # start and the grey pass keep every lobe at the image's colour (under a grey
    # map, free chromaticities would explain the light's colour by saturated
    # lobes); the colour pass frees them
    found = []
    H, W = start_size
    for i, p0 in enumerate(psi_starts(model, starts)):
        T = post.transport(p0, logits0)
        seen = ~post.view.unseen.reshape(H, W)
        x = constant_log_map(post, T, (H, W))
        bins = post.entropy.bins_for(x, seen)
        x = illumination_block(post, x, T, seen, bins, True, start_iters(cfg.illumination_iters))
        if on_colour:
            value = posterior_at(post, p0, logits0, x, T, seen, post.entropy.bins_for(x, seen))[0]
            psi, logits, scale = p0, logits0, 0.0
        else:
            L = np.where(seen[..., None], np.exp(x), 0.0).reshape(-1, 3)
            step = reflectance_block(post, p0, logits0, L, start_iters(cfg.block_iters), fit_scale=True,
                                     fit_chroma=False)
            value = post.reflectance_terms(step.psi, step.logits, step.L)[0]
            psi, logits, scale = step.psi, step.logits, float(np.log(step.L.max() / L.max()))
        log({"pass": "start", "round": i, "neg_log_posterior": value, "map_size": [H, W]})
        found.append((value, psi, logits, np.where(seen[..., None], x + scale, BLACK)))
    # min is stable: equal posteriors keep the starts' order
    end = min(found, key=lambda f: f[0])[1:]
    for pass_name, size in zip(passes, sizes[1:]):
        end = alternate(posterior(size, pass_name), pass_name, size, *end[:3], cfg, log)
    return end


def constant_log_map(post, T, size) -> np.ndarray:
    """Where every start begins: the constant log map (H, W, 3) of ``size`` whose
    image through the transport ``T`` matches the usable pixels' median level."""
    level = np.median(post.observed[post.keep]) / max(np.median(T.sum(axis=2).T[post.keep]), 1e-12)
    return np.full(tuple(size) + (3,), np.log(max(level, 1e-12)))


def alternate(post, pass_name, size, psi, logits, log_map, cfg, log) -> tuple:
    """One pass of alternating illumination and reflectance blocks (at most
    ``cfg.max_rounds`` rounds, until the posterior changes by less than
    ``cfg.tol``) on a map of ``size`` from the given state (the map resampled to
    it). Logs one row per round. Returns (psi, logits, log map, seen (H, W),
    negative log posterior)."""
    H, W = size
    log_map = resample(log_map, size)
    T = post.transport(psi, logits)
    seen = ~post.view.unseen.reshape(H, W)
    prev = kept = None
    for rnd in range(cfg.max_rounds):
        # illumination block (T from the current reflectance)
        bins = post.entropy.bins_for(log_map, seen)
        log_map = illumination_block(post, log_map, T, seen, bins, pass_name == "grey", cfg.illumination_iters)
        kept = posterior_at(post, psi, logits, log_map, T, seen, bins)
        # reflectance block, with the map's overall scale, over a subset of the
        # pixels: kept only if the posterior over all of them falls too (a step
        # that fits the subset can ruin the rest). From the colour pass's second
        # round it first takes the joint step along the colour split
        # (colour_split), which neither block takes; the reflectance block then
        # settles each lobe's brightness, and the two are kept or rejected
        # together (if rejected, the block alone runs). Not in the first round:
        # the sharper lobes' colour is still the start's guess (START_GREY_MIX)
        tries = [(False, logits, log_map)]
        if pass_name == "colour" and cfg.colour_split and rnd > 0:
            tries.insert(0, (True, *colour_split(post, logits, log_map, seen)))
        for with_split, try_logits, try_map in tries:
            L = np.where(seen[..., None], np.exp(try_map), 0.0).reshape(-1, 3)
            step = reflectance_block(post, psi, try_logits, L, cfg.block_iters, fit_scale=True,
                                     fit_chroma=pass_name == "colour")
            new_map = try_map + float(np.log(step.L.max() / L.max()))
            new_T = post.transport(step.psi, step.logits)   # serves the next illumination block
            new = posterior_at(post, step.psi, step.logits, new_map, new_T, seen, bins)
            rejected = not new[0] <= kept[0]
            if not rejected:
                psi, logits, log_map, T, kept = step.psi, step.logits, new_map, new_T, new
                break
        total, lik, terms = kept
        log({"pass": pass_name, "round": rnd, "neg_log_posterior": total, "likelihood": lik, **terms,
             "unseen_texels": int((~seen).sum()), "map_size": [H, W], "reflectance_step_rejected": rejected,
             "colour_split_kept": bool(with_split and not rejected)})
        if prev is not None and abs(prev - total) <= cfg.tol * abs(prev):
            break
        prev = total
    return psi, logits, log_map, seen, kept[0]


def colour_split(post, logits, log_map, seen) -> tuple:
    """The joint step along the split of colour between material and light (not in
    the paper), which one image cannot see: the map's channels times g and every
    lobe's chromaticity divided by g leave the image unchanged but for each lobe's
    brightness (its chromaticity is renormalised), so neither block moves along it
    (each holds the other's colour). g = exp(B u), u (2,) in the plane orthogonal to
    (1, 1, 1) (:data:`~mi_dsbrdf.model.priors.LOG_CHROMA_BASIS`), minimises the
    weighted chromaticity and light-colour priors, by L-BFGS-B within
    +-SPLIT_LIMIT. The hue prior is left to the caller's acceptance test: it
    prices the angles between the lobes' hues, which are undefined at grey, and
    rewards any tint all lobes share over none (a grey material moved to the
    bound). Returns (logits (R, 2), log map (H, W, 3)) after the step, the map
    scaled to keep the broad lobe's (lobe 0) light exactly."""
    c = softmax_chroma(logits)
    log_m = post.light_colour.colour(np.where(seen[..., None], log_map, BLACK))

    def moved(u):
        lg = LOG_CHROMA_BASIS @ u
        c2 = c * np.exp(-lg)
        return lg, c2 / c2.sum(axis=1, keepdims=True), c2.sum(axis=1)

    def cost(u):
        lg, c2, _ = moved(u)
        material = post.w["chromaticity"] * post.model.chromaticity_prior.nll(c2) if post.w["chromaticity"] else 0.0
        return material + post.light_colour.nll_of_colour(log_m + lg)

    res = minimize(cost, np.zeros(2), method="L-BFGS-B", bounds=[(-SPLIT_LIMIT, SPLIT_LIMIT)] * 2)
    lg, c2, sums = moved(res.x if res.fun < cost(np.zeros(2)) else np.zeros(2))
    return chroma_logits(c2, floor=1e-3), np.where(seen[..., None], log_map + lg + np.log(sums[0]), BLACK)


def psi_starts(model, starts=None) -> list:
    """``starts`` as a list of (k,) float arrays, checked (InputError), or
    :func:`~mi_dsbrdf.inference.reflectance.reflectance_starts` for None."""
    if starts is None:
        return reflectance_starts(model)
    k = model.basis.n_bases
    out = [np.asarray(p, dtype=np.float64) for p in starts]
    if not out or any(p.shape != (k,) or not np.all(np.isfinite(p)) for p in out):
        raise InputError("starts must be a non-empty list of finite psi vectors of %d values each" % k)
    return out


def posterior_at(post, psi, logits, log_map, T, seen, bins) -> tuple:
    """(negative log posterior, likelihood, prior terms) of the whole image at a
    material whose transport is ``T`` and the log map (unseen texels black)."""
    lik = post.map_likelihood(log_map, T, seen, grad=False)[0]
    terms = post.prior_terms(psi, logits, log_map, bins)
    return lik + sum(terms.values()), lik, terms


def map_sizes(map_size, levels, n_passes) -> list:
    """Map sizes (H, W) of the start and of each pass: the start on ``map_size``
    halved ``levels - 1`` times (never below 2 x 4), every pass on ``map_size``.
    The start only chooses among the reflectance starts, and a coarse map has fewer
    unknowns and a smaller transport. The passes do not run coarse: a lobe sharper
    than the texel spacing hides between the texel centres of a coarse map."""
    H, W = map_size
    start = (max(H >> (levels - 1), 2), max(W >> (levels - 1), 4))
    return [start] + [(H, W)] * n_passes


def illumination_block(post, log_map, T, seen, bins, grey, iters) -> np.ndarray:
    """L-BFGS-B on the log map (H, W, 3) at fixed reflectance (transport ``T``):
    likelihood + entropy + gradient priors over the ``seen`` texels; with
    ``grey`` one value per texel shared by the channels. Returns the new log map
    (unseen texels at BLACK)."""
    H, W, _ = log_map.shape
    idx = seen.reshape(-1)

    def unpack(v):
        x = np.full((H * W, 3), BLACK)
        x[idx] = v[:, None] if grey else v.reshape(-1, 3)
        return x.reshape(H, W, 3)

    def fun(v):
        val, g, _ = post.illumination_terms(unpack(v), T, seen, bins)
        g = g.reshape(-1, 3)[idx]
        return val, (g.sum(axis=1) if grey else g.reshape(-1))

    x0 = log_map.reshape(-1, 3)[idx]
    v0 = x0.mean(axis=1) if grey else x0.reshape(-1)
    res = minimize(fun, v0, jac=True, method="L-BFGS-B", options={"maxiter": iters, "maxfun": 2 * iters},
                   bounds=[(BLACK + 1, LOG_MAX)] * v0.size)
    return unpack(res.x)
