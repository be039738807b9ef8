"""Error measures of the paper, as functions over arrays.

* :func:`log_rmse` — Eq. 5, the log-space BRDF error used both to fit
  reflectance models to measurements and to report how well they fit;
* :func:`log_rmse_scale_invariant` — Eq. 20, the same after the best overall
  scale of the model: what one image under unknown light can determine.
"""
from __future__ import annotations

import numpy as np


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
    Returns (error, s). The minimum is found by golden-section search on log s
    (Eq. 5 of a scaled model is unimodal in log s in practice; the bracket
    spans 1e-6..1e6).
    """
    m = np.asarray(model_values, dtype=np.float64)
    lo, hi = np.log(1e-6), np.log(1e6)
    g = (np.sqrt(5) - 1) / 2

    def f(log_s):
        return log_rmse(m * np.exp(log_s), measured_values, cos_i)

    a, b = lo + (1 - g) * (hi - lo), lo + g * (hi - lo)
    fa, fb = f(a), f(b)
    for _ in range(80):
        if fa < fb:
            hi, b, fb = b, a, fa
            a = lo + (1 - g) * (hi - lo)
            fa = f(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + g * (hi - lo)
            fb = f(b)
    log_s = (lo + hi) / 2
    return f(log_s), float(np.exp(log_s))


def material_error(material, samples, scale_invariant=True) -> float:
    """Eq. 20 (or Eq. 5) of a material (anything with ``.eval(theta_h, theta_d)``,
    e.g. :class:`~mi_dsbrdf.brdf.dsbrdf.Material`) against measured
    :class:`~mi_dsbrdf.model.fitting.Samples`."""
    values = material.eval(samples.theta_h, samples.theta_d)
    if scale_invariant:
        return log_rmse_scale_invariant(values, samples.values, samples.cos_i)[0]
    return log_rmse(values, samples.values, samples.cos_i)
