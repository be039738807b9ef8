"""Mitsuba scene dicts of the shipped camera and shapes: what the app's scenes,
renders and the evaluation's synthetic cases are built from."""
from __future__ import annotations

import os

import mitsuba as mi

from mi_dsbrdf.errors import InputError

#: the repository's ``scenes/`` folder (example scenes and their assets)
SCENE_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "scenes")


def camera(res: int, fov: float = 30.0, box_filter: bool = True) -> dict:
    """The shipped scenes' camera as a Mitsuba dict: perspective, at distance 4
    on +z looking at the origin, a res x res film (box filter: one pixel, one
    footprint, as the texel-sum forward model assumes)."""
    film = {"type": "hdrfilm", "width": res, "height": res}
    if box_filter:
        film["rfilter"] = {"type": "box"}
    return {"type": "perspective", "fov": fov,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
            "film": film}


#: shapes known by name (besides a .ply/.obj mesh file)
SHAPES = ("sphere", "torus")


def shape_dict(shape: str, bsdf) -> dict:
    """Mitsuba dict of ``shape`` (``sphere``, the shipped non-convex ``torus``, or a
    .ply/.obj mesh file) carrying ``bsdf`` (a dict or a BSDF instance)."""
    if shape == "sphere":
        obj = {"type": "sphere"}
    elif shape == "torus":
        obj = {"type": "ply", "filename": os.path.join(SCENE_DIR, "meshes", "torus.ply")}
    elif os.path.exists(shape) and shape.lower().endswith((".ply", ".obj")):
        obj = {"type": shape.lower().rsplit(".", 1)[1], "filename": os.path.abspath(shape)}
    else:
        raise InputError("shape %r: give %s or an existing .ply/.obj file" % (shape, " or ".join(SHAPES)))
    obj["bsdf"] = bsdf
    return obj
