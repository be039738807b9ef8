"""Functional PCA of log kappa / log gamma curves (paper Eq. 2-3).

Each material contributes the 2R log curves of its lobes as functions of
theta_d on [0, pi/2]. Functional PCA finds the mean function b_mu and the
basis functions b_i that are orthonormal in L2 over theta_d and capture the most
variance. The curves are quadratic B-splines, so each function is its vector of
control values a and the L2 inner product is exact:

    <f, g> = a_f^T G a_g,   G_jl = int_0^{pi/2} B_j(theta) B_l(theta) dtheta

(Gauss-Legendre quadrature, exact for the piecewise-quartic products). With
G = L L^T, the PCA of the rows (a - mean)^T L is the functional PCA, and a
principal direction v maps back to control values as L^{-T} v.
"""
from __future__ import annotations

import dataclasses
import functools

import numpy as np

from mi_dsbrdf.brdf.curves import DEFAULT_KNOTS, N_CONTROL, CurveBasis, check_knots, spline_matrix


def gram_matrix(knots=DEFAULT_KNOTS) -> np.ndarray:
    """(6, 6) float64 Gram matrix of the spline basis functions over [0, pi/2]
    (a new array; computed once per knot vector)."""
    return _gram_matrix(check_knots(knots)).copy()


@functools.lru_cache(maxsize=8)
def _gram_matrix(t: tuple) -> np.ndarray:
    x, w = np.polynomial.legendre.leggauss(4)          # exact to degree 7
    G = np.zeros((N_CONTROL, N_CONTROL))
    for a, b in zip(t, t[1:]):
        if b <= a:
            continue
        xs = 0.5 * (b - a) * x + 0.5 * (a + b)
        # evaluate just inside the interval (the half-open spline intervals)
        Bm = spline_matrix(np.clip(xs, a, np.nextafter(b, a)), t)
        G += Bm.T @ (Bm * (0.5 * (b - a) * w)[:, None])
    return G


@dataclasses.dataclass
class FPCA:
    """Result of functional PCA.

    mean : (R, 2, 6) control values of b_mu
    bases : (K, R, 2, 6) control values of b_1..b_K, L2-orthonormal over theta_d
    variance : (K,) variance of the scores along each basis function
    scores : (M, K) coefficients psi of the training materials
    """
    mean: np.ndarray
    bases: np.ndarray
    variance: np.ndarray
    scores: np.ndarray
    knots: tuple = DEFAULT_KNOTS

    @property
    def explained(self) -> np.ndarray:
        """(K,) cumulative fraction of the total variance explained."""
        total = self.variance.sum()
        return np.cumsum(self.variance) / total if total > 0 else np.ones_like(self.variance)

    def basis(self, k: int) -> CurveBasis:
        """The first ``k`` basis functions as a :class:`CurveBasis`."""
        if not 1 <= k <= self.bases.shape[0]:
            raise ValueError("k must be in 1..%d, got %d" % (self.bases.shape[0], k))
        return CurveBasis(self.mean, self.bases[:k], self.knots)


def fpca(controls, knots=DEFAULT_KNOTS) -> FPCA:
    """Functional PCA of the curves of M materials.

    ``controls``: (M, R, 2, 6) float64 log-curve control values (lobes ordered
    consistently across materials). Returns all min(M - 1, R*2*6) components,
    in order of decreasing variance; basis signs are fixed (largest-magnitude
    control value positive) so that rebuilds are deterministic.
    """
    X = np.asarray(controls, dtype=np.float64)
    if X.ndim != 4 or X.shape[2:] != (2, N_CONTROL):
        raise ValueError("controls must have shape (M, R, 2, %d), got %s" % (N_CONTROL, X.shape))
    M, R = X.shape[:2]
    if M < 2:
        raise ValueError("functional PCA needs at least 2 materials, got %d" % M)
    flat = X.reshape(M, -1)
    mean = flat.mean(axis=0)
    G = gram_matrix(knots)
    Lc = np.linalg.cholesky(G)
    L = np.kron(np.eye(2 * R), Lc)                     # block-diagonal: one block per curve
    Y = (flat - mean) @ L
    _, S, Vt = np.linalg.svd(Y, full_matrices=False)
    K = min(M - 1, flat.shape[1])
    V = Vt[:K].T                                       # (D, K), orthonormal columns
    for i in range(K):
        if V[np.argmax(np.abs(V[:, i])), i] < 0:
            V[:, i] = -V[:, i]
    bases = np.linalg.solve(L.T, V).T                  # control values L^{-T} v
    scores = Y @ V
    variance = S[:K] ** 2 / (M - 1)
    return FPCA(mean.reshape(R, 2, N_CONTROL), bases.reshape(K, R, 2, N_CONTROL), variance, scores,
                tuple(knots))


def l2_inner(a, b, knots=DEFAULT_KNOTS) -> float:
    """Exact L2 inner product over theta_d of two sets of curves given by
    control values of equal shape (..., 6): the sum over all curves."""
    G = gram_matrix(knots)
    a = np.asarray(a, dtype=np.float64).reshape(-1, N_CONTROL)
    b = np.asarray(b, dtype=np.float64).reshape(-1, N_CONTROL)
    return float(np.einsum("ij,jk,ik->", a, G, b))
