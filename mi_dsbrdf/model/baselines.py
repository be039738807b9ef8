"""Baseline reflectance models that reports compare the DSBRDF against.

Lambert + L-lobe Cook-Torrance (the paper's Fig. 2 comparison):

    f = k_d / pi + sum_l k_s,l D(theta_h; m_l) F(theta_d; F0_l) G / (4 cos theta_i cos theta_o)

with the Beckmann distribution D, Schlick's Fresnel term with an RGB F0 and the
Cook-Torrance shadowing term G. Free variables: RGB k_d (3) and per lobe RGB
k_s (3), roughness m (1) and RGB F0 (3): 10 for one lobe, 24 for three. Fitted
by minimising the same objective as the DSBRDF (:func:`fit_cook_torrance`).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares
from scipy.special import expit

from mi_dsbrdf.brdf.angles import from_half_diff
from mi_dsbrdf.brdf.log_error import log_rmse
from mi_dsbrdf.model.fit_problem import OBJECTIVE, FitObjective

LOG_M_MIN, LOG_M_MAX = math.log(1e-3), math.log(2.0)


def cook_torrance(params, theta_h, theta_d, phi_d, n_lobes) -> np.ndarray:
    """(N, 3) float64 BRDF values (1/sr) of Lambert + ``n_lobes`` Cook-Torrance
    lobes; ``params`` = [log k_d (3), then per lobe log k_s (3), log m, logit F0 (3)]."""
    p = np.asarray(params, dtype=np.float64)
    th, td = np.asarray(theta_h, dtype=np.float64), np.asarray(theta_d, dtype=np.float64)
    wi, wo = from_half_diff(th, td, np.asarray(phi_d, dtype=np.float64))
    ci, co = np.maximum(wi[2], 1e-6), np.maximum(wo[2], 1e-6)
    ch, cd = np.cos(th), np.cos(td)
    G = np.minimum(1.0, np.minimum(2 * ch * co / cd, 2 * ch * ci / cd))
    tan2 = np.sin(th) ** 2 / np.maximum(ch ** 2, 1e-12)
    schlick = (1.0 - cd) ** 5
    out = np.repeat((np.exp(np.clip(p[:3], -30, 20)) / math.pi)[None], th.size, axis=0)
    for lobe in range(n_lobes):
        q = p[3 + 7 * lobe: 10 + 7 * lobe]
        # clipped exponents: no optimiser step overflows to inf * 0
        ks, m2 = np.exp(np.clip(q[:3], -30, 20)), math.exp(2 * min(max(q[3], LOG_M_MIN), LOG_M_MAX))
        f0 = expit(q[4:7])
        D = np.exp(-tan2 / m2) / (math.pi * m2 * np.maximum(ch, 1e-6) ** 4)
        F = f0[None] + (1 - f0[None]) * schlick[:, None]
        out += ks[None] * (D * G / (4 * ci * co))[:, None] * F
    return out


def fit_cook_torrance(samples, n_lobes, start=None, max_nfev=100, objective: FitObjective = OBJECTIVE):
    """Fit Lambert + ``n_lobes`` Cook-Torrance lobes to
    :class:`~mi_dsbrdf.model.samples.Samples` by the DSBRDF fits' objective
    (:class:`~mi_dsbrdf.model.fit_problem.FitObjective`; trust-region least squares).

    Starts: for one lobe, roughness m in {0.02, 0.1, 0.3}; for more, ``start``
    (e.g. a one-lobe fit, whose lobe is copied with m x {0.3, 1, 3}) and a
    generic start with m in {0.01, 0.08, 0.4}. Returns (params, Eq. 5 in the paper's
    convention on the samples).
    """
    y = objective.logs(samples.values, samples.cos_i)

    def residuals(p):
        f = cook_torrance(p, samples.theta_h, samples.theta_d, samples.phi_d, n_lobes)
        return (objective.logs(f, samples.cos_i) - y).reshape(-1)

    far = samples.theta_h > math.radians(30)
    diffuse = np.maximum(samples.values[far].mean(axis=0) if np.any(far) else samples.values.mean(axis=0), 1e-4)

    def generic(ms):
        p0 = [*np.log(diffuse * math.pi)]
        for m in ms:
            p0 += [math.log(0.1 * m)] * 3 + [math.log(m)] + [-2.0] * 3
        return np.array(p0)

    if n_lobes == 1:
        starts = [generic([m]) for m in (0.02, 0.1, 0.3)]
    else:
        starts = [generic(np.geomspace(0.01, 0.4, n_lobes))]
        if start is not None:
            s0 = np.asarray(start, dtype=np.float64)
            lobe = s0[3:10].copy()
            p0 = list(s0[:3])
            for f in np.geomspace(0.3, 3.0, n_lobes):
                q = lobe.copy()
                q[3] += math.log(f)
                q[:3] += 0.0 if abs(math.log(f)) < 0.2 else math.log(0.3)
                p0 += list(q)
            starts.append(np.array(p0))
    best = None
    for p0 in starts:
        sol = least_squares(residuals, p0, method="trf", max_nfev=max_nfev)
        if best is None or sol.cost < best.cost:
            best = sol
    f = cook_torrance(best.x, samples.theta_h, samples.theta_d, samples.phi_d, n_lobes)
    return best.x, log_rmse(f, samples.values, samples.cos_i, "paper")
