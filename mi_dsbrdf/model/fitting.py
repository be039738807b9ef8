"""Fitting DSBRDF materials to measured BRDFs (paper §3.1-3.2).

A fit minimises :data:`~mi_dsbrdf.model.fit_problem.OBJECTIVE` (a
:class:`~mi_dsbrdf.model.fit_problem.FitObjective`): Eq. 5 in the paper's
convention, log(f + 1e-6), plus a weighted cosine-weighted term log(0.01 + f cos
theta_i), over measured samples of the MERL grid
(:class:`~mi_dsbrdf.model.samples.Samples`), by the least-squares problem of
:mod:`mi_dsbrdf.model.fit_problem` (Levenberg-Marquardt, analytic Jacobian, box
bounds); errors are reported with Eq. 5 in both conventions
(:mod:`mi_dsbrdf.evaluation.metrics`). The κ/γ log-curve control values are an
affine function of the free variables, ``ctrl = A p + b``, which covers the
three models with one code path:

* ``fit_full``: every control value free (3 lobes x 2 curves x 6 = 36, plus
  2 chromaticity variables per lobe = 42 variables), from the best of a few
  constant-curve starts, with a small curvature penalty that keeps curves
  defined where grazing angles leave few samples;
* ``fit_basis``: coefficients ψ of a learned :class:`~mi_dsbrdf.brdf.curves.CurveBasis`
  (k, default 10) plus 2 chromaticity variables per lobe (16 for k = 10);
* ``fit_constant``: one value per curve (the starts of ``fit_full``).

Chromaticity c_r is a softmax of (z_r0, z_r1, 0): non-negative, sums to one,
two free variables per lobe. Lobes are ordered by specularity after fitting:
lobe 0 the broadest (smallest mean log γ), the last lobe the sharpest, so that
curves of different materials are comparable for functional PCA.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from mi_dsbrdf.brdf.chromaticity import chroma_logits
from mi_dsbrdf.brdf.curves import N_CONTROL
from mi_dsbrdf.brdf.dsbrdf import Material, clamp_controls
from mi_dsbrdf.brdf.log_error import material_errors
from mi_dsbrdf.model.fit_problem import (LOG_GAMMA_BOUNDS, N_LOBES, OBJECTIVE, FitObjective, FitProblem,
                                         control_bounds, solve)
from mi_dsbrdf.model.samples import Samples

#: Weight of the curvature penalty (second differences of control values).
SMOOTHNESS = 0.02
#: Constant-curve starts (gamma per lobe, kappa as fractions of the peak's log).
STARTS = (((1.0, 60.0, 4000.0), (0.3, 0.8)),
          ((2.0, 25.0, 800.0), (0.5, 0.5)),
          ((0.5, 8.0, 200.0), (0.4, 0.7)))


@dataclasses.dataclass
class Fit:
    """Result of a fit: the material, its Eq. 5 errors on the samples in the paper's
    convention (``error``) and the cosine-weighted one (``error_cosine``), diagnostics."""
    material: Material
    error: float
    error_cosine: float
    iterations: int
    at_bounds: list       # lobes whose curves touch a bound ("lobe 2 gamma max", ...)
    variables: np.ndarray  # psi of a basis fit; (R, 2, 6) control values of a full fit


def order_lobes(ctrl, chroma):
    """Sort lobes by specularity (mean log gamma control value, ascending)."""
    order = np.argsort(ctrl[:, 1].mean(axis=1), kind="stable")
    return ctrl[order], chroma[order]


def _result(samples, ctrl, chroma, iters, name, knots, psi=None) -> Fit:
    if psi is None:
        ctrl, chroma = order_lobes(ctrl, chroma)
    ctrl = np.stack(clamp_controls(ctrl[:, 0], ctrl[:, 1]), axis=1)
    mat = Material(ctrl[:, 0], ctrl[:, 1], chroma, knots=knots, name=name, psi=psi)
    flags = []
    for r in range(ctrl.shape[0]):
        if ctrl[r, 1].max() >= LOG_GAMMA_BOUNDS[1] - 1e-3:
            flags.append("lobe %d gamma at max" % r)
        if r > 0 and ctrl[r, 1].min() <= LOG_GAMMA_BOUNDS[0] + 1e-3:
            flags.append("lobe %d gamma at min" % r)
    err = material_errors(mat, samples, scale_invariant=False)
    return Fit(mat, err["paper"], err["cosine"], iters, flags, ctrl.copy() if psi is None else psi)


def _initial_chroma(samples):
    """Grey lobes, the broadest one with the colour of the data's diffuse floor."""
    far = samples.theta_h > math.radians(30)
    col = samples.values[far].mean(axis=0) if np.any(far) else samples.values.mean(axis=0)
    c = np.full((N_LOBES, 3), 1 / 3)
    if np.all(col > 0):
        c[0] = col / col.sum()
    return chroma_logits(c)


def fit_constant(samples: Samples, gamma, kappa, z0, max_iter=25, objective: FitObjective = OBJECTIVE):
    """Constant curves (one log kappa, one log gamma per lobe) fitted from a start.

    Returns (ctrl (R, 2, 6), chromaticity (R, 3), cost)."""
    problem = FitProblem(samples, N_LOBES, objective=objective)
    A = np.kron(np.eye(2 * N_LOBES), np.ones((N_CONTROL, 1)))   # (36, 6): one value per curve
    p0 = np.stack([np.log(kappa), np.log(gamma)], axis=1).reshape(-1)
    lo, hi = control_bounds(1, objective)
    ctrl, chroma, _, cost, _ = solve(problem, A, np.zeros(A.shape[0]), p0, z0, lo, hi, max_iter=max_iter)
    return ctrl, chroma, cost


def fit_full(samples: Samples, name=None, smoothness=SMOOTHNESS, max_iter=80,
             objective: FitObjective = OBJECTIVE) -> Fit:
    """The colour-separated 3-lobe B-spline DSBRDF (42 variables) minimising the fit error,
    from the best of the constant-curve starts :data:`STARTS`."""
    problem = FitProblem(samples, N_LOBES, objective=objective)
    lum = samples.values.mean(axis=1)
    peak = float(np.max(lum))
    far = samples.theta_h > math.radians(30)
    floor = float(np.median(lum[far])) if np.any(far) else 1e-3
    K = max(math.log1p(max(peak, 1e-6)), 1e-3)
    z0 = _initial_chroma(samples)
    best = None
    for gammas, (f1, f2) in STARTS:
        kappa = np.clip([math.log1p(max(floor, 1e-6)), f1 * K, f2 * K], 1e-3, 80.0)
        ctrl, chroma, cost = fit_constant(samples, np.array(gammas), kappa, z0, objective=objective)
        if best is None or cost < best[2]:
            best = (ctrl, chroma, cost)
    ctrl0, chroma0, _ = best
    lo, hi = control_bounds(N_CONTROL, objective)
    n = 2 * N_LOBES * N_CONTROL
    ctrl, chroma, _, _, iters = solve(problem, np.eye(n), np.zeros(n), ctrl0.reshape(-1), chroma_logits(chroma0),
                                       lo, hi, smoothness=smoothness, max_iter=max_iter)
    return _result(samples, ctrl, chroma, iters, name or samples.name, problem.knots)


def fit_basis(samples: Samples, basis, psi0=None, chroma0=None, name=None, max_iter=100,
              objective: FitObjective = OBJECTIVE) -> Fit:
    """The colour-separated basis model: k coefficients psi + 2 chromaticity
    variables per lobe, minimising the fit error (starting at psi0, default 0)."""
    problem = FitProblem(samples, basis.n_lobes, basis.knots, objective)
    A = basis.bases.reshape(basis.n_bases, -1).T
    psi0 = np.zeros(basis.n_bases) if psi0 is None else np.asarray(psi0, dtype=np.float64)
    z0 = _initial_chroma(samples) if chroma0 is None else chroma_logits(chroma0)
    ctrl, chroma, x, _, iters = solve(problem, A, basis.mean.reshape(-1), psi0, z0, max_iter=max_iter)
    psi = x[:basis.n_bases]
    return _result(samples, ctrl, chroma, iters, name or samples.name, basis.knots, psi=psi)
