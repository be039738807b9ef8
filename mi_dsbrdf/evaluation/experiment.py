"""Synthetic experiments with known truth (paper §6): one case, run and scored.

A *case* is a plain dict (JSON, so a runner can ship it to any worker)::

    {"id": "point-chrome-60-priors", "kind": "point" | "probe", "material": MERL name,
     "angle": degrees from the viewer (point), "probe": "probulator/grace.hdr" (probe),
     "priors": bool, "weights": {"w_entropy": ..., ...} (optional Config prior
     weights, with priors), "shape": "sphere" | "torus", "res": pixels, "map": [H, W],
     "rounds": int, "iters": int, "method": "dsbrdf" | "dsbrdf-adam" | "principled-adam" | "mean-constant"
     (probes: the model's mean material under a constant map, the do-nothing baseline),
     "spp": samples per pixel (Adam methods), "gmm": the leave-one-out model's GMM
     structure (optional, :func:`~mi_dsbrdf.model.build.gmm_structure`; default the build's),
     "bases": the leave-one-out model's number of bases k (optional; default the build's),
     "fits_from": the model file whose stored full fits the leave-one-out model is built from
     (optional; default the shipped one),
     "truth_samples": directions per texel side of the probe's truth render (optional, default 1:
     the texel centres; the probe's map integrated over each texel's footprint as s x s directions),
     "exposure": the rendered image's factor (optional, probes, default 1: the result must not
     depend on it; another exposure reruns the case with only rounding changed),
     "photons": shot noise (optional, probes; default none): the image as photon counts, this many
     at the mean of the pixels that see the object (the silhouette ring included), Poisson-drawn
     (:func:`shot_noise`; a camera's raw image near mid-grey holds a few thousand),
     "start": index into :func:`~mi_dsbrdf.inference.reflectance.reflectance_starts` (optional,
     probes: run from that start alone, a diagnostic of the choice among them)}

:func:`run_case` renders the truth with the measured material (the ``merl``
plugin evaluated by the texel-sum forward model; a probe at twice the
recovered map's resolution, a point light at distance 5 with intensity 40 and
each pixel the mean of PHOTO_PIXEL_RAYS x PHOTO_PIXEL_RAYS rays across it),
recovers it with a leave-one-out model (:func:`~mi_dsbrdf.model.build.loo_model`: the material's own
fit is left out of bases and priors) from the pixels the app would use
(:func:`~mi_dsbrdf.inference.pixels.usable_pixels`: the silhouette ring dropped;
every method alike) and scores it:

* ``brdf_eq20_paper``, ``brdf_eq20_cosine``: Eq. 20 on the MERL grid
  (scale-invariant) in the paper's convention, log(f + 1e-6), and the
  cosine-weighted one, log(1 + f cos theta_i) (:mod:`~mi_dsbrdf.evaluation.metrics`),
  for every case;
* ``brdf_eq20_observed_paper``, ``..._cosine``, ``brdf_eq20_unobserved_...``: the same
  on the MERL cells whose (theta_h, theta_d) the used pixels see under the true
  light (:func:`~mi_dsbrdf.inference.lobes.observed_directions`), and on the rest;
  ``observed_fraction``: the observed share of the cells;
* ``brdf_eq5_paper``, ``brdf_eq5_cosine``: Eq. 5 with the known light scale
  (point lights: the BRDF times recovered / true intensity);
* ``direction_error_deg`` (point lights);
* ``brdf_eq20_paper_by_theta_d``: where in theta_d that error lies
  (:func:`~mi_dsbrdf.evaluation.metrics.log_error_by_theta_d`); ``material``: the
  recovered psi and chromaticity (DSBRDF answers in basis form);
* ``highlight_ratio``, ``truth_highlight_ratio``: the recovered and the
  measured BRDF's peak over off-peak (:func:`~mi_dsbrdf.evaluation.metrics.highlight_ratio`):
  a near-Lambertian material must not come back with a highlight;
* ``illumination_error``, ``illumination_error_paper``: the scale-invariant
  log-RMSE (:func:`~mi_dsbrdf.evaluation.metrics.scale_invariant_log_error`, in
  its log(1 + L) and its paper-like log(L + 1e-6) convention) of the seen texels
  against the truth map at the recovered resolution (probes);
* ``relight``: the same measure (:func:`~mi_dsbrdf.evaluation.metrics.scale_invariant_log_error`) on the
  recovered material relit under two other probes against the measured
  material under them (paper Fig. 9); the images (truth, recovered at its
  best scale; in units of the truth's mean) are returned for the report;
  ``relight_psnr``: the same images in the Stanford-ORB convention
  (:func:`~mi_dsbrdf.evaluation.metrics.relight_psnr`, dB, higher is better);
* ``baseline``: doing nothing, scored on the same case: the leave-one-out
  model's mean material (psi = 0) in every BRDF and relighting measure, and for
  probes a constant map in ``illumination_error`` on the same seen texels;
* ``posterior`` (this tool's answers): the posterior band's coverage of the truth and its width,
  the material's and the map's (:func:`~mi_dsbrdf.evaluation.metrics.posterior_scores`) at each
  of :data:`TEMPERATURES` and the shipped ones, and the seconds they took within the recovery's;
* ``other_mode`` (probes with this tool, where the second route ran): the posterior's other mode
  against the answer and the truth (:func:`~mi_dsbrdf.evaluation.metrics.mode_scores`);
* ``highlight_doubt``, ``flags``, ``highlight_change`` and ``highlight_texels`` (this tool's
  answers): what ``Recovery`` says of them;
* ``terms``: the last logged round's negative log posterior term by term
  (likelihood, each weighted prior; probes with this tool);
* ``trace``: the negative log posterior of every logged round, ``rounds``,
  ``seconds`` (point cases: the recovery's; probes: with the truth's render), and ``finite``
  (no NaN/Inf anywhere in the result).
"""
from __future__ import annotations

import hashlib
import math
import os
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_dsbrdf.brdf.measured import MeasuredBRDF
from mi_dsbrdf.evaluation.adam import adam_recover
from mi_dsbrdf.config import NO_PRIORS, Config
from mi_dsbrdf.evaluation.metrics import (CONVENTIONS, bsdf_values, direction_error_deg, highlight_ratio,
                                          log_error_by_theta_d, mode_scores, observed_samples, observed_split,
                                          posterior_scores, log_rmse, log_rmse_scale_invariant, relight_psnr,
                                          scale_invariant_log_error)
from mi_dsbrdf.inference.envmap import recover_envmap
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.inference.images import read_image
from mi_dsbrdf.inference.latlong import texel_blocks
from mi_dsbrdf.inference.light import recover_light
from mi_dsbrdf.inference.pixels import usable_pixels
from mi_dsbrdf.inference.reflectance import reflectance_starts
from mi_dsbrdf.inference.scene_dicts import camera, shape_dict
from mi_dsbrdf.inference.uncertainty import MAP_TEMPERATURE
from mi_dsbrdf.model import model_file as model_data
from mi_dsbrdf.model.build import loo_model
from mi_dsbrdf.model.samples import samples_from_table

#: the posterior band scored (``posterior``) and the temperatures it is scored at beside the shipped ones
BAND_LEVEL = 0.9
TEMPERATURES = (30, 100, 300, 1000, 2000, 4000, 10000, 15000, 20000, 30000)
#: probes used for relighting (the first two that differ from the case's probe)
RELIGHT_PROBES = ["probulator/pisa.hdr", "probulator/uffizi.hdr", "probulator/ennis.hdr"]
#: point light of the point cases: distance from the object's centre, intensity (W/sr)
POINT_DISTANCE, POINT_INTENSITY = 5.0, 40.0
#: rays per pixel side of a point-lit photograph: each pixel the mean over its area,
#: as a camera's (box filter); within 0.7 % of Mitsuba's render of a sharp highlight
#: at the terminator, where the centre ray alone is 13 % off
PHOTO_PIXEL_RAYS = 8


# --- scenes and truth ---------------------------------------------------------------

def light_at(angle_deg) -> np.ndarray:
    """Unit direction at ``angle_deg`` from the viewer (+z), tilted up and to the side."""
    a = math.radians(angle_deg)
    d = np.array([math.sin(a) * 0.8, math.sin(a) * 0.6, math.cos(a)])
    return d / np.linalg.norm(d)


def downsample(env, height, width) -> np.ndarray:
    """Box-filter an (h, w, 3) lat-long map to (height, width, 3) (h, w multiples of it after cropping)."""
    h, w = env.shape[:2]
    e = env[:h - h % height, :w - w % width, :3]
    return e.reshape(height, e.shape[0] // height, width, e.shape[1] // width, 3).mean(axis=(1, 3))


def texels(bsdf: dict, res: int, map_hw=(1, 1), shape="sphere", samples=1, pixel_rays=1):
    """A :class:`~mi_dsbrdf.inference.forward.TexelSum` of ``shape``
    (:func:`~mi_dsbrdf.inference.scene_dicts.shape_dict`; anything but the sphere with
    shadow rays) carrying ``bsdf``, seen by the shipped camera, each texel lit from
    ``samples`` x ``samples`` directions, a point or directional light seen through
    ``pixel_rays`` x ``pixel_rays`` rays a pixel."""
    scene = mi.load_dict({"type": "scene", "sensor": camera(res), "object": shape_dict(shape, bsdf)})
    return TexelSum(scene, scene.shapes()[0], tuple(map_hw), visibility=shape != "sphere", samples=samples,
                    pixel_rays=pixel_rays)


def render(ts, illumination=None, direction=None, point=None) -> np.ndarray:
    """(H, W, 3) image of a TexelSum under a map (T, 3) (``illumination``) or one
    light: ``direction`` (irradiance 3) or ``point`` position (intensity 40)."""
    if point is not None:
        ts = ts.with_point(point)
        illumination = np.full((1, 3), POINT_INTENSITY)
    elif direction is not None:
        ts = ts.with_directions(np.asarray(direction)[None], [1.0])
        illumination = np.full((1, 3), 3.0)
    h, w = ts.image_size
    img = np.zeros((h * w, 3))
    img[ts.pixels] = ts.render(np.asarray(illumination).reshape(-1, 3))
    return img.reshape(h, w, 3)


def mitsuba_photo(bsdf: dict, res: int, illumination, shape="sphere", spp=1024) -> np.ndarray:
    """(H, W, 3) float64 Mitsuba render (``direct``, box filter) of ``shape`` carrying
    ``bsdf`` under the map ``illumination`` (h, w, 3), its texels written as blocks
    (as the tool saves a map), seen by the shipped camera."""
    scene = {"type": "scene", "integrator": {"type": "direct", "hide_emitters": True}, "sensor": camera(res),
             "object": shape_dict(shape, bsdf), "light": {"type": "envmap", "bitmap": mi.Bitmap(texel_blocks(
                 np.asarray(illumination, dtype=np.float32)))}}
    return np.array(mi.render(mi.load_dict(scene), spp=spp, seed=0), dtype=np.float64)


def shot_noise(image, mask, photons, seed) -> np.ndarray:
    """``image`` (..., 3) with photon (Poisson) noise: counted at ``photons`` per
    unit of the mean of its ``mask`` (...) pixels, and scaled back. ``seed``: any
    string (the case's id), so that a case draws the same noise every run."""
    img = np.asarray(image, dtype=np.float64)
    unit = float(img[np.asarray(mask, bool)].mean()) / float(photons)
    rng = np.random.default_rng(int.from_bytes(hashlib.sha256(str(seed).encode()).digest()[:8], "little"))
    return rng.poisson(np.maximum(img, 0.0) / unit) * unit


def specularity(name) -> float:
    """gamma of the most specular lobe of the material's DSBRDF fit at theta_d = 0
    (the x axis of paper Fig. 8)."""
    m = model_data.shipped_model().library_material(name)
    return float(np.exp(m.log_gamma[:, 0]).max())


def _normalised_pair(truth, values, mask) -> np.ndarray:
    """(2, H, W, 3) float16: truth and ``values`` at its best linear scale, in units of the truth's mean."""
    t, v = np.asarray(truth, np.float64), np.asarray(values, np.float64)
    ref = max(float(t[mask].mean()), 1e-300)
    s = float((t[mask] * v[mask]).sum() / max((v[mask] ** 2).sum(), 1e-300))
    return np.clip(np.stack([t, s * v]) / ref, 0, 6e4).astype(np.float16)


def dsbrdf_bsdf(material):
    """The ``dsbrdf`` plugin instance of a :class:`~mi_dsbrdf.brdf.dsbrdf.Material`."""
    props = {"type": "dsbrdf", "lobes": int(material.n_lobes)}
    for r in range(material.n_lobes):
        for key, values in (("kappa", np.exp(material.log_kappa[r])), ("gamma", np.exp(material.log_gamma[r])),
                            ("chromaticity", material.chromaticity[r])):
            props["%s_%d" % (key, r)] = " ".join(repr(float(v)) for v in values)
    return mi.load_dict(props)


# --- one case -----------------------------------------------------------------------

def _finite(x) -> bool:
    if isinstance(x, dict):
        return all(_finite(v) for v in x.values())
    if isinstance(x, (list, tuple)):
        return all(_finite(v) for v in x)
    if isinstance(x, np.ndarray):
        return bool(np.all(np.isfinite(x)))
    if isinstance(x, float):
        return math.isfinite(x)
    return True


def run_case(case: dict, data: str, cache: str, threads: int = 0) -> dict:
    """Render, recover and score one case (see the module doc). ``data``: the
    folder holding ``merl/merl_nbrdf_weights.npz`` and ``envmaps/``; ``cache``:
    where leave-one-out models are kept; ``threads``: Dr.Jit's thread count (0:
    leave it). Returns a JSON-ready dict, plus numpy ``images`` for the report."""
    if threads:
        dr.set_thread_count(threads)
    nbrdf = os.path.join(data, "merl", "merl_nbrdf_weights.npz")
    name = case["material"]
    res, (H, W) = case["res"], case.get("map", (16, 32))
    model = loo_model(name, cache, case.get("gmm"), case.get("bases"), case.get("fits_from"))
    samples = samples_from_table(MeasuredBRDF.from_nbrdf(nbrdf, name))
    merl = {"type": "merl", "nbrdf": nbrdf, "material": name}
    shape = case.get("shape", "sphere")
    method = case.get("method", "dsbrdf")
    weights = case.get("weights", {}) if case.get("priors", True) else NO_PRIORS
    # the case's rounds and iterations, unless its weights (Config overrides) name them
    cfg = Config(**{"map_size": (H, W), "max_rounds": case.get("rounds", 3), "block_iters": case.get("iters", 15),
                    **weights})
    out = {"case": case, "specularity": specularity(name)}
    small = seen = None           # the truth map at the recovered resolution and its seen texels (probes)
    # the material's posterior, the map's spread and their time (this tool's answers)
    laplace = spread = posterior_seconds = None
    t0 = time.perf_counter()
    if case["kind"] == "point":
        d_true = light_at(case["angle"])
        ts = texels(merl, res, shape=shape, pixel_rays=PHOTO_PIXEL_RAYS)
        img = render(ts, point=POINT_DISTANCE * d_true)
        ts = texels({"type": "dsbrdf"}, res, shape=shape, pixel_rays=cfg.pixel_rays)
        keep = usable_pixels(ts.mask, img)
        where = observed_samples(ts.with_point(POINT_DISTANCE * d_true), np.full((1, 3), POINT_INTENSITY), keep,
                                 samples)
        t0 = time.perf_counter()                    # the recovery alone (its photograph is 8 x 8 rays a pixel)
        result = recover_light(ts, img, keep, model, cfg, point=(np.zeros(3), POINT_DISTANCE))
        out["seconds"] = time.perf_counter() - t0
        material, rows, laplace = result.material, result.log, result.laplace
        posterior_seconds = result.posterior_seconds
        values = material.eval(samples.theta_h, samples.theta_d)
        out["direction_error_deg"] = direction_error_deg(result.light["direction"], d_true)
        out["intensity_ratio"] = result.light["intensity"] / POINT_INTENSITY
        for c in CONVENTIONS:
            out["brdf_eq5_" + c] = log_rmse(values * out["intensity_ratio"], samples.values, samples.cos_i, c)
    else:
        probe = read_image(os.path.join(data, "envmaps", case["probe"]))
        truth = downsample(probe, 2 * H, 2 * W)
        ts = texels(merl, res, (2 * H, 2 * W), shape=shape, samples=case.get("truth_samples", 1))
        if case.get("photo") == "mitsuba":           # box-filtered pixels, the map sampled continuously
            img = mitsuba_photo(merl, res, truth, shape) * case.get("exposure", 1.0)
        else:
            img = render(ts, truth.reshape(-1, 3)) * case.get("exposure", 1.0)
        if case.get("photons"):
            img = shot_noise(img, ts.mask, case["photons"], seed=case["id"])
        keep = usable_pixels(ts.mask, img)          # the app's pixels: the silhouette ring dropped
        view = texels({"type": "dsbrdf"}, res, (H, W), shape=shape)     # what inference sees
        where = observed_samples(view, downsample(truth, H, W), keep, samples)
        if method == "mean-constant":
            # doing nothing: the model's mean material (psi = 0) under a constant map
            out["seconds"] = 0.0
            material, rows, seen, recovered_map = model.mean_material(), [], np.ones((H, W), bool), np.ones((H, W, 3))
            values = material.eval(samples.theta_h, samples.theta_d)
        elif method == "dsbrdf":
            starts = None if case.get("start") is None else [reflectance_starts(model)[case["start"]]]
            result = recover_envmap(view, img, keep, model, cfg, starts=starts)
            out["seconds"] = time.perf_counter() - t0
            out["terms"] = {k: float(v) for k, v in result.log[-1].items()
                            if k in ("neg_log_posterior", "likelihood", "curve_penalty", "gmm", "hue", "entropy",
                                     "gradient", "chromaticity", "light_colour")}
            material, rows, seen, recovered_map = result.material, result.log, result.seen, result.illumination
            laplace, spread, posterior_seconds = result.laplace, result.illumination_spread, result.posterior_seconds
            values = material.eval(samples.theta_h, samples.theta_d)
            if result.other_mode is not None:
                out["other_mode"] = mode_scores(result.other_mode, result.other_mode_gap, values, samples)
        else:
            fit = adam_recover(img, keep, res, (H, W), method, model, spp=case.get("spp", 16),
                               iters=case.get("iters", 100), shape=shape, seed=0)
            out["seconds"] = time.perf_counter() - t0
            rows, material, recovered_map = fit["rows"], fit["bsdf"], fit["map"]
            values = bsdf_values(material, samples) if method == "principled-adam" else \
                material.eval(samples.theta_h, samples.theta_d)
            seen = np.ones((H, W), bool)
        small = downsample(truth, H, W)
        out["illumination_error"] = scale_invariant_log_error(recovered_map, small, seen)
        out["illumination_error_paper"] = scale_invariant_log_error(recovered_map, small, seen, "paper")
        out["seen_fraction"] = float(seen.mean())
        maps = {"illumination": _normalised_pair(small, recovered_map, seen)}
    for c in CONVENTIONS:
        out["brdf_eq20_" + c], s = log_rmse_scale_invariant(values, samples.values, samples.cos_i, c)
        if c == "paper":
            scale = s
            out["brdf_eq20_paper_by_theta_d"] = log_error_by_theta_d(values, samples.values, samples.theta_d, scale)
    out.update(observed_split(values, samples, where))
    if laplace is not None:
        out["highlight_doubt"], out["flags"] = result.highlight_doubt, result.flags
        out["highlight_change"], out["highlight_texels"] = result.highlight_change, result.highlight_texels
        # the posterior band at each temperature, the shipped ones among them
        out["posterior"] = {"level": BAND_LEVEL, "default": laplace.temperature, "map_default": MAP_TEMPERATURE,
                            "seconds": posterior_seconds, "temperature": posterior_scores(
                                material, laplace, samples, where, scale,
                                sorted(set(TEMPERATURES) | {laplace.temperature, MAP_TEMPERATURE}), BAND_LEVEL,
                                None if spread is None else (recovered_map, small, seen, spread, MAP_TEMPERATURE))}
    if getattr(material, "psi", None) is not None:
        out["material"] = {"psi": material.psi.tolist(), "chromaticity": material.chromaticity.tolist()}
    out["highlight_ratio"] = highlight_ratio(values, samples.theta_h, samples.theta_d)
    out["truth_highlight_ratio"] = highlight_ratio(samples.values, samples.theta_h, samples.theta_d)
    out["trace"] = [float(r["neg_log_posterior"]) for r in rows]
    out["rounds"] = len(rows)
    out["relight"], out["relight_psnr"], images = relight(case, material, merl, data)
    if case["kind"] == "probe":
        images.update(maps)
    out["baseline"] = _do_nothing(case, model, samples, merl, data, small, seen, where)
    out["finite"] = _finite(out)
    out["images"] = images
    return out


def _do_nothing(case, model, samples, merl, data, truth_map=None, seen=None, where=None) -> dict:
    """The do-nothing baseline's measures on this case: the model's mean material
    (psi = 0) in Eq. 20 (both conventions; also on the ``where`` samples and the
    rest) and relit, and a constant map against ``truth_map`` (H, W, 3) on the
    ``seen`` texels (probes)."""
    mean = model.mean_material()
    values = mean.eval(samples.theta_h, samples.theta_d)
    out = {"brdf_eq20_" + c: log_rmse_scale_invariant(values, samples.values, samples.cos_i, c)[0]
           for c in CONVENTIONS}
    if where is not None:
        out.update(observed_split(values, samples, where))
    out["highlight_ratio"] = highlight_ratio(values, samples.theta_h, samples.theta_d)
    out["relight"], out["relight_psnr"], _ = relight(case, mean, merl, data)
    if truth_map is not None:
        for key, c in (("illumination_error", "cosine"), ("illumination_error_paper", "paper")):
            out[key] = scale_invariant_log_error(np.ones_like(truth_map), truth_map, seen, c)
    return out


def relight(case, material, merl, data, res=48, map_hw=(32, 64)):
    """Relit image errors (scale-invariant log error and Stanford-ORB PSNR) under
    two probes other than the case's, and the images (truth, recovered) for the
    report. ``material``: a DSBRDF Material or a Mitsuba BSDF."""
    probes = [p for p in RELIGHT_PROBES if p != case.get("probe")][:2]
    bsdf = dsbrdf_bsdf(material) if hasattr(material, "log_kappa") else material
    errors, psnr, images = {}, {}, {}
    truth_ts = texels(merl, res, map_hw)
    ts = texels(bsdf, res, map_hw)
    for p in probes:
        L = downsample(read_image(os.path.join(data, "envmaps", p)), *map_hw).reshape(-1, 3)
        a, b = render(truth_ts, L), render(ts, L)
        key = os.path.splitext(os.path.basename(p))[0]
        errors[key] = scale_invariant_log_error(b, a, truth_ts.mask)
        psnr[key] = relight_psnr(b, a, truth_ts.mask)
        images[key] = _normalised_pair(a, b, truth_ts.mask)
    return errors, psnr, images
