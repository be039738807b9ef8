"""The negative log posterior of paper §4 (Eq. 18), term by term.

    -log p(R, L | I) = likelihood (Eq. 19) + reflectance priors (Eq. 6, 12)
                       + illumination priors (Eq. 13-16) + const

This module holds the likelihood; the priors are in :mod:`mi_dsbrdf.model.priors`.
Each term is a function returning (value, gradient) in float64, so that the
inference loop adds them to the gradients Dr.Jit returns for the rendering.
"""
from __future__ import annotations

import numpy as np

#: Width s of the smoothed kink of |.| (in log units): |d| ~ sqrt(d^2 + s^2) - s;
#: residuals below s count quadratically.
KINK = 1e-3


def log_likelihood_terms(model, observed, mask, offset, scale=1.0, grad=True, kink=KINK):
    """Eq. 19: a Laplacian likelihood on log pixel values,

        -log p(I | R, L) = sum_{p, c in mask} rho(log(model + e) - log(observed + e)) / scale,
        rho(d) = sqrt(d^2 + s^2) - s   (|d| with a smooth kink of width s = ``kink``),

    ``model``, ``observed``: (H, W, C) float arrays (observed saturated or
    invalid pixels are excluded through ``mask`` (H, W) bool); ``offset``: e,
    in image units (``Config.log_offset`` times the mean observed value).
    Returns (value, d value / d model (H, W, C), or None without ``grad``); both
    finite for zero, negative-rounded or huge model values.
    """
    if not offset > 0:
        raise ValueError("the log offset must be positive, got %r" % (offset,))
    m = np.asarray(model, dtype=np.float64)
    o = np.asarray(observed, dtype=np.float64)
    keep = np.asarray(mask, bool)[..., None]
    mp = np.maximum(m, 0.0) + offset
    d = np.where(keep, np.log(mp) - np.log(np.maximum(o, 0.0) + offset), 0.0)
    r = np.sqrt(d * d + kink * kink)
    value = float((r - kink).sum()) / scale
    if not grad:
        return value, None
    grad = np.where(keep & (m >= 0), d / r / mp, 0.0) / scale
    return value, grad
