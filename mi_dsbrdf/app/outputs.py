"""Result files beyond the parameters: the re-render scene and the previews.

* :func:`write_scene_xml` rewrites the input scene with the recovered material
  and light (Mitsuba's own parser and writer, so everything else in the scene
  is kept as the user wrote it);
* :func:`render_saved_scene` renders the written scene with Mitsuba, as a user
  will (``rerender.png``);
* :func:`material_preview` shows a material on spheres under several lights;
* :func:`illumination_preview` shows a lat-long map with its unseen texels marked.
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET

import mitsuba as mi
import numpy as np

from mi_dsbrdf.app.io import save_preview, srgb_bitmap
from mi_dsbrdf.app.scenes import camera
from mi_dsbrdf.brdf.dsbrdf import Material
from mi_dsbrdf.inference.latlong import procedural_sky


#: the integrator a saved scene gets when other surfaces' light onto the object was
#: fitted: Mitsuba's path tracer to the depth of one bounce off them
BOUNCE_INTEGRATOR = {"type": "path", "max_depth": 3}


def write_scene_xml(source, out_file, light, material_file, bounce=False) -> None:
    """Write ``out_file``: the scene ``source`` (an XML path or a scene dict) with
    its ``dsbrdf`` object reading ``material_file`` and its light replaced by
    ``light``: {"type": "envmap", "filename"} | {"type": "directional",
    "direction", "intensity"} | {"type": "point", "position", "intensity"}
    (direction: object -> light). File names in the written scene are relative
    to the folder of ``material_file`` (the result's folder); relative file names
    of the input scene (meshes, textures) are made absolute so that the new scene
    loads from its own folder. Objects keep their ids (a dict's: the keys of the
    scene's own entries), so that ``relight --shape-id`` finds them. With
    ``bounce`` (the light other surfaces reflect onto the object was fitted) the
    scene's integrator becomes :data:`BOUNCE_INTEGRATOR`, so that Mitsuba renders
    that light as the fit did."""
    config = mi.parser.ParserConfig(mi.variant())
    if isinstance(source, dict):
        base, state = os.getcwd(), mi.parser.parse_dict(config, source)
    else:
        base = os.path.dirname(os.path.abspath(os.fspath(source)))
        state = mi.parser.parse_file(config, os.fspath(source))
    folder = os.path.dirname(os.path.abspath(material_file))
    ids = _kept_ids(state, isinstance(source, dict))
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
        elif node.type == mi.ObjectType.Integrator and bounce:
            for key in list(props.keys()):
                del props[key]
            props.set_plugin_name(BOUNCE_INTEGRATOR["type"])
            props["max_depth"] = BOUNCE_INTEGRATOR["max_depth"]
        elif "filename" in props.keys():
            name = props["filename"]
            if not os.path.isabs(name) and os.path.exists(os.path.join(base, name)):
                props["filename"] = os.path.join(base, name)
    for i, name in ids.items():        # Mitsuba's writer drops ids: carried as a property, restored below
        state.nodes[i].props[_ID_PROPERTY] = name
    mi.parser.write_file(state, os.fspath(out_file))
    _restore_ids(out_file)


#: the property that carries an object's id through Mitsuba's XML writer
_ID_PROPERTY = "mi_dsbrdf_object_id"


def _kept_ids(state, from_dict) -> dict:
    """{node index: id} of the objects whose ids the written scene keeps: every
    id of a scene file; of a dict, the keys of the scene's own entries (a nested
    dict's key, "bsdf" or "film", is a property name, not an id)."""
    if from_dict:
        root = state.nodes[0].props
        indices = [root[k].index() for k in root.keys() if root.type(k) == mi.Properties.Type.ResolvedReference]
    else:
        indices = range(len(state.nodes))
    return {i: state.nodes[i].props.id() for i in indices if state.nodes[i].props.id()}


def _restore_ids(xml_file) -> None:
    """Turn each ``<string name=_ID_PROPERTY value=ID/>`` of ``xml_file`` into its
    parent's ``id="ID"``."""
    tree = ET.parse(xml_file)
    for parent in tree.iter():
        for child in list(parent):
            if child.tag == "string" and child.get("name") == _ID_PROPERTY:
                parent.remove(child)
                parent.set("id", child.get("value"))
                if not len(parent) and not (parent.text or "").strip():
                    parent.text = None
    ET.indent(tree, space="    ")
    tree.write(xml_file, encoding="unicode")


#: the preview render of the saved scene (:func:`render_saved_scene`): its longest side
#: at most PREVIEW_SIDE pixels, and about PREVIEW_SAMPLES camera rays in all (about a
#: second or two on a laptop's CPU), between MIN_SPP and MAX_SPP a pixel
PREVIEW_SIDE, PREVIEW_SAMPLES, MIN_SPP, MAX_SPP = 1024, 1 << 22, 4, 1024
#: the film's integer properties scaled with its size
_FILM_SIZES = ("width", "height", "crop_offset_x", "crop_offset_y", "crop_width", "crop_height")


def render_saved_scene(scene_file, side=PREVIEW_SIDE, samples=PREVIEW_SAMPLES) -> tuple:
    """Mitsuba's render of the scene ``scene_file`` (relative file names from its
    folder) with its own integrator, its film scaled so that the longest side of
    its crop is at most ``side`` pixels: ((h, w, 3) float32, spp), the samples per pixel
    chosen so that the render takes about ``samples`` camera rays (non-finite
    values are 0)."""
    config = mi.parser.ParserConfig(mi.variant())
    kept = mi.FileResolver(mi.file_resolver())
    resolver = mi.FileResolver(kept)
    resolver.prepend(os.path.dirname(os.path.abspath(os.fspath(scene_file))))
    mi.set_file_resolver(resolver)      # as mi.load_file does, for the scene's relative file names
    try:
        state = mi.parser.parse_file(config, os.fspath(scene_file))
        for node in state.nodes:
            if node.type == mi.ObjectType.Film:
                props = node.props
                size = {k: int(props[k]) for k in _FILM_SIZES if k in props.keys()}
                size.setdefault("width", 768)               # Mitsuba's film defaults
                size.setdefault("height", 576)
                longest = max(size.get("crop_width", size["width"]), size.get("crop_height", size["height"]))
                f = min(1.0, side / longest)
                for k, v in size.items():
                    props[k] = max(int(round(v * f)), 0 if k.startswith("crop_offset") else 1)
        mi.parser.transform_all(config, state)
        scene = mi.parser.instantiate(config, state)
    finally:
        mi.set_file_resolver(kept)
    crop = scene.sensors()[0].film().crop_size()
    spp = int(np.clip(samples // max(int(crop[0]) * int(crop[1]), 1), MIN_SPP, MAX_SPP))
    img = np.array(mi.render(scene, spp=spp, seed=0), dtype=np.float32)
    return np.where(np.isfinite(img), img, 0.0).astype(np.float32), spp


def material_preview(material_file, path, res=96, spp=64) -> None:
    """PNG of the material: on three spheres (Mitsuba, ``direct`` integrator) lit
    from the upper left, from the side (grazing angles) and by the shipped
    procedural sky; below them, with matplotlib, its BRDF against theta_h at
    three theta_d (:func:`brdf_slices`), with the posterior's 90 % band and the
    directions the image did not see shaded, when the material records them."""
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
    brdf_slices(Material.load(material_file), path, np.array(srgb_bitmap(np.concatenate(tiles, axis=1))))


#: the theta_d (degrees) of the BRDF slices in material.png
SLICE_THETA_D = (10.0, 45.0, 75.0)


def brdf_slices(material, path, top=None, level=0.9, n=128) -> None:
    """PNG: the material's BRDF (the mean of its channels, 1/sr, log scale)
    against theta_h at each of SLICE_THETA_D, with the ``level`` band of ``n``
    posterior samples (:meth:`~mi_dsbrdf.brdf.dsbrdf.Material.sample`) if the
    material has a covariance, and grey where the image it was recovered from did
    not look (:meth:`~mi_dsbrdf.brdf.dsbrdf.Material.observed` is 0); ``top``, an
    (h, w, 3) uint8 picture, above the plots. Hand-made plots are not worth it:
    matplotlib draws them."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    theta_h = np.radians(np.linspace(0.0, 90.0, 181) ** 2 / 90.0)          # dense near the highlight
    draws = material.sample(n) if material.covariance_factor is not None else []
    rows = 2 if top is not None else 1
    fig = plt.figure(figsize=(9.0, 3.2 * rows), dpi=100)
    if top is not None:
        ax = fig.add_subplot(rows, 1, 1)
        ax.imshow(top)
        ax.set_axis_off()
    for i, td_deg in enumerate(SLICE_THETA_D):
        ax = fig.add_subplot(rows, 3, 3 * (rows - 1) + i + 1)
        td = np.full_like(theta_h, np.radians(td_deg))
        x = np.degrees(theta_h)
        seen = material.observed(theta_h, td)
        if seen is not None:
            ax.fill_between(x, 0, 1, where=seen <= 0, color="0.88", step="mid", transform=ax.get_xaxis_transform(),
                            label="not seen by the image")
        if draws:
            values = np.stack([m.eval(theta_h, td).mean(axis=1) for m in draws])
            lo, hi = np.quantile(values, [(1 - level) / 2, (1 + level) / 2], axis=0)
            ax.fill_between(x, np.maximum(lo, 1e-6), np.maximum(hi, 1e-6), color="tab:blue", alpha=0.3,
                            label="%d %% posterior band" % round(100 * level))
        value = np.maximum(material.eval(theta_h, td).mean(axis=1), 1e-6)
        ax.plot(x, value, color="tab:blue", label="recovered")
        ax.set_yscale("log")
        # two decades either side of the answer: a band's tail (kappa at its bound) would flatten it
        ax.set_ylim(max(value.min() / 100, 1e-6), value.max() * 100)
        ax.set_xscale("function", functions=(np.sqrt, np.square))
        ax.set_xlim(0, 90)
        ax.set_xticks([0, 5, 20, 45, 90])
        ax.set_title("θd = %g°" % td_deg, fontsize=10)
        ax.set_xlabel("θh (degrees)")
        if i == 0:
            ax.set_ylabel("BRDF (1/sr), mean of RGB")
            ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(os.fspath(path))
    plt.close(fig)


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
