"""Error measures of the paper, as functions over arrays.

BRDF errors come in two conventions, always named:

* ``"paper"`` — the paper's Eq. 5: the RMS over measured samples and channels of
  log(f + 1e-6) - log(rho + 1e-6), f the model and rho the measurement in 1/sr.
  The floor :data:`PAPER_FLOOR` is the one of the authors' lab's code (iBRDF,
  ``fit_merl.cpp``: ``log(f + 1e-6)``). It weighs every decade of the BRDF
  alike: a metal predicted at 1e-14/sr where it reflects 1e-3/sr costs as much
  as a peak off by a factor of 1000.
* ``"cosine"`` — the graphics-fitting convention (Löw et al. 2012; the neural-BRDF
  loss): log(1 + rho cos theta_i). Nearly linear below 0.1/sr, so it hardly sees
  diffuse and dark errors; it measures what a bright picture shows.

Functions:

* :func:`log_rmse` — Eq. 5 in either convention;
* :func:`log_rmse_scale_invariant` — Eq. 20, the same after the best overall
  scale of the model: what one image under unknown light can determine;
* :func:`material_errors` — of a material against measured samples, both conventions;
* :func:`log_error_by_theta_d` — where in theta_d Eq. 20 (paper) lies;
* :func:`scale_invariant_log_error` — Eq. 20's measure on images and
  illumination maps; :func:`direction_error_deg` for a recovered light;
* :func:`highlight_ratio` — peak over off-peak of a BRDF: whether a
  near-Lambertian material came back with a highlight;
* :func:`bsdf_values` — any Mitsuba BSDF on the MERL grid, to score baselines
  on the same samples as the DSBRDF.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
from scipy.optimize import minimize_scalar

from mi_dsbrdf.brdf.angles import from_half_diff
from mi_dsbrdf.brdf.dsbrdf import highlight_ratio  # noqa: F401 (one of this module's measures)

#: Floor of the paper convention's log, log(f + PAPER_FLOOR) (1/sr).
PAPER_FLOOR = 1e-6
#: The two conventions of BRDF errors, the paper's first.
CONVENTIONS = ("paper", "cosine")


def log_brdf(values, cos_i, convention="paper") -> np.ndarray:
    """The log-BRDF a convention compares: (N, 3) log(rho + 1e-6) (``"paper"``)
    or log(1 + rho cos theta_i) (``"cosine"``).

    ``values``: (N, 3) BRDF values in 1/sr (negative values count as 0);
    ``cos_i``: (N,) cosine of the incident angle of each sample (unused by the
    paper convention).
    """
    v = np.maximum(np.asarray(values, dtype=np.float64), 0.0)
    if convention == "paper":
        return np.log(v + PAPER_FLOOR)
    if convention == "cosine":
        return np.log1p(v * np.asarray(cos_i, dtype=np.float64).reshape(-1, 1))
    raise ValueError("unknown error convention %r (use one of %s)" % (convention, ", ".join(CONVENTIONS)))


def log_rmse(model_values, measured_values, cos_i, convention="paper") -> float:
    """Eq. 5 in a convention (see the module doc): sqrt(mean over samples and
    channels of [log_brdf(model) - log_brdf(measured)]^2).

    ``model_values``, ``measured_values``: (N, 3) float arrays in 1/sr over the
    same N measured samples; ``cos_i``: (N,). Returns a float (dimensionless).
    """
    a = log_brdf(model_values, cos_i, convention)
    b = log_brdf(measured_values, cos_i, convention)
    if a.shape != b.shape:
        raise ValueError("model and measured values differ in shape: %s vs %s" % (a.shape, b.shape))
    return float(np.sqrt(np.mean((a - b) ** 2)))


def log_rmse_scale_invariant(model_values, measured_values, cos_i, convention="paper") -> tuple:
    """Eq. 20: min over s > 0 of Eq. 5 (in ``convention``) between s * model and
    the measurement.

    Under illumination of unknown strength only light x reflectance is
    observable, so a recovered BRDF is scored up to one overall scale.
    Returns (error, s). The minimum is found by Brent's bounded search on log s
    (Eq. 5 of a scaled model is unimodal in log s in practice; s in 1e-6..1e6).
    """
    m = np.asarray(model_values, dtype=np.float64)
    res = minimize_scalar(lambda log_s: log_rmse(m * np.exp(log_s), measured_values, cos_i, convention),
                          method="bounded", bounds=(math.log(1e-6), math.log(1e6)), options={"xatol": 1e-6})
    return float(res.fun), float(np.exp(res.x))


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


def material_errors(material, samples, scale_invariant=True, conventions=CONVENTIONS) -> dict:
    """Eq. 20 (or Eq. 5) of a material (anything with ``.eval(theta_h, theta_d)``,
    e.g. :class:`~mi_dsbrdf.brdf.dsbrdf.Material`) against measured
    :class:`~mi_dsbrdf.model.samples.Samples`: ``{convention: error}``."""
    values = material.eval(samples.theta_h, samples.theta_d)
    if scale_invariant:
        return {c: log_rmse_scale_invariant(values, samples.values, samples.cos_i, c)[0] for c in conventions}
    return {c: log_rmse(values, samples.values, samples.cos_i, c) for c in conventions}


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
