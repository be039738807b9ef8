"""Rusinkiewicz half/difference angles — the package's single conversion.

Directions are unit vectors in the local shading frame (normal = +z), given as
three arrays ``(x, y, z)``: numpy float64 arrays or Dr.Jit arrays (the same code
runs on both, see :mod:`mi_dsbrdf.brdf.xp`). All angles are in radians.

    h = (wi + wo) / |wi + wo|                     half vector, angles (theta_h, phi_h)
    d = R_y(-theta_h) R_z(-phi_h) wi              difference vector, (theta_d, phi_d)

For an isotropic BRDF only (theta_h, theta_d, phi_d) matter; MERL tables fold
phi_d into [0, pi) by reciprocity.
"""
from __future__ import annotations

import math

from mi_dsbrdf.brdf.xp import log1p, ops


def half_vector(wi, wo):
    """Unit half vector of two unit directions; (0, 0, 1) where wi = -wo."""
    o = ops(*wi, *wo)
    hx, hy, hz = wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]
    norm2 = hx * hx + hy * hy + hz * hz
    ok = norm2 > 1e-30
    inv = o.select(ok, 1.0, 0.0) / o.sqrt(o.select(ok, norm2, 1.0))
    return hx * inv, hy * inv, o.select(ok, hz * inv, 1.0)


def cos_half_diff(wi, wo):
    """(cos theta_h, cos theta_d, sin^2 theta_h): the isotropic angles, without acos.

    sin^2 theta_h = h_x^2 + h_y^2 keeps full relative precision near the
    specular peak, where 1 - cos theta_h underflows in float32.
    """
    hx, hy, hz = half_vector(wi, wo)
    cos_d = wi[0] * hx + wi[1] * hy + wi[2] * hz
    return hz, cos_d, hx * hx + hy * hy


def log_cos_h(cos_h, sin2_h):
    """log cos theta_h, accurate at the specular peak and finite at 90 deg.

    1/2 log1p(-sin^2 theta_h) while sin^2 theta_h < 1/2 (full relative precision
    as theta_h -> 0), log max(cos theta_h, 1e-30) beyond. Takes the values
    :func:`cos_half_diff` returns, or cos and sin^2 of an angle (numpy reference).
    """
    o = ops(cos_h, sin2_h)
    near = sin2_h < 0.5
    return o.select(near, 0.5 * log1p(-o.select(near, sin2_h, 0.0)),
                    o.log(o.fmax(o.select(near, 1.0, cos_h), 1e-30)))


def pair_geometry(frame, wi, d, omega) -> tuple:
    """What an isotropic BRDF sees of a light direction: (log cos theta_h, theta_d,
    weight) of the direction ``d`` (three world components) at the shading frame
    ``frame`` (its s, t and n axes, three components each) with ``wi`` (local) the
    direction to the camera; the weight cos theta_o * ``omega`` (solid angle), zero
    unless both directions are above the surface."""
    o = ops(*wi, *d)
    wo = [sum(a * b for a, b in zip(axis, d)) for axis in frame]          # to the local frame
    cos_h, cos_d, sin2_h = cos_half_diff(wi, wo)
    weight = o.select((wi[2] > 0) & (wo[2] > 0), wo[2] * omega, 0.0)
    return log_cos_h(cos_h, sin2_h), o.acos(cos_d), weight


def half_diff(wi, wo):
    """Rusinkiewicz angles (theta_h, phi_h, theta_d, phi_d) of direction pairs.

    phi_h in (-pi, pi], phi_d in (-pi, pi]; callers that need MERL's folding
    use :func:`fold_phi_d`.
    """
    o = ops(*wi, *wo)
    hx, hy, hz = half_vector(wi, wo)
    theta_h = o.acos(hz)
    phi_h = o.atan2(hy, hx)
    # d = R_y(-theta_h) R_z(-phi_h) wi
    cp, sp = o.cos(phi_h), o.sin(phi_h)
    x1 = wi[0] * cp + wi[1] * sp
    y1 = -wi[0] * sp + wi[1] * cp
    ct, st = hz, o.sqrt(hx * hx + hy * hy)
    dx = x1 * ct - wi[2] * st
    dz = x1 * st + wi[2] * ct
    theta_d = o.acos(dz)
    phi_d = o.atan2(y1, dx)
    return theta_h, phi_h, theta_d, phi_d


def fold_phi_d(phi_d):
    """phi_d folded into [0, pi) (isotropy and reciprocity, as MERL stores it)."""
    o = ops(phi_d)
    p = o.select(phi_d < 0.0, phi_d + math.pi, phi_d)
    return o.select(p >= math.pi, p - math.pi, p)


def from_half_diff(theta_h, theta_d, phi_d, phi_h=0.0):
    """Inverse conversion: (wi, wo) as tuples of arrays, for given angles.

    wi = R_z(phi_h) R_y(theta_h) d,  wo = R_z(phi_h) R_y(theta_h) (-d_x, -d_y, d_z).
    """
    o = ops(theta_h, theta_d, phi_d)
    sd, cd = o.sin(theta_d), o.cos(theta_d)
    dx, dy, dz = sd * o.cos(phi_d), sd * o.sin(phi_d), cd
    sh, ch = o.sin(theta_h), o.cos(theta_h)
    cp, sp = math.cos(phi_h), math.sin(phi_h)

    def to_world(x, y, z):
        x1, z1 = x * ch + z * sh, -x * sh + z * ch   # R_y(theta_h)
        return (x1 * cp - y * sp, x1 * sp + y * cp, z1)  # R_z(phi_h)

    return to_world(dx, dy, dz), to_world(-dx, -dy, dz)
