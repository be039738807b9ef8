"""Measured BRDF samples on the MERL grid: what fits and BRDF errors are computed over.

:func:`grid_subset` picks the grid cells (every theta_h, a subset of theta_d
and phi_d, both directions above the horizon); :class:`Samples` holds their
angles, cos theta_i and RGB values (1/sr), from a measured table
(:func:`samples_from_table`) or any BRDF function (:func:`samples_from_function`).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from mi_dsbrdf.brdf.angles import from_half_diff
from mi_dsbrdf.brdf.measured import N_PHI_D, N_THETA_D, N_THETA_H, grid_angles
from mi_dsbrdf.errors import MeasuredFileError


@dataclasses.dataclass(frozen=True)
class Samples:
    """Measured BRDF samples on the MERL grid, all directions above the horizon.

    theta_h, theta_d, phi_d, cos_i : (N,) float64 (radians; cos theta_i > 0)
    values : (N, 3) float64 BRDF values in 1/sr
    """
    theta_h: np.ndarray
    theta_d: np.ndarray
    phi_d: np.ndarray
    cos_i: np.ndarray
    values: np.ndarray
    name: str = None

    def __len__(self):
        return self.theta_h.shape[0]


#: fewest measured samples a material is fitted to (a 3-lobe fit has 39 unknowns)
MIN_SAMPLES = 200


def grid_subset(theta_d_step=3, phi_d_step=20):
    """Indices (i_h, j_d, k_p) of MERL grid cells used for fitting.

    Every theta_h (the square-root map is dense at the peak), every
    ``theta_d_step``-th theta_d and every ``phi_d_step``-th phi_d, keeping only
    cells whose incident and outgoing directions are both above the horizon
    (cos > 1e-3). Returns three (N,) int64 arrays.
    """
    ih, jd, kp = np.meshgrid(np.arange(N_THETA_H), np.arange(0, N_THETA_D, theta_d_step),
                             np.arange(0, N_PHI_D, phi_d_step), indexing="ij")
    ih, jd, kp = ih.reshape(-1), jd.reshape(-1), kp.reshape(-1)
    th, td, pd = grid_angles()
    wi, wo = from_half_diff(th[ih], td[jd], pd[kp])
    keep = (wi[2] > 1e-3) & (wo[2] > 1e-3)
    return ih[keep], jd[keep], kp[keep]


def samples_from_table(brdf, subset=None) -> Samples:
    """Samples of a :class:`~mi_dsbrdf.brdf.measured.MeasuredBRDF` (unmeasured cells dropped)."""
    ih, jd, kp = grid_subset() if subset is None else subset
    keep = brdf.measured[ih, jd, kp]
    ih, jd, kp = ih[keep], jd[keep], kp[keep]
    if ih.size < MIN_SAMPLES:
        raise MeasuredFileError("%s has %d measured values on the fitting grid; a fit needs at least %d"
                                % (brdf.name or "the measured BRDF", ih.size, MIN_SAMPLES))
    return _samples(ih, jd, kp, brdf.table[ih, jd, kp].astype(np.float64), brdf.name)


def samples_from_function(brdf, subset=None, name=None) -> Samples:
    """Samples of ``brdf(theta_h, theta_d, phi_d) -> (N, 3)`` at the grid cells
    (identical to tabulating it on the MERL grid and reading those cells)."""
    ih, jd, kp = grid_subset() if subset is None else subset
    th, td, pd = grid_angles()
    values = np.asarray(brdf(th[ih], td[jd], pd[kp]), dtype=np.float64)
    return _samples(ih, jd, kp, values, name)


def _samples(ih, jd, kp, values, name) -> Samples:
    th, td, pd = grid_angles()
    wi, _ = from_half_diff(th[ih], td[jd], pd[kp])
    if not np.all(np.isfinite(values)):
        raise MeasuredFileError("measured values of %s are not finite" % (name or "material"))
    return Samples(th[ih], td[jd], pd[kp], np.asarray(wi[2]), np.maximum(values, 0.0), name)


# --- the least-squares problem -----------------------------------------------------

