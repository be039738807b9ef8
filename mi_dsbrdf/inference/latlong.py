"""Lat-long illumination maps in Mitsuba's ``envmap`` convention.

A map is an (H, W, 3) float32 array of radiance. Texel (row i, column j) has its
centre at u = (j + 0.5) / W, v = (i + 0.5) / H and looks along the world
direction (y up)

    theta = pi v,  phi = 2 pi u,
    d = (sin theta sin phi, cos theta, -sin theta cos phi),

which is the inverse of Mitsuba's lookup u = atan2(d_x, -d_z) / 2 pi,
v = acos(d_y) / pi. Its solid angle is (2 pi / W)(cos theta_0 - cos theta_1).
"""
from __future__ import annotations

import math

import numpy as np


def latlong_directions(height: int, width: int) -> np.ndarray:
    """(H, W, 3) float64 unit directions of the texel centres."""
    theta = (np.arange(height) + 0.5) / height * math.pi
    phi = (np.arange(width) + 0.5) / width * 2 * math.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(T) * np.sin(P), np.cos(T), -np.sin(T) * np.cos(P)], axis=-1)


def texel_solid_angles(height: int, width: int) -> np.ndarray:
    """(H, W) float64 solid angles (sr) of the texels; they sum to 4 pi."""
    edges = np.cos(np.arange(height + 1) / height * math.pi)
    return np.repeat(((edges[:-1] - edges[1:]) * 2 * math.pi / width)[:, None], width, axis=1)


def texel_directions(height: int, width: int, side: int) -> tuple:
    """The directions of the (height s) x (width s) grid, ordered texel by texel
    (the s x s directions inside a texel contiguous, row by row), and each one's
    solid angle (its share of its texel's): ((H W s^2, 3), (H W s^2,)) float64."""
    s = int(side)
    d = latlong_directions(height * s, width * s).reshape(height, s, width, s, 3).transpose(0, 2, 1, 3, 4)
    omega = texel_solid_angles(height * s, width * s).reshape(height, s, width, s).transpose(0, 2, 1, 3)
    return d.reshape(-1, 3), omega.reshape(-1)


#: a map written for Mitsuba repeats each texel as a TEXEL_BLOCK x TEXEL_BLOCK block:
#: inference treats a texel as constant, Mitsuba's envmap interpolates bilinearly
#: between texel centres, and the blocks confine that blend to their edges
#: (docs/design.md)
TEXEL_BLOCK = 8


def texel_blocks(illumination, block=TEXEL_BLOCK) -> np.ndarray:
    """(H * block, W * block, 3) float32: each texel of an (H, W, 3) lat-long map
    repeated as a block x block block (``illumination.exr``). Averaging the blocks
    gives the map back."""
    m = np.asarray(illumination, dtype=np.float32)
    return np.repeat(np.repeat(m, block, axis=0), block, axis=1)


def direction_to_uv(d) -> np.ndarray:
    """(N, 2) lat-long coordinates in [0, 1) of world directions (N, 3)."""
    d = np.asarray(d, dtype=np.float64).reshape(-1, 3)
    u = np.arctan2(d[:, 0], -d[:, 2]) / (2 * math.pi) % 1.0
    v = np.arccos(np.clip(d[:, 1], -1, 1)) / math.pi
    return np.stack([u, v], axis=-1)


def procedural_sky(height=64, width=128, sun_direction=(0.5, 0.7, -0.5), sun_radius_deg=3.0,
                   sun_to_sky=4.0) -> np.ndarray:
    """A clear-sky map: blue-to-white gradient, a warm sun disc, a grey ground.

    ``sun_to_sky``: irradiance on an upward surface from the sun relative to
    the sky's. Returns (H, W, 3) float32 radiance.
    """
    d = latlong_directions(height, width)
    up = d[..., 1]
    t = np.clip(up, 0, 1)[..., None]
    zenith, horizon = np.array([0.25, 0.45, 0.95]), np.array([0.9, 0.95, 1.0])
    sky = (horizon * (1 - t) ** 2 + zenith * (1 - (1 - t) ** 2)) * 0.6
    ground = np.array([0.35, 0.3, 0.25]) * 0.3
    env = np.where(up[..., None] > 0, sky, ground)
    s = np.asarray(sun_direction, dtype=np.float64)
    s = s / np.linalg.norm(s)
    sun = (d @ s) > math.cos(math.radians(sun_radius_deg))
    omega = texel_solid_angles(height, width)
    sky_irr = np.sum(env.mean(-1) * omega * np.clip(up, 0, None))
    sun_omega = np.sum(omega[sun])
    if sun_omega > 0:
        radiance = sun_to_sky * sky_irr / (sun_omega * max(s[1], 1e-3))
        env[sun] = radiance * np.array([1.0, 0.92, 0.8])
    return env.astype(np.float32)


#: log radiance of masked (unseen) texels: black, and below every bin of the entropy prior
BLACK = -30.0


def resample(log_map, size) -> np.ndarray:
    """The log map (h, w, 3) on ``size`` (H, W) texels, each new texel taking the
    value of the old texel its centre falls in; unseen (BLACK) texels take the
    darkest seen value first, so that a texel seen only at the finer size starts lit."""
    h, w, _ = log_map.shape
    H, W = size
    seen = log_map > BLACK
    x = np.where(seen, log_map, log_map[seen].min() if seen.any() else 0.0)
    rows = ((np.arange(H) + 0.5) * h / H).astype(np.int64)
    cols = ((np.arange(W) + 0.5) * w / W).astype(np.int64)
    return x[rows][:, cols]
