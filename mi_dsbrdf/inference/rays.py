"""Camera rays onto the object: through each pixel's centre, or a regular grid of
points over each pixel's area (what a box pixel filter averages)."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np


def centre_hits(scene, sensor, shape) -> tuple:
    """(the SurfaceInteraction of the ray through each pixel centre of ``sensor``'s
    film, row by row; (H * W,) bool: the pixels whose centre ray sees ``shape``)."""
    w, h = (int(v) for v in sensor.film().crop_size())
    return sample_hits(scene, sensor, shape, np.arange(w * h), 1)


def sample_hits(scene, sensor, shape, pixels, side) -> tuple:
    """Rays through the centres of a ``side`` x ``side`` grid over the area of each
    pixel of ``pixels`` (flat film indices, row by row): (their SurfaceInteraction,
    pixel-major, a pixel's rays row by row; (len(pixels) * side^2,) bool: the rays
    that see ``shape``)."""
    w, h = (int(v) for v in sensor.film().crop_size())
    pixels = np.asarray(pixels, dtype=np.int64)
    sub = (np.arange(side) + 0.5) / side
    oy, ox = (a.reshape(-1) for a in np.meshgrid(sub, sub, indexing="ij"))
    x = (pixels % w)[:, None] + ox[None, :]
    y = (pixels // w)[:, None] + oy[None, :]
    uv = mi.Point2f((x.reshape(-1) / w).astype(np.float32), (y.reshape(-1) / h).astype(np.float32))
    rays, _ = sensor.sample_ray(0.0, 0.5, uv, mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(rays)
    hit = np.array(si.is_valid()) & (np.array(dr.reinterpret_array(mi.UInt32, si.shape)) ==
                                     np.array(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))))
    return si, hit
