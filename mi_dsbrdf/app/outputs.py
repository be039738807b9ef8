"""Result files beyond the parameters: the re-render scene and the previews.

* :func:`write_scene_xml` rewrites the input scene with the recovered material
  and light (Mitsuba's own parser and writer, so everything else in the scene
  is kept as the user wrote it);
* :func:`material_preview` shows a material on spheres under several lights;
* :func:`illumination_preview` shows a lat-long map with its unseen texels marked.
"""
from __future__ import annotations

import os

import mitsuba as mi
import numpy as np

from mi_dsbrdf.app.io import save_preview
from mi_dsbrdf.app.scenes import camera
from mi_dsbrdf.inference.latlong import procedural_sky


def write_scene_xml(source, out_file, light, material_file) -> None:
    """Write ``out_file``: the scene ``source`` (an XML path or a scene dict) with
    its ``dsbrdf`` object reading ``material_file`` and its light replaced by
    ``light``: {"type": "envmap", "filename"} | {"type": "directional",
    "direction", "intensity"} | {"type": "point", "position", "intensity"}
    (direction: object -> light). File names in the written scene are relative
    to the folder of ``material_file`` (the result's folder); relative file names
    of the input scene (meshes, textures) are made absolute so that the new scene
    loads from its own folder."""
    config = mi.parser.ParserConfig(mi.variant())
    if isinstance(source, dict):
        base, state = os.getcwd(), mi.parser.parse_dict(config, source)
    else:
        base = os.path.dirname(os.path.abspath(os.fspath(source)))
        state = mi.parser.parse_file(config, os.fspath(source))
    folder = os.path.dirname(os.path.abspath(material_file))
    for node in state.nodes:
        props = node.props
        if props.plugin_name() in ("dsbrdf", "merl") and node.type == mi.ObjectType.Unknown:
            node.type = mi.ObjectType.BSDF         # a dict names no tag, and the parser knows no Python plugin
        if node.type == mi.ObjectType.BSDF and props.plugin_name() == "dsbrdf":
            for key in list(props.keys()):
                del props[key]
            props["filename"] = os.path.relpath(material_file, folder)
        elif node.type == mi.ObjectType.Emitter:
            for key in list(props.keys()):
                if key != "to_world" or light["type"] != "envmap":
                    del props[key]
            props.set_plugin_name(light["type"])
            if light["type"] == "envmap":
                props["filename"] = os.path.relpath(light["filename"], folder)
            elif light["type"] == "directional":
                props["direction"] = mi.ScalarVector3f(*(-float(v) for v in light["direction"]))
                props["irradiance"] = mi.ScalarColor3f(*([float(light["intensity"])] * 3))
            else:
                props["position"] = mi.ScalarPoint3f(*(float(v) for v in light["position"]))
                props["intensity"] = mi.ScalarColor3f(*([float(light["intensity"])] * 3))
        elif "filename" in props.keys():
            name = props["filename"]
            if not os.path.isabs(name) and os.path.exists(os.path.join(base, name)):
                props["filename"] = os.path.join(base, name)
    mi.parser.write_file(state, os.fspath(out_file))


def material_preview(material_file, path, res=96, spp=64) -> None:
    """PNG of the material on three spheres (Mitsuba, ``direct`` integrator): lit
    from the upper left, from the side (grazing angles) and by the shipped
    procedural sky."""
    lights = [{"type": "directional", "direction": [0.5, -0.6, -0.62], "irradiance": {"type": "rgb", "value": 2.0}},
              {"type": "directional", "direction": [-1.0, -0.3, 0.1], "irradiance": {"type": "rgb", "value": 2.0}},
              {"type": "envmap", "bitmap": mi.Bitmap(procedural_sky(64, 128))}]
    tiles = []
    for light in lights:
        scene = mi.load_dict({
            "type": "scene", "integrator": {"type": "direct"},
            "sensor": camera(res, 30, box_filter=False),
            "object": {"type": "sphere", "bsdf": {"type": "dsbrdf", "filename": os.path.abspath(material_file)}},
            "light": light})
        tiles.append(np.array(mi.render(scene, spp=spp, seed=0), dtype=np.float32))
    save_preview(np.concatenate(tiles, axis=1), path)


def illumination_preview(log_map_or_map, path, seen=None, scale=8) -> None:
    """PNG of a lat-long map (nearest-neighbour enlarged ``scale`` times), its
    exposure set by the median of the seen texels; unseen texels hatched grey."""
    L = np.asarray(log_map_or_map, dtype=np.float64)
    seen = np.ones(L.shape[:2], bool) if seen is None else np.asarray(seen, bool)
    med = np.median(L[seen].mean(axis=-1)) if seen.any() else 1.0
    img = L / max(med, 1e-30) * 0.25
    H, W = seen.shape
    hatch = ((np.arange(H)[:, None] + np.arange(W)[None]) % 2 == 0)[..., None] * 0.2 + 0.1
    img = np.where(seen[..., None], img, hatch)
    img = np.repeat(np.repeat(img, scale, axis=0), scale, axis=1)
    save_preview(img.astype(np.float32), path)
