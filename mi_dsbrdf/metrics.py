"""Error measures of the paper, as functions over arrays.

* :func:`log_rmse` — Eq. 5, the log-space BRDF error used both to fit
  reflectance models to measurements and to report how well they fit.
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
