"""Forward rendering of scenes to EXR with PNG previews."""
from __future__ import annotations

import os
import tempfile
import time

import mitsuba as mi
import numpy as np

from mi_dsbrdf.app.io import check_radiance, save_preview, staged_file, write_exr
from mi_dsbrdf.app.scenes import camera, shape_dict
from mi_dsbrdf.brdf.dsbrdf import Material
from mi_dsbrdf.errors import InputError
from mi_dsbrdf.inference.images import read_image
from mi_dsbrdf.model.library import library_names


def render_scene(scene_file, spp=None, **params) -> np.ndarray:
    """Render a scene XML (with ``<default>`` overrides ``params``) to (H, W, 3)
    float32, at ``spp`` samples per pixel (None: the scene's own)."""
    if spp is not None:
        _positive(spp, "--spp")
    try:
        scene = mi.load_file(os.fspath(scene_file), **{k: str(v) for k, v in params.items()})
    except Exception as e:  # noqa: BLE001  (Mitsuba raises RuntimeError subclasses with varied text)
        raise InputError("scene %s does not load: %s" % (scene_file, str(e).splitlines()[-1])) from None
    if not scene.sensors():
        raise InputError("scene %s has no camera: add a <sensor>" % scene_file)
    size = scene.sensors()[0].film().crop_size()
    if min(int(size[0]), int(size[1])) < 1:
        raise InputError("scene %s has a %dx%d film: give a film of at least 1x1 pixels"
                         % (scene_file, size[0], size[1]))
    img = np.array(mi.render(scene, spp=spp or 0), dtype=np.float32)
    bad = ~np.isfinite(img)
    if bad.any():
        raise InputError("render of %s has %d non-finite pixels: check its emitters and textures for NaN/Inf"
                         % (scene_file, int(bad.any(axis=2).sum())))
    return img


def render_to_files(scene_file, out, spp=None, force=False, **params) -> dict:
    """Render into the folder ``out`` (made when the render succeeded):
    ``<scene name>.exr`` and ``.png``, replacing earlier ones only with ``force``;
    returns paths and time."""
    stem = os.path.join(os.fspath(out), os.path.splitext(os.path.basename(os.fspath(scene_file)))[0])
    if os.path.exists(out) and not os.path.isdir(out):
        raise InputError("output %s is a file, not a folder: choose a folder name" % out)
    for f in (stem + ".exr", stem + ".png"):
        if os.path.exists(f) and not force:
            raise InputError("%s exists; pass --force to replace it" % f)
    t0 = time.perf_counter()
    img = render_scene(scene_file, spp=spp, **params)
    seconds = time.perf_counter() - t0
    made = not os.path.exists(out)
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise InputError("cannot make the output folder %s: %s" % (out, e.strerror)) from None
    try:
        write_files(img, stem + ".exr", force)
    except BaseException:
        if made and not os.listdir(out):
            os.rmdir(out)               # an error or an interruption leaves no empty folder behind
        raise
    return {"exr": stem + ".exr", "png": stem + ".png", "seconds": seconds}


def write_files(img, exr, force=False) -> str:
    """Write ``img`` as the EXR ``exr`` and an sRGB PNG beside it, each through a
    temporary file moved into place (an error leaves neither half-written);
    returns the PNG's path."""
    png = os.path.splitext(os.fspath(exr))[0] + ".png"
    tmp_exr, tmp_png = staged_file(exr, force), staged_file(png, force)
    try:
        write_exr(tmp_exr, img)
        save_preview(img, tmp_png)
        os.replace(tmp_exr, exr)
        os.replace(tmp_png, png)
    finally:
        for f in (tmp_exr, tmp_png):
            if os.path.exists(f):
                os.remove(f)
    return png


def relight(material, out_file, envmap=None, shape="sphere", scene=None, shape_id=None, res=256, spp=64,
            force=False, samples=0) -> dict:
    """Render a recovered (or library) material and write ``out_file`` (EXR) and a PNG beside it.

    Either on ``shape`` (``sphere``, ``torus`` or a .ply/.obj mesh) under the
    lat-long map ``envmap`` with Mitsuba's path tracer (a ``res`` x ``res`` film),
    or in the user's own ``scene`` XML with the material on its shape of id
    ``shape_id`` (its camera, film, integrator and lights as written; ``res`` is
    not used). ``material``: a material.json or a library name. With ``samples``
    N > 0 (a recovered material, which carries its posterior), also N renders of
    posterior materials (:meth:`~mi_dsbrdf.brdf.dsbrdf.Material.sample`), and
    their per-pixel standard deviation written as ``<out>_std.exr`` and a PNG
    beside it. The files appear only when every render succeeded.
    """
    check_exr_name(out_file)
    bsdf = material_dict(material)
    spp = _positive(spp, "spp")
    if samples:
        samples = _positive(samples, "samples")
        if not os.path.exists(os.fspath(material)):
            raise InputError("--samples needs a recovered material.json, which carries its posterior; %s is a "
                             "library material" % os.fspath(material))
        draws = Material.load(material).sample(samples)
    if scene is not None:
        if envmap is not None:
            raise InputError("give an envmap or a scene, not both: the scene brings its own lights")
        if shape_id is None:
            raise InputError("a scene needs --shape-id: the id of the shape that gets the material")

        def scene_of(b):
            return scene_with_material(scene, shape_id, b)
    else:
        if envmap is None:
            raise InputError("give an envmap (a lat-long HDR/EXR map) or a scene to relight in")
        if shape_id is not None:
            raise InputError("--shape-id names a shape of --scene; under --envmap the shape is --shape "
                             "(sphere, torus or a mesh file)")
        res = _positive(res, "res")
        check_envmap(envmap)

        def scene_of(b):
            return mi.load_dict({
                "type": "scene", "integrator": {"type": "path", "max_depth": 4},
                "sensor": camera(res, 32, box_filter=False),
                "object": shape_dict(shape, b), "emitter": {"type": "envmap",
                                                           "filename": os.path.abspath(os.fspath(envmap))}})
    std_file = os.path.splitext(os.fspath(out_file))[0] + "_std.exr"
    for f in (out_file, std_file) if samples else (out_file,):
        for g in (f, os.path.splitext(f)[0] + ".png"):
            staged_file(g, force)           # checked before the render
    t0 = time.perf_counter()
    img = _render_finite(scene_of(bsdf), spp)
    std = None
    if samples:
        # the posterior's spread: every sample rendered with its own material file and
        # the same seed, so that the spread is the material's, not Monte Carlo noise
        with tempfile.TemporaryDirectory() as tmp:
            renders = []
            for i, m in enumerate(draws):
                path = os.path.join(tmp, "sample%d.json" % i)
                m.save(path)
                renders.append(_render_finite(scene_of({"type": "dsbrdf", "filename": path}), spp))
        std = np.std(np.stack(renders), axis=0).astype(np.float32)
    seconds = time.perf_counter() - t0
    png = write_files(img, out_file, force)
    out = {"exr": os.fspath(out_file), "png": png, "seconds": seconds}
    if std is not None:
        out.update(std_exr=std_file, std_png=write_files(std, std_file, force))
    return out


def _render_finite(scene, spp) -> np.ndarray:
    """Mitsuba's render (seed 0) as float32 (InputError if any pixel is not finite)."""
    img = np.array(mi.render(scene, spp=spp), dtype=np.float32)
    if not np.all(np.isfinite(img)):
        raise InputError("relighting produced non-finite pixels: the material or the map holds values "
                         "too large to render")
    return img


def check_exr_name(out_file) -> None:
    """InputError unless ``out_file`` names an EXR file (``.exr``): the image is
    float radiance, and its PNG preview takes the same name with ``.png``."""
    if os.path.splitext(os.fspath(out_file))[1].lower() != ".exr":
        raise InputError("output %s: give a file name ending in .exr (the PNG preview is written beside it)"
                         % os.fspath(out_file))


def material_dict(material) -> dict:
    """The ``dsbrdf`` plugin dict of a material.json or a library name, the
    material loaded and checked here first (one-line MaterialError/InputError)."""
    path = os.fspath(material)
    if os.path.exists(path):
        Material.load(path)
        return {"type": "dsbrdf", "filename": os.path.abspath(path)}
    if path in library_names():
        return {"type": "dsbrdf", "material": path}
    raise InputError("material %s is neither a file nor a library material" % path)


def check_envmap(path) -> None:
    """InputError unless ``path`` is a lat-long map of finite, non-negative radiance:
    twice as wide as high (within 1 %) and at least 4x2 texels."""
    L = read_image(path, what="envmap")
    check_radiance(L, "envmap %s" % os.fspath(path), unit="texel")
    h, w = L.shape[:2]
    if h < 2 or abs(w - 2 * h) > 0.02 * h:
        raise InputError("envmap %s is %dx%d: a lat-long map is twice as wide as high, at least 4x2"
                         % (os.fspath(path), w, h))


def scene_with_material(scene_file, shape_id, bsdf) -> "mi.Scene":
    """The user's scene XML with the shape of id ``shape_id`` given the BSDF ``bsdf``
    (a plugin dict); its other objects, including a BSDF it shared, are unchanged."""
    if not os.path.isfile(os.fspath(scene_file)):
        raise InputError("scene file %s does not exist" % os.fspath(scene_file))
    config = mi.parser.ParserConfig(mi.variant())
    try:
        state = mi.parser.parse_file(config, os.fspath(scene_file))
        mi.parser.transform_all(config, state)      # references resolved, as instantiate needs them
    except Exception as e:  # noqa: BLE001  (Mitsuba raises RuntimeError subclasses with varied text)
        raise InputError("scene %s does not parse: %s" % (scene_file, str(e).splitlines()[-1])) from None
    shapes = [i for i, n in enumerate(state.nodes) if n.type == mi.ObjectType.Shape]
    ids = [state.nodes[i].props.id() for i in shapes]
    if shape_id not in ids:
        raise InputError("scene %s has no shape with id %r; its shapes' ids: %s" % (
            scene_file, shape_id, ", ".join(repr(i) for i in ids if i) or "none (add id=\"...\" to a shape)"))
    index = shapes[ids.index(shape_id)]

    def target(props, key):
        """Index of the node a reference of ``props`` names (by id or resolved), or None."""
        kind = props.type(key)
        if kind == mi.Properties.Type.ResolvedReference:
            return props[key].index()
        if kind == mi.Properties.Type.Reference:
            return state.id_to_index.get(props[key].id())
        return None
    props = state.nodes[index].props
    for key in list(props.keys()):      # drop the shape's own BSDF reference (a shared BSDF stays for the others)
        i = target(props, key)
        if i is not None and state.nodes[i].type == mi.ObjectType.BSDF:
            del props[key]
    node = mi.parser.SceneNode()
    node.type = mi.ObjectType.BSDF
    node.props = mi.Properties("dsbrdf")
    for key, value in bsdf.items():
        if key != "type":
            node.props[key] = value
    state.nodes.append(node)
    # fetched again: appending may move the nodes, and a reference taken before would dangle
    state.nodes[index].props["bsdf_relit"] = mi.Properties.ResolvedReference(len(state.nodes) - 1)
    try:
        return mi.parser.instantiate(config, state)
    except Exception as e:  # noqa: BLE001
        raise InputError("scene %s does not load: %s" % (scene_file, str(e).splitlines()[-1])) from None


def _positive(value, name) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= 16384:
        raise InputError("%s must be an integer from 1 to 16384, got %r" % (name, value))
    return value
