"""Joint MAP estimate of reflectance and a point or directional light (paper §5).

The light is a direction (unit vector from the object towards the light) and a
non-negative intensity, equal in RGB (the colour is the material's): irradiance
for a directional light; for a point light, which sits at a distance taken from
the scene, the radiant intensity in W/sr. A wrong reflectance biases the light
and the other way round, so the search starts globally (:func:`recover_light`):
the best few of 64 directions under the mean material, and the directions the
brightest pixel suggests, each get a short reflectance fit and a coarse Powell
refinement; the best posterior starts the alternation: Powell's method on the
light (:func:`light_block`) and the reflectance block from every start, then
rounds of the reflectance block with the light refined jointly.
"""
from __future__ import annotations

import time

import numpy as np
from scipy.optimize import minimize

from mi_dsbrdf.backend import single_blas_thread
from mi_dsbrdf.brdf.chromaticity import softmax_chroma
from mi_dsbrdf.brdf.dsbrdf import Material
from mi_dsbrdf.config import Config
from mi_dsbrdf.errors import InputError
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.inference.objective import Posterior, angles_from_direction, direction_from_angles
from mi_dsbrdf.inference.reflectance import image_chroma_logits, reflectance_block, reflectance_starts
from mi_dsbrdf.inference.result import Recovery
from mi_dsbrdf.inference.uncertainty import LIGHT_POSTERIOR_TEMPERATURE, highlight_doubt, laplace

#: directions of the global search (Fibonacci lattice) and how many of them go on
SEARCH_DIRECTIONS, SEARCH_KEEP = 64, 6
#: directions the brightest observed pixel suggests (:func:`highlight_lights`)
HIGHLIGHT_DIRECTIONS = 2
#: candidates the light search refines at most (one logged row each): the
#: SEARCH_KEEP best of the lattice and the HIGHLIGHT_DIRECTIONS
SEARCH_CANDIDATES = SEARCH_KEEP + HIGHLIGHT_DIRECTIONS
#: the search's reflectance fits run this fraction of a block's iterations (at least 5)
SEARCH_FRACTION = 0.25
#: function evaluations of the search's coarse Powell refinement, and of a light block
#: (40 in the search: within 1 % in Eq. 20 of the answers at 100, in 40 % of the time)
SEARCH_POWELL_EVALS, POWELL_EVALS = 40, 400
#: the fraction of its components' volume terms the GMM prior keeps under a point or
#: directional light (:class:`~mi_dsbrdf.inference.objective.Posterior`): 1 is the
#: normalised density of Eq. 6 (a light sees a narrow band of theta_d, and the prior
#: carries more of the answer)
LIGHT_GMM_VOLUME = 1.0


def light_likelihood(post, material, theta, phi, log_intensity) -> float:
    """Eq. 19 of the image of ``material`` under a light from (theta, phi) of this
    log intensity, over the reflectance block's evenly spread pixels (scaled to
    stand for all): the light has 3 unknowns, and this is Powell's inner loop."""
    post.aim(theta, phi)
    return post.subset_likelihood(material, np.full((1, 3), np.exp(log_intensity)))


def light_block(post, material, theta, phi, log_intensity, maxfev=POWELL_EVALS) -> tuple:
    """Powell's method on (theta, phi, log intensity) with the reflectance fixed."""
    res = minimize(lambda v: light_likelihood(post, material, *v), [theta, phi, log_intensity], method="Powell",
                   options={"xtol": 1e-4, "ftol": 1e-7, "maxfev": maxfev})
    return tuple(res.x)


def candidate_lights(post, material, n=SEARCH_DIRECTIONS, keep=SEARCH_KEEP) -> list:
    """The ``keep`` best of ``n`` directions spread over the sphere (Fibonacci
    lattice), each with the intensity that matches the image's median level under
    ``material``: [(likelihood, theta, phi, log intensity), ...]."""
    found = []
    i = np.arange(n) + 0.5
    thetas, phis = np.arccos(1 - 2 * i / n), np.pi * (1 + 5 ** 0.5) * i
    for th, ph in zip(thetas, phis):
        log_i = matched_log_intensity(post, material, th, ph)
        if log_i is None:
            continue
        found.append((light_likelihood(post, material, th, ph, log_i), th, ph % (2 * np.pi), log_i))
    if not found:
        raise InputError("no light direction lights the observed pixels")
    return sorted(found)[:keep]


def matched_log_intensity(post, material, theta, phi):
    """Log intensity that matches the median observed level of the pixels a light
    from (theta, phi) reaches under ``material``; None if it reaches none."""
    post.aim(theta, phi)
    v = post.refl
    lit = v.lobes.render(material, np.ones((1, 3))).mean(axis=1)[v.keep]
    if not np.any(lit > 0):
        return None
    ratio = np.median(v.observed[v.keep].mean(axis=1)[lit > 0]) / np.median(lit[lit > 0])
    return float(np.log(ratio)) if ratio > 0 else None


def highlight_lights(post) -> list:
    """Directions the brightest observed pixel suggests: its normal (the light of a
    matte object) and the mirror of the view direction about it (the light of a
    glossy one), as [(theta, phi), ...] (:data:`HIGHLIGHT_DIRECTIONS` of them)."""
    lum = np.where(post.keep, post.observed.mean(axis=1), -np.inf)
    i = int(np.argmax(lum))
    si = post.view.texels.si
    n = np.array(si.n)[:, i].astype(np.float64)
    v = np.array(si.to_world(si.wi))[:, i].astype(np.float64)
    mirror = 2 * (n @ v) * n - v
    return [angles_from_direction(n), angles_from_direction(mirror)]


@single_blas_thread
def recover_light(texels: TexelSum, observed, mask, model, config: Config = None, progress=None,
                  known_light=None, point=None, colour=True) -> Recovery:
    """MAP estimate of the material and a directional or point light.

    Parameters
    ----------
    texels : the view (its BSDF is not used: the posterior brings its own)
    observed : (H, W, 3) float radiance; mask : (H, W) bool usable pixels
    model : :class:`~mi_dsbrdf.model.model_file.ReflectanceModel`
    config : :class:`~mi_dsbrdf.config.Config` (default ``Config()``)
    progress : called with each logged row
    known_light : (direction (3,), intensity): skip the light search and block
    point : (centre (3,), distance) of a point light: it sits at ``distance``
        from ``centre`` in the recovered direction; None: a directional light
    colour : fit the lobes' chromaticities; False for a grey image, whose lobes
        keep its colour (grey): free, a lobe the image barely shows could take any
        colour
    """
    cfg = config or Config()
    # the light is white by assumption (its colour is the material's): the priors that
    # split the image's colour between material and light are a map's
    def posterior(view):
        return Posterior(view, observed, mask, model, cfg.with_colour_split(False), point=point,
                         gmm_volume=LIGHT_GMM_VOLUME)
    post = posterior(texels)
    # the search and the first round see each pixel through its centre ray (most of
    # the evaluations); the later rounds refine material and light over the pixels'
    # footprints (TexelSum.pixel_rays)
    search = post if texels.pixel_rays == 1 else posterior(texels.with_pixel_rays(1))
    logits = image_chroma_logits(post.observed, post.keep, post.R)
    psi = np.zeros(post.k)
    t0 = time.perf_counter()
    rows = []

    def log(row):
        rows.append(dict(row, seconds=time.perf_counter() - t0))
        if progress:
            progress(rows[-1])

    if known_light is None:
        mean_material = search.material(psi, logits)
        best = None
        cands = [c[1:] for c in candidate_lights(search, mean_material)]
        for th, ph in highlight_lights(search):
            li = matched_log_intensity(search, mean_material, th, ph)
            if li is not None:
                cands.append((th, ph, li))
        for th, ph, li in cands:
            search.aim(th, ph)
            step = reflectance_block(search, psi, logits, np.full((1, 3), np.exp(li)),
                                     max(int(cfg.block_iters * SEARCH_FRACTION), 5), fit_scale=True,
                                     fit_chroma=colour)
            li = float(np.log(step.L[0, 0]))
            th, ph, li = light_block(search, search.material(step.psi, step.logits), th, ph, li,
                                     maxfev=SEARCH_POWELL_EVALS)                     # coarse: refined later
            search.aim(th, ph)
            value = search.reflectance_terms(step.psi, step.logits, np.full((1, 3), np.exp(li)))[0]
            log({"pass": "light search", "round": len(rows), "neg_log_posterior": value})
            if best is None or value < best[0]:
                best = (value, step.psi, step.logits, th, ph, li)
        _, psi, logits, theta, phi, log_i = best
    else:
        theta, phi = angles_from_direction(known_light[0])
        log_i = float(np.log(known_light[1]))
    prev = None
    for rnd in range(cfg.max_rounds):
        if known_light is None and rnd == 0:
            # Powell on the light; from the second round on, the reflectance block
            # refines the direction and the scale jointly with the material
            theta, phi, log_i = light_block(search, search.material(psi, logits), theta, phi, log_i)
        L = np.full((1, 3), np.exp(log_i))
        post.aim(theta, phi)
        if rnd == 0:
            # the reflectance block from every start (psi found so far, the mean, GMM
            # means), on the search's centre rays like the light block before it
            search.aim(theta, phi)
            steps = [reflectance_block(search, p0, logits, L, cfg.block_iters, fit_scale=known_light is None,
                                       fit_chroma=colour) for p0 in [psi] + reflectance_starts(model)]
            step = min(steps, key=lambda s: search.reflectance_terms(s.psi, s.logits, s.L)[0])
        elif known_light is None:
            step = reflectance_block(post, psi, logits, L, cfg.block_iters, fit_scale=True, direction=(theta, phi),
                                     fit_chroma=colour)
            theta, phi = step.direction
        else:
            step = reflectance_block(post, psi, logits, L, cfg.block_iters, fit_chroma=colour)
        psi, logits, L = step.psi, step.logits, step.L
        log_i = float(np.log(L[0, 0]))
        total, lik = post.reflectance_terms(psi, logits, L)
        log({"pass": "light", "round": rnd, "neg_log_posterior": total, "likelihood": lik,
             **post.prior_terms(psi, logits)})
        if prev is not None and abs(prev - total) <= cfg.tol * abs(prev):
            break
        prev = total
    direction = direction_from_angles(theta, phi)
    light = {"type": "directional" if point is None else "point", "direction": direction,
             "intensity": float(np.exp(log_i))}
    if point is not None:
        light["position"] = np.asarray(point[0]) + point[1] * direction
    chroma = softmax_chroma(logits)
    # the material's posterior with the light at its MAP
    t_posterior = time.perf_counter()
    post.aim(theta, phi)
    posterior_of_material = laplace(post, psi, logits, np.full((1, 3), np.exp(log_i)), fit_chroma=colour,
                                    temperature=LIGHT_POSTERIOR_TEMPERATURE)
    material = Material.from_basis(model.basis, psi, chroma, name="recovered").with_covariance(
        posterior_of_material.factor())
    return Recovery(material=material, psi=psi, chromaticity=chroma, light=light, log=rows,
                    laplace=posterior_of_material, highlight_doubt=highlight_doubt(material),
                    posterior_seconds=time.perf_counter() - t_posterior)
