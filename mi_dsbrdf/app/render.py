"""Forward rendering of scenes to EXR with PNG previews."""
from __future__ import annotations

import os
import time

import mitsuba as mi
import numpy as np

from mi_dsbrdf.app.io import save_preview, write_exr
from mi_dsbrdf.app.scenes import camera, shape_dict
from mi_dsbrdf.errors import InputError
from mi_dsbrdf.model.library import library_names


def render_scene(scene_file, spp=None, **params) -> np.ndarray:
    """Render a scene XML (with ``<default>`` overrides ``params``) to (H, W, 3) float32."""
    scene = mi.load_file(os.fspath(scene_file), **{k: str(v) for k, v in params.items()})
    img = mi.render(scene, spp=spp or 0)
    img = np.array(img, dtype=np.float32)
    if not np.all(np.isfinite(img)):
        raise FloatingPointError("render of %s produced non-finite pixels" % scene_file)
    return img


def render_to_files(scene_file, out_stem, spp=None, **params) -> dict:
    """Render and write ``<out_stem>.exr`` and ``<out_stem>.png``; returns paths and time."""
    t0 = time.perf_counter()
    img = render_scene(scene_file, spp=spp, **params)
    seconds = time.perf_counter() - t0
    write_exr(out_stem + ".exr", img)
    save_preview(img, out_stem + ".png")
    return {"exr": out_stem + ".exr", "png": out_stem + ".png", "seconds": seconds}


def relight(material_file, envmap_file, out_file, shape="sphere", res=256, spp=64) -> dict:
    """Render a recovered (or library) material on ``shape`` under a lat-long
    ``envmap_file`` with Mitsuba's path tracer; writes ``out_file`` (EXR) and a
    PNG beside it. ``material_file``: a material.json or a library name."""
    bsdf = {"type": "dsbrdf"}
    if os.path.exists(os.fspath(material_file)):
        bsdf["filename"] = os.path.abspath(os.fspath(material_file))
    elif str(material_file) in library_names():
        bsdf["material"] = str(material_file)
    else:
        raise InputError("material %s is neither a file nor a library material" % material_file)
    if not os.path.exists(os.fspath(envmap_file)):
        raise InputError("envmap %s does not exist" % envmap_file)
    obj = shape_dict(shape, bsdf)
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 4},
        "sensor": camera(res, 32, box_filter=False),
        "object": obj, "emitter": {"type": "envmap", "filename": os.path.abspath(os.fspath(envmap_file))}})
    t0 = time.perf_counter()
    img = np.array(mi.render(scene, spp=spp), dtype=np.float32)
    if not np.all(np.isfinite(img)):
        raise FloatingPointError("relighting produced non-finite pixels")
    write_exr(out_file, img)
    png = os.path.splitext(os.fspath(out_file))[0] + ".png"
    save_preview(img, png)
    return {"exr": os.fspath(out_file), "png": png, "seconds": time.perf_counter() - t0}
