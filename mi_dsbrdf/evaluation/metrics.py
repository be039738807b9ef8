"""Error measures of the paper, as functions over arrays.

The BRDF errors (Eq. 5 and Eq. 20, in the ``"paper"`` and ``"cosine"``
conventions) live in :mod:`mi_dsbrdf.brdf.log_error`, where the model's fits
use them; they are re-exported here beside the measures of a recovery:

* :func:`log_rmse`, :func:`log_rmse_scale_invariant`, :func:`material_errors`,
  :func:`values_errors`, :func:`split_errors`, :func:`observed_errors` (Eq. 20 where the image looked, and elsewhere),
  :func:`log_brdf`, :data:`PAPER_FLOOR`, :data:`CONVENTIONS` (see
  :mod:`mi_dsbrdf.brdf.log_error`);
* :func:`log_error_by_theta_d` — where in theta_d Eq. 20 (paper) lies;
* :func:`scale_invariant_log_error` — Eq. 20's measure on images and
  illumination maps; :func:`direction_error_deg` for a recovered light;
* :func:`relight_psnr` — a relit image's PSNR in the Stanford-ORB convention;
* :func:`highlight_ratio` — peak over off-peak of a BRDF: whether a
  near-Lambertian material came back with a highlight;
* :func:`bsdf_values` — any Mitsuba BSDF on the MERL grid, to score baselines
  on the same samples as the DSBRDF;
* :func:`band_scores` — whether a recovered material's posterior band holds the
  truth (its coverage) and how wide it is, where the image looked and elsewhere;
  :func:`map_coverage`, the same for a map's spread; :func:`posterior_scores`, both
  at several temperatures; :func:`mode_scores`, the posterior's other mode;
* :func:`observed_samples` — the samples an image looks at; :func:`observed_split`,
  Eq. 20 on them and on the rest.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_dsbrdf.brdf.angles import from_half_diff
from mi_dsbrdf.brdf.dsbrdf import highlight_ratio  # noqa: F401 (one of this module's measures)
from mi_dsbrdf.inference.lobes import observed_directions
from mi_dsbrdf.brdf.log_error import (CONVENTIONS, PAPER_FLOOR, log_brdf, log_rmse,  # noqa: F401 (re-exported)
                                      log_rmse_scale_invariant, material_errors, observed_errors,
                                      split_errors, values_errors)


#: theta_d bands (degrees) of :func:`log_error_by_theta_d`: the last holds the
#: grazing pairs a sphere shows only at its rim, lit from behind it
THETA_D_BANDS = ((0, 30), (30, 60), (60, 75), (75, 90))


def log_error_by_theta_d(model_values, measured_values, theta_d, scale=1.0, bands=THETA_D_BANDS) -> dict:
    """Where in theta_d Eq. 20 (paper convention) lies: for each band
    ``"lo-hi"`` (degrees) of :data:`THETA_D_BANDS`, the RMS and the mean of
    log(s f + 1e-6) - log(rho + 1e-6) over its samples and channels, and the
    share of the total squared error it holds. ``scale``: s, the model's best
    overall scale (:func:`log_rmse_scale_invariant`'s second value); ``theta_d``
    (N,) in radians. A mean far from 0 in one band is a curve's end too bright
    (> 0) or too dark (< 0) there."""
    d = log_brdf(np.asarray(model_values, dtype=np.float64) * scale, None) - log_brdf(measured_values, None)
    td = np.degrees(np.asarray(theta_d, dtype=np.float64))
    total = max(float((d * d).sum()), 1e-300)
    out = {}
    for lo, hi in bands:
        sel = (td >= lo) & (td < hi) if hi < 90 else (td >= lo) & (td <= hi)
        if not sel.any():
            continue
        out["%d-%d" % (lo, hi)] = {"rms": float(np.sqrt(np.mean(d[sel] ** 2))), "mean": float(d[sel].mean()),
                                   "share": float((d[sel] ** 2).sum() / total)}
    return out


def direction_error_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    c = float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def scale_invariant_log_error(values, truth, mask, convention="cosine") -> float:
    """Eq. 20's measure on images or illumination maps, at the best scale s of
    ``values`` (light and material trade scale), over ``mask`` (H, W), in units
    of m, the truth's mean there: the RMSE of

    * ``"cosine"`` (the default): log(1 + s v / m) - log(1 + t / m), like the
      cosine BRDF convention nearly blind to what is darker than the mean (a
      map's sky and ground beside its sun);
    * ``"paper"``: log(s v / m + 1e-6) - log(t / m + 1e-6), like the paper's
      convention every decade alike (a map's sky/ground structure)."""
    t = np.asarray(truth, np.float64)[mask]
    ref = max(float(t.mean()), 1e-300)
    return log_rmse_scale_invariant(np.asarray(values, np.float64)[mask] / ref, t / ref, np.ones(t.shape[0]),
                                    convention)[0]


def relight_psnr(values, truth, mask) -> float:
    """PSNR (dB) of an HDR image against the truth in the Stanford-ORB convention
    as we apply it: each channel of ``values`` at its least-squares scale to the
    truth over ``mask`` (H, W), then 10 log10(peak^2 / MSE) over the masked
    pixels, the peak being the truth's largest masked value (HDR, no clipping
    or tone mapping). Higher is better."""
    t = np.asarray(truth, np.float64)[mask]
    v = np.asarray(values, np.float64)[mask]
    s = (t * v).sum(axis=0) / np.maximum((v * v).sum(axis=0), 1e-300)
    mse = float(np.mean((s * v - t) ** 2))
    return 10.0 * math.log10(max(float(t.max()), 1e-300) ** 2 / max(mse, 1e-300))


def bsdf_values(bsdf, samples) -> np.ndarray:
    """(N, 3) BRDF values (1/sr) of any Mitsuba BSDF at the angles of MERL
    :class:`~mi_dsbrdf.model.samples.Samples` (eval / cos theta_o): scores baselines on
    the same grid as the DSBRDF."""
    wi, wo = from_half_diff(samples.theta_h, samples.theta_d, samples.phi_d)
    n = samples.theta_h.shape[0]
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*(np.asarray(c, np.float32) for c in wi))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.n = mi.Normal3f(0, 0, 1)
    v = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*(np.asarray(c, np.float32) for c in wo)))
    return np.array(v, dtype=np.float64).T.reshape(n, 3) / np.asarray(wo[2], np.float64)[:, None]


def band_scores(material, samples, where, scale, level=0.9, n=128, seed=0) -> dict:
    """The posterior band of a recovered ``material`` (with a covariance,
    :meth:`~mi_dsbrdf.brdf.dsbrdf.Material.band`) against measured ``samples``.

    Per (theta_h, theta_d) cell of the samples (the DSBRDF has no phi_d): the
    truth is the median over the cell's samples of values / ``scale`` (Eq. 20's
    best scale of the material, s model ~ truth); ``where`` (N,) bool marks the
    samples the image saw (a cell is observed if any of its samples is).

    Returns {"coverage_observed", "coverage_unobserved"}: the share of (cell,
    channel) whose truth lies inside the ``level`` band; {"width_observed",
    "width_unobserved"}: the band's median width in log(rho + 1e-6) (the paper's
    convention); NaN where there are no such cells."""
    th, td = np.asarray(samples.theta_h), np.asarray(samples.theta_d)
    cells, index = np.unique(np.stack([th, td], axis=1), axis=0, return_inverse=True)
    index = index.reshape(-1)
    order = np.argsort(index, kind="stable")
    starts = np.searchsorted(index[order], np.arange(cells.shape[0]))
    values = np.asarray(samples.values, dtype=np.float64)[order] / scale
    truth = np.stack([np.median(v, axis=0) for v in np.split(values, starts[1:])])
    seen = np.zeros(cells.shape[0], bool)
    np.logical_or.at(seen, index, np.asarray(where, bool).reshape(-1))
    lo, hi = material.band(cells[:, 0], cells[:, 1], level, n, seed)
    inside = (truth >= lo) & (truth <= hi)
    width = np.log(np.maximum(hi, 0) + PAPER_FLOOR) - np.log(np.maximum(lo, 0) + PAPER_FLOOR)
    out = {}
    for part, cell in (("observed", seen), ("unobserved", ~seen)):
        out["coverage_" + part] = float(inside[cell].mean()) if cell.any() else float("nan")
        out["width_" + part] = float(np.median(width[cell])) if cell.any() else float("nan")
    return out


def map_coverage(recovered, truth, seen, spread, level) -> float:
    """The share of seen texel channels whose truth (H, W, 3) lies within the
    normal ``level`` band of the recovered map's log, +- z ``spread`` (H, W, 3),
    after the best log scale (the mean log ratio over the seen texels)."""
    from scipy.stats import norm
    r = np.log(np.maximum(truth[seen], 1e-30)) - np.log(np.maximum(recovered[seen], 1e-30))
    return float(np.mean(np.abs(r - r.mean()) <= norm.ppf(0.5 + level / 2) * spread[seen]))


def posterior_scores(material, laplace, samples, where, scale, temperatures, level, map_spread=None) -> dict:
    """{"%g" % t: :func:`band_scores` of ``material`` with the covariance
    ``laplace.factor(t)``, and its ``no_highlight`` probability
    (:meth:`~mi_dsbrdf.brdf.dsbrdf.Material.no_highlight_probability`)} for each
    temperature t; with ``map_spread`` =
    (recovered map, truth map, seen texels, spread, the spread's temperature), each
    also holds ``map_coverage`` (:func:`map_coverage` of the spread scaled to t: a
    standard deviation grows as the square root of the temperature)."""
    out = {}
    for t in temperatures:
        tempered = material.with_covariance(laplace.factor(t))
        out["%g" % t] = band_scores(tempered, samples, where, scale, level)
        out["%g" % t]["no_highlight"] = tempered.no_highlight_probability()
        if map_spread is not None:
            recovered, truth, seen, spread, t_spread = map_spread
            out["%g" % t]["map_coverage"] = map_coverage(recovered, truth, seen, spread * math.sqrt(t / t_spread),
                                                         level)
    return out


def mode_scores(other, gap, values, samples) -> dict:
    """How the posterior's other mode (``other``, a Material with negative log
    posterior ``gap`` above the answer's) differs from the answer (its BRDF
    ``values`` (N, 3) at ``samples``) and how it scores against the truth:
    {"gap", "highlight_ratio", "distance_<c>": Eq. 20 between the two materials,
    "brdf_eq20_<c>": Eq. 20 of the other mode against the truth}, c each convention."""
    ov = other.eval(samples.theta_h, samples.theta_d)
    out = {"gap": float(gap), "highlight_ratio": highlight_ratio(ov, samples.theta_h, samples.theta_d)}
    for c in CONVENTIONS:
        out["distance_" + c] = log_rmse_scale_invariant(ov, values, samples.cos_i, c)[0]
        out["brdf_eq20_" + c] = log_rmse_scale_invariant(ov, samples.values, samples.cos_i, c)[0]
    return out


def observed_samples(view, light, keep, samples) -> np.ndarray:
    """(N,) bool: the ``samples`` whose (theta_h, theta_d) the ``keep`` pixels of
    ``view`` look at under the true ``light`` (T, 3) (where the image shows the
    material, :func:`~mi_dsbrdf.inference.lobes.observed_directions`)."""
    rows = np.nonzero(np.asarray(keep).reshape(-1)[view.pixels])[0]
    return observed_directions(view, light, rows)(samples.theta_h, samples.theta_d) > 0


def observed_split(values, samples, where) -> dict:
    """Eq. 20 (both conventions) of ``values`` on the observed samples (``where``)
    and on the rest, and the observed share of the samples."""
    return {"observed_fraction": float(where.mean()),
            **{"brdf_eq20_%s_%s" % (part, c): e
               for part, errors in split_errors(values, samples, where).items() for c, e in errors.items()}}
