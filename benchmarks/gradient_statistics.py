"""How heavy-tailed are real illumination maps' log gradients? The exponent alpha of the
gradient prior (paper Eq. 16, :class:`~mi_dsbrdf.inference.illumination_priors.GradientPrior`)
fitted by maximum likelihood to the validation probes (issue 15).

The prior prices a texel's colour gradient v (2 directions x 3 channels of the log map, lat-long
aware, in polar texel spacings; the prior's own differences) as (|v|^2 + eps^2)^(alpha / 2) / s.
Read as a density over v in R^6, exp(-(|v|^2 + eps^2)^(alpha / 2) / s), normalised numerically,
its maximum-likelihood alpha and s over the validation probes' texels (weighted by solid angle, as
the prior weighs them) say what the maps look like at the inference's map size. Only the
validation probes are used: the report probes do not choose settings.

    .venv/bin/python benchmarks/gradient_statistics.py          # -> benchmarks/results/gradient_statistics.json
"""
from __future__ import annotations

import json
import os
import sys

import numpy as np
from scipy.optimize import minimize
from scipy.special import gammaln

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mi_dsbrdf.config import Config  # noqa: E402
from mi_dsbrdf.inference.illumination_priors import GradientPrior  # noqa: E402
from mi_dsbrdf.inference.latlong import texel_solid_angles  # noqa: E402

OUT = os.path.join(ROOT, "benchmarks", "results", "gradient_statistics.json")
#: the exponents the fit searches (open interval)
ALPHA_RANGE = (0.02, 2.5)
#: the dimension of the prior's v: 2 directions x 3 channels
DIM = 6


def gradient_magnitudes(log_map) -> tuple:
    """(|v| (N,), solid-angle weights (N,) summing to one) of an (H, W, C) log map, the
    gradient prior's own differences (the last row, with no neighbour past the pole, left out)."""
    H, W, _ = log_map.shape
    dphi, dth, _ = GradientPrior.differences(log_map)
    m2 = (dphi ** 2 + dth ** 2).sum(axis=2)
    w = texel_solid_angles(H, W)[:-1].ravel()
    return np.sqrt(m2[:-1].ravel()), w / w.sum()


def log_normaliser(alpha, log_s, eps, dim) -> float:
    """log of the integral over R^dim of exp(-(|v|^2 + eps^2)^(alpha/2) / s): the radial
    integral in u = log |v| on a fine grid (log-sum-exp; the integrand's peak lies at
    |v|^alpha ~ dim s / alpha, which quadrature misses for small alpha)."""
    s = np.exp(log_s)
    u_peak = np.log(dim * s / alpha) / alpha
    u = np.linspace(min(np.log(eps), u_peak) - 30.0 / dim, u_peak + np.log(200.0) / alpha, 40001)
    e = dim * u - (np.exp(2 * u) + eps ** 2) ** (alpha / 2) / s
    top = e.max()
    integral = top + np.log(np.exp(e - top).sum() * (u[1] - u[0]))
    sphere = np.log(2) + dim / 2 * np.log(np.pi) - gammaln(dim / 2)
    return float(sphere + integral)


def fit(g, w, eps, dim, alpha=None) -> dict:
    """Maximum-likelihood (alpha, s) of the prior's density (alpha held if given)."""
    def nll(p):
        a, log_s = (alpha, p[0]) if alpha is not None else p
        if not ALPHA_RANGE[0] < a < ALPHA_RANGE[1]:
            return 1e18
        return float((w * ((g * g + eps * eps) ** (a / 2) / np.exp(log_s))).sum()
                     + log_normaliser(a, log_s, eps, dim))
    if alpha is not None:
        r = min((minimize(nll, [ls], method="Nelder-Mead") for ls in (-3.0, -1.0, 1.0)), key=lambda r: r.fun)
        return {"alpha": alpha, "log_s": float(r.x[0]), "nll": float(r.fun)}
    r = min((minimize(nll, [a, ls], method="Nelder-Mead") for a in (0.2, 0.5, 1.0) for ls in (-3.0, 0.0)),
            key=lambda r: r.fun)
    return {"alpha": float(r.x[0]), "log_s": float(r.x[1]), "nll": float(r.fun)}


def main():
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    from natural_light import VALIDATION_PROBES
    from experiments import DATA
    from mi_dsbrdf.evaluation.experiment import downsample
    cfg = Config()
    H, W = cfg.map_size
    gs, ws = [], []
    for probe in VALIDATION_PROBES:
        env = np.array(mi.Bitmap(os.path.join(DATA, "envmaps", probe)), dtype=np.float64)
        g, w = gradient_magnitudes(np.log(np.maximum(downsample(env, H, W), 1e-8)))
        gs.append(g)
        ws.append(w / len(VALIDATION_PROBES))
    g, w = np.concatenate(gs), np.concatenate(ws)
    out = {"probes": VALIDATION_PROBES, "map_size": [H, W], "eps": cfg.gradient_eps,
           "quantiles_of_gradient": dict(zip(["10", "25", "50", "75", "90", "99"],
                                             np.quantile(g, [.1, .25, .5, .75, .9, .99]).round(3).tolist())),
           "dimensions": DIM}
    best = fit(g, w, cfg.gradient_eps, DIM)
    out["maximum_likelihood"] = best
    out["at_alpha"] = [fit(g, w, cfg.gradient_eps, DIM, alpha=a) for a in (0.15, 0.3, 0.5, 0.8)]
    print("validation probes at %dx%d, |v| quantiles (10, 25, 50, 75, 90, 99 %%): %s"
          % (H, W, list(out["quantiles_of_gradient"].values())))
    edge = " (the search's lower bound: the tail is heavier than any alpha)" if best["alpha"] < ALPHA_RANGE[0] + 0.005 else ""
    print("maximum-likelihood alpha %.3f%s (mean -log p %.3f); at alpha " % (best["alpha"], edge, best["nll"])
          + ", ".join("%.2f: %.3f" % (h["alpha"], h["nll"]) for h in out["at_alpha"]))
    with open(OUT, "w") as fh:
        json.dump(out, fh, indent=1)
    print("->", os.path.relpath(OUT, ROOT))


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    main()
