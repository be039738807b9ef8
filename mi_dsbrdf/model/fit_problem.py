"""The least-squares problem of a DSBRDF fit (paper §3.1-3.2): what a fit
minimises and how.

* :class:`FitObjective` (:data:`OBJECTIVE`, the shipped model's) — Eq. 5 in the
  paper's convention, log(f + 1e-6), plus a weighted cosine-weighted term
  log(0.01 + f cos theta_i), over measured samples of the MERL grid;
* :class:`FitProblem` — its residuals and analytic Jacobian for log kappa / log
  gamma control values ``ctrl = A p + b`` and per-lobe chromaticity variables;
* :func:`solve` — Levenberg-Marquardt (:func:`mi_dsbrdf.lm.levenberg_marquardt`)
  on it with box bounds and a curvature penalty;
* :func:`control_bounds` — the box of the control values (:data:`LOG_KAPPA_BOUNDS`,
  :data:`LOG_GAMMA_BOUNDS`).

The fits themselves (full, basis, constant curves) are in
:mod:`mi_dsbrdf.model.fitting`.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from mi_dsbrdf.brdf.angles import log_cos_h
from mi_dsbrdf.brdf.chromaticity import softmax_chroma, softmax_jacobian
from mi_dsbrdf.brdf.curves import DEFAULT_KNOTS, N_CONTROL, spline_matrix
from mi_dsbrdf.brdf.dsbrdf import LOG_GAMMA_MAX, LOG_KAPPA_MAX, clamp_controls
from mi_dsbrdf.lm import levenberg_marquardt
from mi_dsbrdf.model.samples import Samples

N_LOBES = 3
#: Bounds of fitted log kappa / log gamma control values. gamma >= 0.2 keeps the
#: two sharper lobes lobes (gamma -> 0 is a constant, Lambertian term; the broad
#: lobe may go there, see :attr:`FitObjective.broad_gamma_min`); kappa >= e^-9
#: lets an unneeded lobe fade out without an unbounded log.
LOG_KAPPA_BOUNDS = (-9.0, LOG_KAPPA_MAX)
LOG_GAMMA_BOUNDS = (math.log(0.2), LOG_GAMMA_MAX - 1.0)


# --- what a fit minimises -------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class FitObjective:
    """What a fit minimises: a weighted sum of squared log errors in the two
    conventions of :mod:`mi_dsbrdf.evaluation.metrics`, each with its own floor::

        paper_weight^2  mean[log(paper_floor + f) - log(paper_floor + rho)]^2
      + cosine_weight^2 mean[log(cosine_offset + f cos) - log(cosine_offset + rho cos)]^2

    The paper term keeps the dark half of a BRDF (the off-peak floor of metals, the
    grazing diffuse); the cosine term keeps the peak and the diffuse colour where
    the picture is bright. A weight of 0 drops its term.
    """
    paper_weight: float = 1.0
    paper_floor: float = 1e-6
    cosine_weight: float = 3.0
    cosine_offset: float = 0.01
    #: Lower bound of the broadest lobe's gamma: small enough, the lobe can be a
    #: flat (Lambertian) floor, exp(kappa) - 1, where the other lobes keep
    #: gamma >= LOG_GAMMA_BOUNDS[0] and stay lobes.
    broad_gamma_min: float = 1e-4

    def terms(self):
        """(weight, floor, cosine-weighted) of each active term."""
        t = [(self.paper_weight, self.paper_floor, False), (self.cosine_weight, self.cosine_offset, True)]
        return [x for x in t if x[0] > 0]

    def logs(self, values, cos_i) -> np.ndarray:
        """(T, N, 3) weighted logs of (N, 3) BRDF values (1/sr), one slice per
        active term, scaled so that the sum of squared differences of two
        ``logs`` is the objective (weight^2 x mean squared log error, summed)."""
        v = np.maximum(np.asarray(values, dtype=np.float64), 0.0)
        scale = 1.0 / math.sqrt(v.size)
        return np.stack([w * scale * np.log(floor + v * (np.asarray(cos_i)[:, None] if cosine else 1.0))
                         for w, floor, cosine in self.terms()])


#: The objective of the shipped model's fits: the paper's convention with its own
#: floor, the cosine term weighted 3x (it keeps the peak and the diffuse colour at
#: little cost to the paper convention), a broad lobe free to be flat.
OBJECTIVE = FitObjective()


# --- its residuals, Jacobian and solver -------------------------------------------------

class FitProblem:
    """Residuals and Jacobian of the fit error (:class:`FitObjective`) for control
    values ctrl = A p + b (:func:`solve` supplies A and b).

    Parameters
    ----------
    samples : Samples
        N measured samples of the MERL grid (angles in radians, values in 1/sr).
    n_lobes : int
        R, the lobes of the DSBRDF.
    knots : the B-spline knots of the κ/γ curves over theta_d.
    objective : FitObjective
        What the residuals measure; the sum of their squares is the objective.
    """

    def __init__(self, samples: Samples, n_lobes, knots=DEFAULT_KNOTS, objective: FitObjective = OBJECTIVE):
        self.B = spline_matrix(samples.theta_d, knots)                      # (N, 6)
        self.lch = log_cos_h(np.cos(samples.theta_h), np.sin(samples.theta_h) ** 2)
        terms = objective.terms()
        if not terms:
            raise ValueError("a fit objective needs a term of positive weight")
        n = samples.cos_i.shape[0]
        self.objective = objective
        self.cos_i = samples.cos_i
        # per term: weight / sqrt(3N) (residuals -> RMSE), floor, weight of f (cos theta_i or 1)
        self.w = np.array([t[0] for t in terms]) / math.sqrt(3 * n)                      # (T,)
        self.floor = np.array([t[1] for t in terms])                                       # (T,)
        self.c = np.stack([samples.cos_i if t[2] else np.ones(n) for t in terms])[:, :, None]  # (T, N, 1)
        self.y = objective.logs(samples.values, samples.cos_i)                              # (T, N, 3)
        self.R = n_lobes
        self.knots = knots

    def lobes(self, ctrl):
        """(N, R) lobe values L_r and their derivatives by the log kappa and
        log gamma control values (clamped as in :func:`~mi_dsbrdf.brdf.dsbrdf.clamp_controls`;
        zero derivative where a clamp is active): (L, dL_da (N, R, 6), dL_dg (N, R, 6))."""
        lk, lg = clamp_controls(ctrl[:, 0], ctrl[:, 1])
        free_k = (ctrl[:, 0] == lk).astype(np.float64)          # (R, 6)
        free_g = (ctrl[:, 1] == lg).astype(np.float64)
        gamma = np.exp(self.B @ lg.T)                           # (N, R)
        u = np.exp(self.B @ lk.T + gamma * self.lch[:, None])   # kappa cos^gamma theta_h
        L = np.expm1(u)
        dL_a = (L + 1.0) * u
        dL_g = dL_a * gamma * self.lch[:, None]
        BB = self.B[:, None, :]
        return L, dL_a[:, :, None] * BB * free_k[None], dL_g[:, :, None] * BB * free_g[None]

    def residuals(self, ctrl, logits, jac=False):
        """Residuals (T*3N,) and, with ``jac``, their Jacobians (T*3N, R*2*6) with
        respect to the control values and (T*3N, R*2) to the chromaticity variables."""
        L, dL_da, dL_dg = self.lobes(ctrl)
        C = softmax_chroma(logits)                             # (R, 3)
        rho = L @ C                                            # (N, 3)
        res = self.objective.logs(rho, self.cos_i) - self.y
        if not jac:
            return res.reshape(-1), None, None
        fc = self.floor[:, None, None] + np.maximum(rho, 0.0)[None] * self.c   # (T, N, 3)
        w = self.c / fc * self.w[:, None, None]                # d res / d rho, (T, N, 3)
        T = w.shape[0]
        N, R = L.shape
        # d rho_l / d ctrl[r, curve, j] = C[r, l] dL_r/d(curve) B_j
        F = np.stack([dL_da, dL_dg], axis=2).reshape(N, R, -1)              # (N, R, 2*6)
        dC = softmax_jacobian(C)                                            # (R, 3, 2)
        J_ctrl = np.empty((T, N, 3, R, 2 * N_CONTROL))
        J_z = np.empty((T, N, 3, R, 2))
        for t in range(T):
            for c in range(3):
                coef = w[t, :, c:c + 1] * C[None, :, c]                     # (N, R)
                J_ctrl[t, :, c] = coef[:, :, None] * F
                J_z[t, :, c] = (w[t, :, c:c + 1] * L)[:, :, None] * dC[None, :, c, :]
        return res.reshape(-1), J_ctrl.reshape(T * N * 3, -1), J_z.reshape(T * N * 3, -1)


def second_differences(n_curves):
    """(n_curves * 4, n_curves * 6) operator of second differences of control values."""
    d2 = np.diff(np.eye(N_CONTROL), n=2, axis=0)
    return np.kron(np.eye(n_curves), d2)


def solve(problem, A, b, p0, z0, lower=None, upper=None, smoothness=0.0, max_iter=100):
    """Fit ctrl = A p + b and chromaticity variables z from (p0, z0); ``smoothness``
    weighs second differences of the control values (extra residuals, linear in p).

    Parameters
    ----------
    problem : FitProblem
    A : (R*2*6, P) float64, b : (R*2*6,) float64
        The control values' affine map of the P free variables p.
    p0 : (P,) float64, z0 : (R, 2) float64
        The start: free variables and chromaticity logits.
    lower, upper : (P,) float64 or None
        Box bounds of p.

    Returns
    -------
    ctrl : (R, 2, 6), chroma : (R, 3), x : (P + 2R,) the solution, cost (half the
    squared residual norm), iterations.
    """
    R = problem.R
    P = A.shape[1]
    identity = A.shape[0] == P and np.array_equal(A, np.eye(P))
    D2 = second_differences(2 * R) * smoothness
    D = D2 @ A if smoothness else None
    Db = D2 @ b if smoothness else None

    def unpack(x):
        return (A @ x[:P] + b).reshape(R, 2, N_CONTROL), x[P:].reshape(R, 2)

    def fun(x, jac):
        ctrl, z = unpack(x)
        r, Jc, Jz = problem.residuals(ctrl, z, jac=jac)
        if D is not None:
            r = np.concatenate([r, D @ x[:P] + Db])
        if not jac:
            return r, None
        J = np.zeros((r.size, P + 2 * R))
        n = Jc.shape[0]
        J[:n, :P] = Jc if identity else Jc @ A
        J[:n, P:] = Jz
        if D is not None:
            J[n:, :P] = D
        return r, J

    x0 = np.concatenate([p0, np.asarray(z0, dtype=np.float64).reshape(-1)])
    zb = np.full(2 * R, 30.0)
    lo = np.concatenate([np.full(P, -np.inf) if lower is None else lower, -zb])
    hi = np.concatenate([np.full(P, np.inf) if upper is None else upper, zb])
    res = levenberg_marquardt(lambda x: normal_equations(fun(x, True)), lambda x: 0.5 * squared_norm(fun(x, False)[0]),
                              np.clip(x0, lo, hi), propose=lambda x, step: np.clip(x + step, lo, hi),
                              max_iter=max_iter)
    ctrl, z = unpack(res.x)
    return ctrl, softmax_chroma(z), res.x, res.cost, res.iterations


def normal_equations(rJ):
    """(g, H) = (J^T r, J^T J): gradient and Gauss-Newton Hessian of |r|^2 / 2."""
    r, J = rJ
    return J.T @ r, J.T @ J


def squared_norm(r) -> float:
    """|r|^2 of a residual vector."""
    return float(r @ r)


def control_bounds(n, objective):
    """Lower and upper bounds of (N_LOBES, 2, n) log-curve variables, flattened
    (lobe 0, the broadest start, down to ``objective.broad_gamma_min``)."""
    lo = np.empty((N_LOBES, 2, n))
    hi = np.empty((N_LOBES, 2, n))
    lo[:, 0], hi[:, 0] = LOG_KAPPA_BOUNDS
    lo[:, 1], hi[:, 1] = LOG_GAMMA_BOUNDS
    lo[0, 1] = min(LOG_GAMMA_BOUNDS[0], math.log(objective.broad_gamma_min))
    return lo.reshape(-1), hi.reshape(-1)
