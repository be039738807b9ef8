"""Kappa and gamma curves of theta_d (paper §3.1, Eq. 2-3).

Every lobe r has two positive curves of the difference angle theta_d in
[0, pi/2]: kappa_r(theta_d) (magnitude) and gamma_r(theta_d) (sharpness). They are
represented in log space as quadratic B-splines: degree 2, 9 knots (clamped, 3
interior), hence 6 control values per curve::

    log kappa_r(theta_d) = sum_j B_j(theta_d) a_{r,j}
    log gamma_r(theta_d) = sum_j B_j(theta_d) g_{r,j}

The learned model (Eq. 2-3) writes all log curves of a material as a mean
function plus a linear combination of k basis functions, log f = b_mu + sum_i
psi_i b_i. Since functional PCA of spline curves yields spline curves, the mean
and the bases are themselves control-value arrays, and :class:`CurveBasis` is a
linear map psi -> control values. Both representations therefore evaluate
through the same spline code (numpy float64 reference and Dr.Jit kernels).
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from mi_dsbrdf.brdf.xp import ops

DEGREE = 2
N_CONTROL = 6
THETA_D_MAX = math.pi / 2
#: Default knot vector: clamped, uniform interior knots on [0, pi/2].
DEFAULT_KNOTS = (0.0, 0.0, 0.0, math.pi / 8, math.pi / 4, 3 * math.pi / 8,
                 THETA_D_MAX, THETA_D_MAX, THETA_D_MAX)


def check_knots(knots) -> tuple:
    """Validate a knot vector (9 non-decreasing values, clamped on [0, pi/2])."""
    k = tuple(float(v) for v in knots)
    if len(k) != N_CONTROL + DEGREE + 1:
        raise ValueError("a curve knot vector has %d values, got %d" % (N_CONTROL + DEGREE + 1, len(k)))
    if any(b < a for a, b in zip(k, k[1:])) or not all(math.isfinite(v) for v in k):
        raise ValueError("curve knots must be finite and non-decreasing, got %s" % (k,))
    if k[0] != 0.0 or k[-1] != THETA_D_MAX or k[:3] != (0.0,) * 3 or k[-3:] != (THETA_D_MAX,) * 3:
        raise ValueError("curve knots must be clamped: three at 0 and three at pi/2, got %s" % (k,))
    return k


def spline_basis(theta_d, knots=DEFAULT_KNOTS):
    """The 6 B-spline basis functions B_j(theta_d) (Cox-de Boor, degree 2).

    ``theta_d``: numpy or Dr.Jit array of angles in radians, clamped to [0, pi/2].
    Returns a list of 6 arrays of the same kind; they are >= 0 and sum to 1.
    """
    o = ops(theta_d)
    t = knots
    x = o.clip(theta_d, 0.0, THETA_D_MAX)
    last = max(i for i in range(len(t) - 1) if t[i] < t[i + 1])
    # degree 0: indicators of [t_i, t_{i+1}), the last non-empty interval closed
    b = []
    for i in range(len(t) - 1):
        if t[i] == t[i + 1]:
            b.append(None)
            continue
        inside = (x >= t[i]) & ((x < t[i + 1]) | (i == last))
        b.append(o.select(inside, 1.0, 0.0))
    for p in range(1, DEGREE + 1):
        nb = []
        for i in range(len(t) - 1 - p):
            term = None
            if b[i] is not None and t[i + p] > t[i]:
                term = (x - t[i]) / (t[i + p] - t[i]) * b[i]
            if b[i + 1] is not None and t[i + p + 1] > t[i + 1]:
                right = (t[i + p + 1] - x) / (t[i + p + 1] - t[i + 1]) * b[i + 1]
                term = right if term is None else term + right
            nb.append(term)
        b = nb
    return [bj if bj is not None else o.zeros_like(x) for bj in b]


def spline_matrix(theta_d, knots=DEFAULT_KNOTS) -> np.ndarray:
    """(len(theta_d), 6) float64 matrix of basis values, for fitting and FPCA."""
    th = np.asarray(theta_d, dtype=np.float64)
    return np.stack(spline_basis(th, knots), axis=-1)


def eval_log_curve(basis_values, control):
    """sum_j B_j control_j: ``control`` is a sequence of 6 scalars/arrays."""
    acc = basis_values[0] * control[0]
    for bj, cj in zip(basis_values[1:], control[1:]):
        acc = acc + bj * cj
    return acc


class CurveBasis:
    """Learned curve space (Eq. 2-3): log curves = mean + sum_i psi_i basis_i.

    Parameters
    ----------
    mean : (R, 2, 6) float64 array
        Control values of the mean log kappa (``[:, 0]``) and log gamma
        (``[:, 1]``) curves of R lobes.
    bases : (k, R, 2, 6) float64 array
        Control values of the k basis functions (orthonormal in L2 over theta_d
        when built by functional PCA).
    knots : 9 floats
        The spline knot vector shared by all curves.
    """

    def __init__(self, mean, bases, knots=DEFAULT_KNOTS):
        self.mean = np.asarray(mean, dtype=np.float64)
        self.bases = np.asarray(bases, dtype=np.float64)
        self.knots = check_knots(knots)
        if self.mean.ndim != 3 or self.mean.shape[1:] != (2, N_CONTROL):
            raise ValueError("basis mean must have shape (lobes, 2, %d), got %s" % (N_CONTROL, self.mean.shape))
        if self.bases.ndim != 4 or self.bases.shape[1:] != self.mean.shape:
            raise ValueError("bases must have shape (k, %d, 2, %d), got %s"
                             % (self.mean.shape[0], N_CONTROL, self.bases.shape))
        if not (np.all(np.isfinite(self.mean)) and np.all(np.isfinite(self.bases))):
            raise ValueError("basis mean and bases must be finite")

    @property
    def n_lobes(self) -> int:
        return self.mean.shape[0]

    @property
    def n_bases(self) -> int:
        return self.bases.shape[0]

    def control_values(self, psi) -> np.ndarray:
        """(R, 2, 6) control values for coefficients ``psi`` (length k)."""
        psi = np.asarray(psi, dtype=np.float64).reshape(-1)
        if psi.shape[0] != self.n_bases:
            raise ValueError("this basis has %d coefficients, got %d" % (self.n_bases, psi.shape[0]))
        return self.mean + np.tensordot(psi, self.bases, axes=1)

    def control_values_dr(self, psi):
        """The same map for a Dr.Jit Float ``psi`` (differentiable): a flat
        Float of R*2*6 control values in (lobe, curve, j) order."""
        Float = type(psi)
        flat_mean = self.mean.reshape(-1)
        flat_bases = self.bases.reshape(self.n_bases, -1)
        out = Float(flat_mean)
        for i in range(self.n_bases):
            psi_i = dr.gather(Float, psi, i)
            out = out + psi_i * Float(flat_bases[i])
        return out
