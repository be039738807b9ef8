"""Products with a transport T (3, P, T), channel-major (:meth:`TexelSum.transport
<mi_dsbrdf.inference.forward.TexelSum.transport>`): the image of a map, I = T L, and
its adjoint, in float32 BLAS on unit-scaled operands."""
from __future__ import annotations

import numpy as np


def apply_transport(T, illumination) -> np.ndarray:
    """(P, 3) float64 radiance of the map ``illumination`` (T texels x 3) under the
    channel-major transport ``T`` (3, P, T) of :meth:`~mi_dsbrdf.inference.forward.TexelSum.transport`."""
    L, scale = unit_scaled(illumination)
    return np.stack([T[c] @ L[:, c] for c in range(3)], axis=1).astype(np.float64) * scale


def transport_adjoint(T, grad_pixels) -> np.ndarray:
    """(T texels, 3) float64: d loss / d L from d loss / d radiance ``grad_pixels``
    (P, 3), the transpose of :func:`apply_transport`."""
    g, scale = unit_scaled(grad_pixels)
    return np.stack([g[:, c] @ T[c] for c in range(3)], axis=1).astype(np.float64) * scale


def unit_scaled(values) -> tuple:
    """((N, 3) float32 values / s, s) with s the largest |value|: the float32 products
    of a bright sun (1e5) with a sharp lobe's transport (e^60 * solid angle) would
    overflow; scaled to at most 1 they cannot."""
    v = np.asarray(values, dtype=np.float64).reshape(-1, 3)
    s = float(np.abs(v).max()) if v.size else 0.0
    s = s if s > 0 and np.isfinite(s) else 1.0
    return (v / s).astype(np.float32), s
