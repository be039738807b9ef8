"""The photograph workflow: a recovery scene from an image of a sphere.

``mi-dsbrdf recover --sphere`` and :func:`sphere_scene` need no scene XML: the
sphere's outline is fitted to the mask (or to the image's non-black pixels) and
a scene dict is built around a unit sphere at the origin, seen

* by an orthographic camera (the default: a distant camera, a long lens), the
  film's pixel size set so that the sphere's outline falls where it is in the
  image; or
* by a perspective camera of the given horizontal field of view at the origin,
  the sphere placed on the ray through the outline's centre at the distance
  that gives it the outline's angular size (an off-axis sphere's outline is an
  ellipse; a circle fitted to it is exact on the axis and close near it).

The light is a placeholder of the requested kind (``envmap``, ``directional``,
``point``): inference recovers it. A point light is placed 5 radii from the
sphere towards the camera; inference keeps that distance (one image barely
constrains it) and recovers its direction and intensity.
"""
from __future__ import annotations

import math

import mitsuba as mi
import numpy as np

from mi_dsbrdf.app.recover import load_inputs
from mi_dsbrdf.errors import InputError
from mi_dsbrdf.inference.pixels import interior

#: the fitted circle must cover the outline this well (intersection over union)
MIN_IOU = 0.9
#: the outline's largest rms distance from the fitted circle: this many pixels, or
#: this fraction of the radius if larger
OUTLINE_RMS, OUTLINE_RMS_RELATIVE = 0.5, 0.02
#: fewest outline pixels a circle is fitted to
MIN_OUTLINE = 12
LIGHTS = ("envmap", "directional", "point")
#: the point-light placeholder's distance from the sphere's centre, in radii
POINT_DISTANCE = 5.0


def object_pixels(image) -> np.ndarray:
    """(H, W) bool: pixels brighter than 1 % of the image's 99th percentile (a
    sphere photographed on black)."""
    lum = np.asarray(image, dtype=np.float64).mean(axis=2)
    top = np.percentile(lum[lum > 0], 99) if (lum > 0).any() else 0.0
    return lum > 0.01 * top


def fit_circle(mask, given=True) -> tuple:
    """(cx, cy, r) in pixels (x right, y down, pixel centres at +0.5) of the disc
    ``mask`` (H, W bool) shows; InputError if it is not a disc (``given``: the
    user's mask, else the image's non-black pixels, which the message says).

    A circle is fitted by algebraic least squares (Kasa) to the outline pixels
    away from the frame; inside the frame the centroid and the area give the disc
    more precisely. The outline must lie within OUTLINE_RMS of the circle (a
    rasterised disc: 0.25 px; a sphere's lit part under one light, its
    terminator taken for the outline: 0.85 px at r = 17) and the circle must
    cover the mask (MIN_IOU).
    """
    m = np.asarray(mask, bool)
    h, w = m.shape
    ys, xs = np.nonzero(m)
    if xs.size < MIN_OUTLINE:
        raise InputError("the sphere covers %d pixels: too few to fit its outline" % xs.size)
    edge = m & ~interior(m)
    edge[0], edge[-1], edge[:, 0], edge[:, -1] = False, False, False, False
    ey, ex = np.nonzero(edge)
    if ex.size < MIN_OUTLINE:
        raise InputError("the sphere's outline inside the frame has %d pixels: too few to fit it" % ex.size)
    x, y = ex + 0.5, ey + 0.5
    (a, b, c), *_ = np.linalg.lstsq(np.stack([x, y, np.ones_like(x)], axis=1), x * x + y * y, rcond=None)
    cx, cy = a / 2, b / 2
    r = math.sqrt(max(c + cx * cx + cy * cy, 0.0))
    rms = float(np.sqrt(np.mean((np.hypot(x - cx, y - cy) - r) ** 2)))
    if rms > max(OUTLINE_RMS, OUTLINE_RMS_RELATIVE * r):
        raise InputError("the %s outline is not a circle (%.2g px rms from the best one): is it a sphere? %s" % (
            ("mask's", rms, "") if given else
            ("object's", rms, "Without a mask the outline is where the image turns black, and a sphere's unlit side "
                              "is black too: give a mask of the sphere")))
    on_frame = m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any()
    if on_frame:
        r += 0.5                       # outline pixel centres lie half a pixel inside the disc
    else:
        cx, cy, r = xs.mean() + 0.5, ys.mean() + 0.5, math.sqrt(xs.size / math.pi)
    yy, xx = np.mgrid[0:h, 0:w]
    disc = (xx + 0.5 - cx) ** 2 + (yy + 0.5 - cy) ** 2 <= r * r
    iou = (disc & m).sum() / max((disc | m).sum(), 1)
    if iou < MIN_IOU:
        raise InputError("the object's pixels are not a disc (a fitted circle covers them to %.0f %%, need %.0f %%): "
                         "is it a sphere, and is the background black? give a mask of the sphere"
                         % (100 * iou, 100 * MIN_IOU))
    return float(cx), float(cy), float(r)


def sphere_scene(size, circle, light="envmap", fov=None) -> dict:
    """A Mitsuba scene dict: a unit sphere with a ``dsbrdf`` BSDF at the origin,
    seen as the circle (cx, cy, r) on a film of ``size`` (W, H) pixels, and a
    placeholder light of kind ``light``; orthographic without ``fov``, else a
    perspective camera of that horizontal field of view (degrees)."""
    W, H = (int(v) for v in size)
    cx, cy, r = circle
    if light not in LIGHTS:
        raise InputError("light %r: give one of %s" % (light, ", ".join(LIGHTS)))
    T = mi.ScalarTransform4f
    film = {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}}
    if fov is None:
        # orthographic: camera x in [-1, 1] spans the film's width; one pixel is 1/r
        p = 1.0 / r
        ox, oy = (W / 2 - cx) * p, (cy - H / 2) * p
        sensor = {"type": "orthographic", "film": film,
                  "to_world": T().look_at(origin=[ox, oy, 4], target=[ox, oy, 0], up=[0, 1, 0])
                  @ T().scale([W * p / 2, W * p / 2, 1])}
        camera = np.array([0.0, 0.0, 1.0])           # direction from the sphere towards the camera
    else:
        if not (isinstance(fov, (int, float)) and 0 < fov < 180):
            raise InputError("field of view must be in (0, 180) degrees, got %r" % (fov,))
        f = (W / 2) / math.tan(math.radians(fov) / 2)
        u = np.array([cx - W / 2, cy - H / 2])
        u = u / np.linalg.norm(u) if np.linalg.norm(u) > 1e-9 else np.array([1.0, 0.0])
        # the rays through the outline's two points on the radial line: 2 alpha apart
        ends = [np.array([(cx + s * r * u[0] - W / 2) / f, -(cy + s * r * u[1] - H / 2) / f, -1.0]) for s in (1, -1)]
        ends = [e / np.linalg.norm(e) for e in ends]
        alpha = 0.5 * math.acos(float(np.clip(ends[0] @ ends[1], -1, 1)))
        axis = (ends[0] + ends[1]) / np.linalg.norm(ends[0] + ends[1])
        distance = 1.0 / math.sin(alpha)
        position = -distance * axis                  # camera position, the sphere at the origin
        sensor = {"type": "perspective", "fov": float(fov), "fov_axis": "x", "film": film,
                  "to_world": T().translate([float(v) for v in position])
                  @ T().look_at(origin=[0, 0, 0], target=[0, 0, -1], up=[0, 1, 0])}
        camera = position / distance
    emitter = {"envmap": {"type": "envmap", "bitmap": mi.Bitmap(np.ones((8, 16, 3), np.float32))},
               "directional": {"type": "directional", "direction": [float(v) for v in -camera],
                               "irradiance": {"type": "rgb", "value": 1.0}},
               "point": {"type": "point", "position": [float(v) for v in POINT_DISTANCE * camera],
                         "intensity": {"type": "rgb", "value": 1.0}}}[light]
    return {"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor,
            "object": {"type": "sphere", "bsdf": {"type": "dsbrdf"}}, "light": emitter}


def photo_scene(image, mask=None, light="envmap", fov=None, srgb=False) -> tuple:
    """(scene dict, (cx, cy, r)) for a photograph of a sphere: ``image`` and
    ``mask`` are paths or arrays (as :func:`mi_dsbrdf.recover` takes them); the
    outline is fitted to the mask, or to the image's non-black pixels."""
    img, m = load_inputs(image, mask, srgb)
    h, w = img.shape[:2]
    circle = fit_circle(m, given=True) if m is not None else fit_circle(object_pixels(img), given=False)
    return sphere_scene((w, h), circle, light=light, fov=fov), circle
