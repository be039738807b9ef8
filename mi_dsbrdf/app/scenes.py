"""The example scenes in ``scenes/`` and the assets they use.

``python -m mi_dsbrdf.app.scenes`` regenerates the committed assets:
``scenes/meshes/torus.ply`` (trimesh; a non-convex shape that sees only part of
the normal sphere from the camera and shadows itself) and
``scenes/textures/sky.exr`` (:func:`mi_dsbrdf.inference.latlong.procedural_sky`).
"""
from __future__ import annotations

import os

import mitsuba as mi
import numpy as np
import trimesh

from mi_dsbrdf.errors import InputError
from mi_dsbrdf.app.io import write_exr
from mi_dsbrdf.inference.latlong import procedural_sky
from mi_dsbrdf.inference.scene_dicts import SCENE_DIR, SHAPES, camera, shape_dict  # noqa: F401 (re-exported)

SCENES = {
    "sphere_envmap": "sphere_envmap.xml",
    "sphere_directional": "sphere_directional.xml",
    "torus_envmap": "torus_envmap.xml",
    "sphere_point": "sphere_point.xml",
    "sphere_on_ground": "sphere_on_ground.xml",
}


def sphere_scene(bsdf: dict, res: int = 24, fov: float = 30.0):
    """A unit sphere with ``bsdf`` seen by :func:`camera`, no light: a small scene
    for the texel-sum forward model (:mod:`mi_dsbrdf.inference.forward`), which brings its own."""
    return mi.load_dict({"type": "scene", "sensor": camera(res, fov), "object": {"type": "sphere", "bsdf": bsdf}})


def scene_path(name_or_path: str) -> str:
    """Path of a shipped scene by name (``sphere_envmap`` ...) or a given path."""
    if name_or_path in SCENES:
        return os.path.join(SCENE_DIR, SCENES[name_or_path])
    if not os.path.exists(name_or_path):
        raise InputError("no scene %r: give a path or one of %s" % (name_or_path, ", ".join(SCENES)))
    return name_or_path


def make_torus(path, major=0.7, minor=0.3, sections=96, tube=48) -> None:
    """Write a torus (axis tilted 60 deg from the view axis) with vertex normals as PLY."""
    mesh = trimesh.creation.torus(major_radius=major, minor_radius=minor,
                                  major_sections=sections, minor_sections=tube)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.radians(60), [1, 0, 0]))
    os.makedirs(os.path.dirname(path), exist_ok=True)
    mesh.export(path, encoding="binary", vertex_normal=True)


def build_assets(scene_dir: str = SCENE_DIR) -> list:
    torus = os.path.join(scene_dir, "meshes", "torus.ply")
    sky = os.path.join(scene_dir, "textures", "sky.exr")
    make_torus(torus)
    write_exr(sky, procedural_sky())
    return [torus, sky]


if __name__ == "__main__":
    import mi_dsbrdf  # noqa: F401  (variant, for the EXR writer)
    for p in build_assets():
        print("wrote", p)
