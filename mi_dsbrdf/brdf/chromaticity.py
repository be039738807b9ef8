"""Lobe chromaticity as free variables: c_r = softmax(z_r0, z_r1, 0).

A chromaticity is non-negative and sums to one; the softmax of two free
variables and a fixed zero covers it with no constraint, which fitting and
inference both optimise over. float64 numpy throughout.
"""
from __future__ import annotations

import numpy as np


def softmax_chroma(logits) -> np.ndarray:
    """(R, 3) chromaticities from (R, 2) free variables: softmax of (z0, z1, 0)."""
    z = np.concatenate([np.asarray(logits, dtype=np.float64).reshape(-1, 2), np.zeros((len(logits), 1))], axis=1)
    z = z - z.max(axis=1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=1, keepdims=True)


def chroma_logits(chromaticity, floor=1e-6) -> np.ndarray:
    """Inverse of :func:`softmax_chroma` (chromaticities floored at ``floor``)."""
    c = np.maximum(np.asarray(chromaticity, dtype=np.float64), floor)
    return np.log(c[:, :2]) - np.log(c[:, 2:3])


def softmax_jacobian(chromaticity) -> np.ndarray:
    """(R, 3, 2) d c[r, l] / d z[r, k] = c[r, l] (delta_lk - c[r, k]) of the
    chromaticities ``chromaticity`` (R, 3) = :func:`softmax_chroma` (z)."""
    c = np.asarray(chromaticity, dtype=np.float64)
    return c[:, :, None] * (np.eye(3)[None, :, :2] - c[:, None, :2])
