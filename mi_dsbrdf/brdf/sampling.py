"""Importance sampling shared by the ``dsbrdf`` and ``merl`` BSDFs.

A mixture, with exact pdf, of
  * cosine-weighted hemisphere sampling of wo (weight ``w_cos``), and
  * per lobe r, power-cosine sampling of the half vector about the normal,
    p_h(h) = (n_r + 1) / (2 pi) cos^{n_r} theta_h, reflected to
    wo = 2 (wi.h) h - wi, so p(wo) = p_h(h) / (4 wi.h).

The exponents n_r and weights depend only on wi (for the DSBRDF: its lobe curves
at theta_d = theta_i, the specular configuration), so :func:`mixture_pdf`
evaluates exactly the density :func:`mixture_sample` samples. Written once
for numpy (tests) and Dr.Jit (plugins), directions as ``(x, y, z)`` tuples.
"""
from __future__ import annotations

import math

from mi_dsbrdf.brdf.angles import cos_half_diff, log_cos_h
from mi_dsbrdf.brdf.xp import expm1, ops

W_COS = 0.15            # defensive share of cosine-hemisphere sampling
EXPONENT_MAX = 1e6


def dsbrdf_exponent(kappa, gamma):
    """Power-cosine exponent matching a lobe expm1(kappa cos^gamma theta_h).

    Near the peak the lobe falls off like exp(-kappa gamma theta_h^2 / 2) for
    large kappa and like cos^gamma for small kappa; n = gamma kappa / (1 - e^-kappa)
    interpolates the two (-> gamma as kappa -> 0, -> gamma kappa for large kappa).
    """
    o = ops(kappa, gamma)
    ratio = kappa / o.fmax(-expm1(-kappa), 1e-30)
    return o.clip(gamma * o.select(kappa > 1e-6, ratio, 1.0), 0.0, EXPONENT_MAX)


def dsbrdf_weights(kappa, gamma, w_cos=W_COS):
    """Mixture weights and exponents for DSBRDF lobes (lists of R arrays).

    Lobe r gets a share of 1 - w_cos proportional to its energy estimate
    expm1(kappa_r) / (n_r + 1) (peak value times ~solid angle).
    Returns ``(w_cos_array, [w_r], [n_r])``; all weights sum to one.
    """
    o = ops(kappa[0], gamma[0])
    n = [dsbrdf_exponent(k, g) for k, g in zip(kappa, gamma)]
    energy = [expm1(k) / (nr + 1.0) for k, nr in zip(kappa, n)]
    total = energy[0]
    for e in energy[1:]:
        total = total + e
    has = total > 1e-30
    inv = o.select(has, (1.0 - w_cos) / o.select(has, total, 1.0), 0.0)
    w = [e * inv for e in energy]
    wc = o.select(has, w_cos, 1.0) + 0.0 * total
    return wc, w, n


def mixture_pdf(wi, wo, w_cos, weights, exponents):
    """Solid-angle density of wo given wi (0 below the horizon)."""
    o = ops(*wi, *wo)
    cos_o = wo[2]
    above = (cos_o > 0.0) & (wi[2] > 0.0)
    pdf = w_cos * o.fmax(cos_o, 0.0) * (1.0 / math.pi)
    cos_h, cos_d, sin2_h = cos_half_diff(wi, wo)
    log_cos = log_cos_h(cos_h, sin2_h)
    jac = 1.0 / (4.0 * o.fmax(cos_d, 1e-12))
    for w, n in zip(weights, exponents):
        pdf = pdf + w * (n + 1.0) * (0.5 / math.pi) * o.exp(n * log_cos) * jac
    return o.select(above & (cos_d > 0.0), pdf, 0.0)


def mixture_sample(wi, u1, u2x, u2y, w_cos, weights, exponents):
    """Sample wo from the mixture with uniform numbers ``u1`` (component) and
    ``(u2x, u2y)`` (direction). Returns ``(wo, valid)``; invalid samples (below
    the horizon) have ``valid`` False.
    """
    o = ops(wi[2], u1, u2x)
    # component choice: cosine if u1 < w_cos, else the lobe whose cumulative
    # weight interval holds u1
    is_cos = u1 < w_cos
    n_sel = (exponents[-1] if exponents else 0.0) + 0.0 * u1
    cum = w_cos + 0.0 * u1
    for w, n in zip(weights, exponents):
        nxt = cum + w
        n_sel = o.select((u1 >= cum) & (u1 < nxt), n + 0.0 * u1, n_sel)
        cum = nxt
    phi = 2.0 * math.pi * u2y
    cp, sp = o.cos(phi), o.sin(phi)
    # cosine hemisphere (Malley): r = sqrt(u), z = sqrt(1 - u)
    rc = o.sqrt(u2x)
    cos_dir = (rc * cp, rc * sp, o.sqrt(1.0 - u2x))
    # power cosine half vector: cos theta_h = u^(1/(n+1)); 1 - cos computed stably
    one_minus = -expm1(o.log(o.fmax(u2x, 1e-38)) / (n_sel + 1.0))
    sin_h = o.sqrt(one_minus * (2.0 - one_minus))
    h = (sin_h * cp, sin_h * sp, 1.0 - one_minus)
    wi_h = wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]
    refl = tuple(2.0 * wi_h * hc - wc for hc, wc in zip(h, wi))
    wo = tuple(o.select(is_cos, c, r) for c, r in zip(cos_dir, refl))
    valid = (wo[2] > 0.0) & (wi[2] > 0.0) & (is_cos | (wi_h > 0.0))
    return wo, valid
