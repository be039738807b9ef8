"""Log-RMSE of a BRDF against measured samples (the paper's Eq. 5 and Eq. 20).

BRDF errors come in two conventions, always named:

* ``"paper"`` — the paper's Eq. 5: the RMS over measured samples and channels of
  log(f + 1e-6) - log(rho + 1e-6), f the model and rho the measurement in 1/sr.
  The floor :data:`PAPER_FLOOR` is the one of the authors' lab's code (iBRDF,
  ``fit_merl.cpp``: ``log(f + 1e-6)``). It weighs every decade of the BRDF
  alike: a metal predicted at 1e-14/sr where it reflects 1e-3/sr costs as much
  as a peak off by a factor of 1000.
* ``"cosine"`` — the graphics-fitting convention (Löw et al. 2012; the neural-BRDF
  loss): log(1 + rho cos theta_i). Nearly linear below 0.1/sr, so it hardly sees
  diffuse and dark errors; it measures what a bright picture shows.

Functions:

* :func:`log_rmse` — Eq. 5 in either convention;
* :func:`log_rmse_scale_invariant` — Eq. 20, the same after the best overall
  scale of the model: what one image under unknown light can determine;
* :func:`material_errors` — of a material against measured samples, both conventions.

The model's fits (:mod:`mi_dsbrdf.model`) score themselves with these;
:mod:`mi_dsbrdf.evaluation.metrics` re-exports them beside the image measures.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar

#: Floor of the paper convention's log, log(f + PAPER_FLOOR) (1/sr).
PAPER_FLOOR = 1e-6
#: The two conventions of BRDF errors, the paper's first.
CONVENTIONS = ("paper", "cosine")


def log_brdf(values, cos_i, convention="paper") -> np.ndarray:
    """The log-BRDF a convention compares: (N, 3) log(rho + 1e-6) (``"paper"``)
    or log(1 + rho cos theta_i) (``"cosine"``).

    ``values``: (N, 3) BRDF values in 1/sr (negative values count as 0);
    ``cos_i``: (N,) cosine of the incident angle of each sample (unused by the
    paper convention).
    """
    v = np.maximum(np.asarray(values, dtype=np.float64), 0.0)
    if convention == "paper":
        return np.log(v + PAPER_FLOOR)
    if convention == "cosine":
        return np.log1p(v * np.asarray(cos_i, dtype=np.float64).reshape(-1, 1))
    raise ValueError("unknown error convention %r (use one of %s)" % (convention, ", ".join(CONVENTIONS)))


def log_rmse(model_values, measured_values, cos_i, convention="paper") -> float:
    """Eq. 5 in a convention (see the module doc): sqrt(mean over samples and
    channels of [log_brdf(model) - log_brdf(measured)]^2).

    ``model_values``, ``measured_values``: (N, 3) float arrays in 1/sr over the
    same N measured samples; ``cos_i``: (N,). Returns a float (dimensionless).
    """
    a = log_brdf(model_values, cos_i, convention)
    b = log_brdf(measured_values, cos_i, convention)
    if a.shape != b.shape:
        raise ValueError("model and measured values differ in shape: %s vs %s" % (a.shape, b.shape))
    return float(np.sqrt(np.mean((a - b) ** 2)))


def log_rmse_scale_invariant(model_values, measured_values, cos_i, convention="paper") -> tuple:
    """Eq. 20: min over s > 0 of Eq. 5 (in ``convention``) between s * model and
    the measurement.

    Under illumination of unknown strength only light x reflectance is
    observable, so a recovered BRDF is scored up to one overall scale.
    Returns (error, s). The minimum is found by Brent's bounded search on log s
    (Eq. 5 of a scaled model is unimodal in log s in practice; s in 1e-6..1e6).
    """
    m = np.asarray(model_values, dtype=np.float64)
    res = minimize_scalar(lambda log_s: log_rmse(m * np.exp(log_s), measured_values, cos_i, convention),
                          method="bounded", bounds=(math.log(1e-6), math.log(1e6)), options={"xatol": 1e-6})
    return float(res.fun), float(np.exp(res.x))


def material_errors(material, samples, scale_invariant=True, conventions=CONVENTIONS, where=None) -> dict:
    """Eq. 20 (or Eq. 5) of a material (anything with ``.eval(theta_h, theta_d)``,
    e.g. :class:`~mi_dsbrdf.brdf.dsbrdf.Material`) against measured
    :class:`~mi_dsbrdf.model.samples.Samples`: ``{convention: error}``; with
    ``where`` ((N,) bool), on those samples only (NaN if none)."""
    return values_errors(material.eval(samples.theta_h, samples.theta_d), samples, scale_invariant, conventions,
                         where)


def values_errors(values, samples, scale_invariant=True, conventions=CONVENTIONS, where=None) -> dict:
    """:func:`material_errors` of BRDF ``values`` (N, 3) at the samples' angles."""
    measured, cos_i = samples.values, samples.cos_i
    if where is not None:
        where = np.asarray(where, bool).reshape(-1)
        if not where.any():
            return {c: float("nan") for c in conventions}
        values, measured, cos_i = values[where], measured[where], cos_i[where]
    if scale_invariant:
        return {c: log_rmse_scale_invariant(values, measured, cos_i, c)[0] for c in conventions}
    return {c: log_rmse(values, measured, cos_i, c) for c in conventions}


def observed_errors(material, samples, conventions=CONVENTIONS) -> dict:
    """Eq. 20 of a recovered ``material`` on the samples whose (theta_h, theta_d)
    its image saw (:meth:`~mi_dsbrdf.brdf.dsbrdf.Material.observed` > 0), and on
    the rest: ``{"observed": {convention: error}, "unobserved": {...}}`` (NaN
    where there are none; None for a material that records no observation)."""
    seen = material.observed(samples.theta_h, samples.theta_d)
    if seen is None:
        return None
    return split_errors(material.eval(samples.theta_h, samples.theta_d), samples, seen > 0, conventions)


def split_errors(values, samples, where, conventions=CONVENTIONS) -> dict:
    """Eq. 20 of BRDF ``values`` (N, 3) on the samples ``where`` ((N,) bool) and on
    the rest: ``{"observed": {convention: error}, "unobserved": {...}}`` (NaN where
    there are none)."""
    where = np.asarray(where, bool).reshape(-1)
    return {"observed": values_errors(values, samples, conventions=conventions, where=where),
            "unobserved": values_errors(values, samples, conventions=conventions, where=~where)}
