"""The photograph workflow: a recovery scene from an image of a sphere.

``mi-dsbrdf recover --sphere`` and :func:`sphere_scene` need no scene XML: the
sphere's outline is fitted to the mask (or, without one, to the image on its
black background: :mod:`mi_dsbrdf.app.outline`) and a scene dict is built
around a unit sphere at the origin, seen

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

from mi_dsbrdf.app.outline import fit_circle, fit_outline
from mi_dsbrdf.app.recover import load_inputs
from mi_dsbrdf.errors import InputError

LIGHTS = ("envmap", "directional", "point")
#: the point-light placeholder's distance from the sphere's centre, in radii
POINT_DISTANCE = 5.0
#: the farthest a perspective camera is placed from the sphere, in radii
MAX_CAMERA_DISTANCE = 1000


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
        if not (isinstance(fov, (int, float)) and not isinstance(fov, bool) and 0 < fov < 180):
            raise InputError("field of view must be in (0, 180) degrees, got %r" % (fov,))
        f = (W / 2) / math.tan(math.radians(fov) / 2)
        u = np.array([cx - W / 2, cy - H / 2])
        u = u / np.linalg.norm(u) if np.linalg.norm(u) > 1e-9 else np.array([1.0, 0.0])
        # the rays through the outline's two points on the radial line: 2 alpha apart
        ends = [np.array([(cx + s * r * u[0] - W / 2) / f, -(cy + s * r * u[1] - H / 2) / f, -1.0]) for s in (1, -1)]
        ends = [e / np.linalg.norm(e) for e in ends]
        alpha = 0.5 * math.acos(float(np.clip(ends[0] @ ends[1], -1, 1)))
        axis = (ends[0] + ends[1]) / np.linalg.norm(ends[0] + ends[1])
        # a lens this long sees the sphere from so far that float32 rays miss it; its
        # view is orthographic within 1/MAX_CAMERA_DISTANCE
        if not alpha * MAX_CAMERA_DISTANCE > 1:
            raise InputError("a field of view of %g degrees puts the camera over %d sphere radii away: the view is "
                             "orthographic within %g %%, leave out --fov (fov=None)"
                             % (fov, MAX_CAMERA_DISTANCE, 100.0 / MAX_CAMERA_DISTANCE))
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
    outline is fitted to the mask, or without one to the image
    (:func:`~mi_dsbrdf.app.outline.fit_outline`: a sphere on a black background)."""
    img, m = load_inputs(image, mask, srgb)
    h, w = img.shape[:2]
    circle = fit_circle(m) if m is not None else fit_outline(img)
    return sphere_scene((w, h), circle, light=light, fov=fov), circle
