"""One damped Gauss-Newton (Levenberg-Marquardt) core for fits and inference.

Both the model's fits (:mod:`mi_dsbrdf.model.fitting`: least squares on a few
dozen variables) and inference's reflectance block
(:mod:`mi_dsbrdf.inference.reflectance`: a reweighted Laplacian likelihood plus
priors) minimise a cost whose gradient g and Gauss-Newton Hessian H they can
form. A step solves (H + lambda diag(H + floor)) s = -g; it is kept only if the
cost falls (and is finite), otherwise lambda grows and the step is solved again.

Hand-written rather than ``scipy.optimize.least_squares``: the inference cost is
not a sum of squares (IRLS weights, priors added to H and g), and the variables
are few, so a step costs one linearisation and a tiny solve instead of an SVD of
the whole Jacobian. The tests hold it to ``least_squares`` on a MERL fit.
"""
from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Damping:
    """Levenberg-Marquardt damping: lambda starts at ``initial``; a rejected step
    multiplies it by ``increase`` (at most ``tries`` times per iteration), an
    accepted one divides it by ``decrease`` (not below ``minimum``); ``floor``
    is added to diag(H) in the damping term."""
    initial: float = 1e-3
    increase: float = 8.0
    decrease: float = 5.0
    tries: int = 12
    minimum: float = 1e-9
    floor: float = 1e-12


@dataclasses.dataclass(frozen=True)
class LMResult:
    """x: the last accepted variables; cost: their cost; iterations: linearisations made;
    converged: True when a step's relative gain fell below ``tol`` or no step was accepted."""
    x: np.ndarray
    cost: float
    iterations: int
    converged: bool


def levenberg_marquardt(linearise, cost, x0, propose=None, max_iter=100, tol=1e-6, damping=Damping(),
                        cost0=None) -> LMResult:
    """Minimise ``cost(x)`` by damped Gauss-Newton steps.

    Parameters
    ----------
    linearise : x -> (g (n,), H (n, n)), the gradient and Gauss-Newton Hessian at x
    cost : x -> float, the cost a step must lower (may be inf/NaN: rejected)
    x0 : (n,) start
    propose : (x, step) -> x_new, default x + step; applies bounds or step limits
    max_iter : at most this many linearisations
    tol : stop when a step lowers the cost by less than this fraction
    cost0 : cost(x0), when the caller has it
    """
    propose = propose or (lambda x, step: x + step)
    x = np.asarray(x0, dtype=np.float64)
    cur = cost(x) if cost0 is None else cost0
    lam = damping.initial
    for it in range(1, max_iter + 1):
        g, H = linearise(x)
        d = np.diag(H) + damping.floor
        accepted = False
        for _ in range(damping.tries):
            try:
                step = -np.linalg.solve(H + lam * np.diag(d), g)
            except np.linalg.LinAlgError:
                lam *= damping.increase
                continue
            x_new = propose(x, step)
            new = cost(x_new)
            if np.isfinite(new) and new < cur:
                accepted = True
                break
            lam *= damping.increase
        if not accepted:
            return LMResult(x, cur, it, True)
        gain = (cur - new) / max(abs(cur), 1e-300)
        x, cur = x_new, new
        lam = max(lam / damping.decrease, damping.minimum)
        if gain < tol:
            return LMResult(x, cur, it, True)
    return LMResult(x, cur, max_iter, False)
