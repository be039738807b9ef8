"""Where an image looks in a material's domain: the (theta_h, theta_d) cells its
pixel x light pairs saw, each weighted by the light it carried.

A recovered material is constrained by the image only at the (theta_h, theta_d)
its used pixels and the light's directions form; elsewhere it is the model's
prior (paper §3, Eq. 6-12). :class:`DirectionWeights` records those cells, so
that a user (and the reports, which score Eq. 20 on them beside the whole
domain) can tell what the image measured from what the model filled in.

Cells: theta_h in [0, pi/2] on a square-root grid (cell i spans
pi/2 (i/N)^2 .. pi/2 ((i+1)/N)^2, fine near the highlight like MERL's grid),
theta_d uniform in [0, pi/2].
"""
from __future__ import annotations

import math

import numpy as np

from mi_dsbrdf.errors import MaterialError

#: cells along theta_h and theta_d
N_CELLS = 45


def cell_indices(theta_h, theta_d, n=N_CELLS) -> tuple:
    """(i, j) int arrays: the cell of each (theta_h, theta_d) in radians (clipped
    to the domain)."""
    th = np.clip(np.asarray(theta_h, dtype=np.float64), 0.0, math.pi / 2)
    td = np.clip(np.asarray(theta_d, dtype=np.float64), 0.0, math.pi / 2)
    i = np.minimum((np.sqrt(th / (math.pi / 2)) * n).astype(np.int64), n - 1)
    j = np.minimum((td / (math.pi / 2) * n).astype(np.int64), n - 1)
    return i, j


def cell_sums(theta_h, theta_d, weight, n=N_CELLS) -> np.ndarray:
    """(n, n) float64: the sum of the pairs' ``weight`` (clipped at 0) in each
    (theta_h, theta_d) cell; angles in radians, all three of one shape. Sums of
    several batches of pairs add up."""
    i, j = cell_indices(np.ravel(theta_h), np.ravel(theta_d), n)
    w = np.maximum(np.ravel(np.asarray(weight, dtype=np.float64)), 0.0)
    return np.bincount(i * n + j, weights=w, minlength=n * n).reshape(n, n)


class DirectionWeights:
    """The share of an image's light-weighted pixel x light pairs in each
    (theta_h, theta_d) cell (module doc).

    Parameters
    ----------
    weights : (N, N) array_like, >= 0: rows theta_h cells, columns theta_d
        cells; normalised to sum to one (all zero: nothing seen)
    """

    def __init__(self, weights):
        w = np.asarray(weights, dtype=np.float64)
        if w.ndim != 2 or w.shape[0] != w.shape[1] or w.shape[0] < 1:
            raise MaterialError("observed weights must be a square (N, N) table, got shape %s" % (w.shape,))
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise MaterialError("observed weights must be finite and >= 0")
        total = w.sum()
        self.weights = w / total if total > 0 else w

    @classmethod
    def from_pairs(cls, theta_h, theta_d, weight, n=N_CELLS) -> "DirectionWeights":
        """From pairs' angles (radians) and their weights (any shape, the same)."""
        return cls(cell_sums(theta_h, theta_d, weight, n))

    def __call__(self, theta_h, theta_d) -> np.ndarray:
        """The weight of each (theta_h, theta_d)'s cell (the shape of the angles)."""
        i, j = cell_indices(theta_h, theta_d, self.weights.shape[0])
        return self.weights[i, j]

    def to_dict(self) -> dict:
        return {"cells": self.weights.shape[0], "theta_h": "sqrt", "weights": np.round(self.weights, 8).tolist()}

    @classmethod
    def from_dict(cls, d) -> "DirectionWeights":
        if not isinstance(d, dict) or "weights" not in d:
            raise MaterialError("\"observed\" must be an object with \"weights\"")
        return cls(d["weights"])
