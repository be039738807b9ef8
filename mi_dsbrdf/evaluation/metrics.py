"""Error measures of the paper, as functions over arrays.

* :func:`log_rmse` — Eq. 5, the log-space BRDF error used both to fit
  reflectance models to measurements and to report how well they fit;
* :func:`log_rmse_scale_invariant` — Eq. 20, the same after the best overall
  scale of the model: what one image under unknown light can determine;
* :func:`scale_invariant_log_error` — Eq. 20's measure on images and
  illumination maps; :func:`direction_error_deg` for a recovered light;
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


def log_brdf(values, cos_i) -> np.ndarray:
    """log(1 + rho cos theta_i), the quantity Eq. 5 compares.

    ``values``: (N, 3) BRDF values in 1/sr; ``cos_i``: (N,) cosine of the
    incident angle of each sample. The cosine weighting makes the error measure
    what a picture shows (radiance), and the log compresses the specular peak
    so that the diffuse part and the highlight both count.
    """
    v = np.asarray(values, dtype=np.float64)
    c = np.asarray(cos_i, dtype=np.float64).reshape(-1, 1)
    return np.log1p(np.maximum(v, 0.0) * c)


def log_rmse(model_values, measured_values, cos_i) -> float:
    """Eq. 5: sqrt(mean over samples and channels of
    [log(1 + rho_model cos theta_i) - log(1 + rho_measured cos theta_i)]^2).

    ``model_values``, ``measured_values``: (N, 3) float arrays in 1/sr over the
    same N measured samples; ``cos_i``: (N,). Returns a float (dimensionless).
    """
    a = log_brdf(model_values, cos_i)
    b = log_brdf(measured_values, cos_i)
    if a.shape != b.shape:
        raise ValueError("model and measured values differ in shape: %s vs %s" % (a.shape, b.shape))
    return float(np.sqrt(np.mean((a - b) ** 2)))


def log_rmse_scale_invariant(model_values, measured_values, cos_i) -> tuple:
    """Eq. 20: min over s > 0 of Eq. 5 between s * model and the measurement.

    Under illumination of unknown strength only light x reflectance is
    observable, so a recovered BRDF is scored up to one overall scale.
    Returns (error, s). The minimum is found by Brent's bounded search on log s
    (Eq. 5 of a scaled model is unimodal in log s in practice; s in 1e-6..1e6).
    """
    m = np.asarray(model_values, dtype=np.float64)
    res = minimize_scalar(lambda log_s: log_rmse(m * np.exp(log_s), measured_values, cos_i), method="bounded",
                          bounds=(math.log(1e-6), math.log(1e6)), options={"xatol": 1e-6})
    return float(res.fun), float(np.exp(res.x))


def material_error(material, samples, scale_invariant=True) -> float:
    """Eq. 20 (or Eq. 5) of a material (anything with ``.eval(theta_h, theta_d)``,
    e.g. :class:`~mi_dsbrdf.brdf.dsbrdf.Material`) against measured
    :class:`~mi_dsbrdf.model.samples.Samples`."""
    values = material.eval(samples.theta_h, samples.theta_d)
    if scale_invariant:
        return log_rmse_scale_invariant(values, samples.values, samples.cos_i)[0]
    return log_rmse(values, samples.values, samples.cos_i)


def direction_error_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    c = float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def scale_invariant_log_error(values, truth, mask) -> float:
    """Eq. 20's measure on images or illumination maps: the RMSE of
    log(1 + s v / m) - log(1 + t / m) over ``mask`` (H, W), m the truth's mean
    there, at the best scale s of ``values`` (light and material trade scale)."""
    t = np.asarray(truth, np.float64)[mask]
    ref = max(float(t.mean()), 1e-300)
    return log_rmse_scale_invariant(np.asarray(values, np.float64)[mask] / ref, t / ref, np.ones(t.shape[0]))[0]


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
