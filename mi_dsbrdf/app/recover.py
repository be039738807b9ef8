"""``mi-dsbrdf recover``: scene + image -> checked inputs -> inference -> result files.

Result directory (the stable output contract):

    material.json       DSBRDF parameters (``dsbrdf`` plugin ``filename``, ``load_material``)
    illumination.exr    lat-long map, Mitsuba envmap convention (unseen texels black)   (envmap scenes)
    light.json          {"type", "direction": unit vector object -> light, "intensity"
                         (irradiance, or W/sr for a point light, which also has "position")}
    scene.xml           the input scene with the recovered material and light
    log.json            what the scene needed and why, every round's posterior terms and time
    input.png, rerender.png, residual.png, material.png (spheres), illumination.png    previews
"""
from __future__ import annotations

import json
import os
import time

import numpy as np

from mi_dsbrdf.errors import MiDsbrdfError


class InputError(MiDsbrdfError):
    """Bad user input: the message says what and where."""


def read_image(path) -> np.ndarray:
    """(H, W, 3) float64 from an EXR/HDR/PNG file; InputError if missing or unreadable."""
    import mitsuba as mi
    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError("image %s does not exist" % path)
    try:
        bmp = mi.Bitmap(path)
    except Exception as e:  # noqa: BLE001  (Mitsuba raises RuntimeError subclasses with varied text)
        raise InputError("image %s is unreadable: %s" % (path, str(e).splitlines()[-1])) from None
    a = np.array(bmp, dtype=np.float64)
    if a.ndim == 2:
        a = a[..., None]
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    return a[..., :3]


def read_mask(path, shape) -> np.ndarray:
    """(H, W) bool: pixels brighter than half the mask file's maximum (PNG 0-255 or float)."""
    a = read_image(path).mean(axis=2)
    m = a > 0.5 * a.max() if a.max() > 0 else np.zeros(a.shape, bool)
    if m.shape != shape:
        raise InputError("mask %s is %dx%d but the image is %dx%d" % (path, m.shape[1], m.shape[0], shape[1], shape[0]))
    if not m.any():
        raise InputError("mask %s is empty: no pixel to recover from" % path)
    return m


def check_image(image, film_size, path="image") -> None:
    """InputError for size mismatch, non-finite, negative or all-black images."""
    h, w = image.shape[:2]
    if (w, h) != tuple(film_size):
        raise InputError("%s is %dx%d but the scene's film is %dx%d" % (path, w, h, film_size[0], film_size[1]))
    bad = ~np.isfinite(image)
    if bad.any():
        raise InputError("%s has %d NaN/Inf values (first at pixel %s)" % (
            path, int(bad.sum()), tuple(int(v) for v in np.argwhere(bad)[0][:2][::-1])))
    if (image < 0).any():
        raise InputError("%s has %d negative values: an HDR image of radiance is >= 0" % (path, int((image < 0).sum())))
    if not (image > 0).any():
        raise InputError("%s is black everywhere: nothing to recover" % path)


def saturated(image) -> np.ndarray:
    """(H, W) bool: pixels on a clipping plateau (a channel at the image's maximum,
    shared by at least 4 pixels); a lone brightest pixel is a highlight, not clipping."""
    top = image.max()
    at_top = np.any(image >= top * (1 - 1e-6), axis=2)
    return at_top if at_top.sum() >= 4 else np.zeros(at_top.shape, bool)


def prepare_out(path, force) -> None:
    if os.path.exists(path) and os.listdir(path) and not force:
        raise InputError("output directory %s exists and is not empty; pass --force to write into it" % path)
    os.makedirs(path, exist_ok=True)


def recover_files(scene_file, image_file, out, mask_file=None, force=False, map_size=(32, 64), rounds=3,
                  iters=15, progress=True) -> dict:
    """Run the whole recovery and write the result directory; returns the log dict."""
    import mitsuba as mi

    from mi_dsbrdf.inference import envmap as inference
    from mi_dsbrdf.model import model_file as model_data
    from mi_dsbrdf.brdf.dsbrdf import Material
    from mi_dsbrdf.inference.forward import TexelSum
    from mi_dsbrdf.inference.latlong import write_exr
    from mi_dsbrdf.app.outputs import illumination_preview, material_preview, write_scene_xml
    from mi_dsbrdf.app.render import save_preview
    from mi_dsbrdf.inference.scene_needs import decide, dsbrdf_object
    for f, what in ((scene_file, "scene"), (image_file, "image")):
        if not os.path.exists(f):
            raise InputError("%s file %s does not exist" % (what, f))
    image = read_image(image_file)
    try:
        scene = mi.load_file(os.fspath(scene_file))
    except Exception as e:  # noqa: BLE001
        raise InputError("scene %s does not load: %s" % (scene_file, str(e).splitlines()[-1])) from None
    film = scene.sensors()[0].film().crop_size()
    check_image(image, (int(film[0]), int(film[1])), image_file)
    mask = read_mask(mask_file, image.shape[:2]) if mask_file else None
    prepare_out(out, force)
    model = model_data.shipped_model()
    needs = decide(scene, image, mask, model.basis.n_lobes, model.basis.n_bases)
    obj = dsbrdf_object(scene)
    ts = TexelSum(scene, obj, map_size if needs.envmap_block else (1, 1), visibility=needs.visibility)
    keep = ts.mask.copy()
    # silhouette pixels also see the background: use interior pixels only
    for axis in (0, 1):
        for shift in (1, -1):
            keep &= np.roll(ts.mask, shift, axis=axis)
    if mask is not None:
        keep &= mask
    keep &= ~saturated(image)
    if not keep.any():
        raise InputError("no usable pixel: the object covers no interior, unsaturated pixel inside the mask")
    cfg = inference.Config(map_size=tuple(map_size), max_rounds=rounds, block_iters=iters)
    t0 = time.perf_counter()
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(desc="recover", unit="round")

    def report(row):
        if bar is not None:
            bar.set_postfix(nlp="%.4g" % row["neg_log_posterior"], refresh=False)
            bar.update()

    if needs.envmap_block:
        state, rows = inference.recover(ts, image, keep, model, cfg, colour=needs.colour_pass, progress=report)
        psi, chroma = state.psi, state.chromaticity
        seen = state.log_map[..., 0] > inference.BLACK
        L = np.where(seen[..., None], np.exp(state.log_map), 0.0)      # unseen texels: black
        light = {"type": "envmap", "filename": os.path.join(out, "illumination.exr")}
        write_exr(light["filename"], L)
        illumination_preview(L, os.path.join(out, "illumination.png"), seen=seen)
    else:
        point = None
        if needs.light == "point":
            point = (_centre(obj), point_light_distance(scene, obj))
        res, rows = inference.recover_light(ts, image, keep, model, cfg, progress=report, point=point)
        psi, chroma = res["psi"], res["chromaticity"]
        light = {"type": needs.light, "direction": [float(v) for v in res["direction"]],
                 "intensity": res["intensity"]}
        if point is not None:
            light["position"] = [float(v) for v in res["position"]]
            ts.set_point(res["position"])
        else:
            ts.set_directions(np.asarray(res["direction"])[None], [1.0])
        with open(os.path.join(out, "light.json"), "w") as f:
            json.dump(light, f, indent=1)
        L = np.full((1, 3), res["intensity"])
    if bar is not None:
        bar.close()
    material = Material.from_basis(model.basis, psi, chroma, name="recovered")
    material_file = os.path.join(out, "material.json")
    material.save(material_file)
    write_scene_xml(scene_file, os.path.join(out, "scene.xml"), material_file, light)
    material_preview(material_file, os.path.join(out, "material.png"))
    # previews: input, re-render with the recovered parameters, residual
    ts.bsdf = mi.load_dict({"type": "dsbrdf", "filename": os.path.join(out, "material.json")})
    rerender = np.zeros_like(image)
    rerender.reshape(-1, 3)[ts.pixels] = ts.render(L.reshape(-1, 3))
    save_preview(image.astype(np.float32), os.path.join(out, "input.png"))
    save_preview(rerender.astype(np.float32), os.path.join(out, "rerender.png"))
    resid = np.abs(np.log(rerender + 1e-3 * image.mean()) - np.log(image + 1e-3 * image.mean()))
    save_preview((resid * keep[..., None]).astype(np.float32), os.path.join(out, "residual.png"))
    log = {"scene": os.fspath(scene_file), "image": os.fspath(image_file), "needs": list(needs.reasons),
           "rounds": rows, "seconds": time.perf_counter() - t0, "light": light,
           "unseen_texels": rows[-1].get("unseen_texels") if rows else None}
    with open(os.path.join(out, "log.json"), "w") as f:
        json.dump(log, f, indent=1, default=float)
    return log


def _centre(shape) -> np.ndarray:
    bbox = shape.bbox()
    return (np.array(bbox.min, dtype=np.float64) + np.array(bbox.max, dtype=np.float64)) / 2


def point_light_distance(scene, shape) -> float:
    """Distance of the scene's point light from the object's centre: inference
    recovers the light's direction and intensity and keeps this distance (one
    image barely constrains it); InputError if the light is inside the object."""
    import mitsuba as mi
    position = np.array(mi.traverse(scene.emitters()[0])["position"], dtype=np.float64).reshape(3)
    centre = _centre(shape)
    bbox = shape.bbox()
    radius = 0.5 * np.linalg.norm(np.array(bbox.max, dtype=np.float64) - np.array(bbox.min, dtype=np.float64))
    distance = float(np.linalg.norm(position - centre))
    if distance <= radius:
        raise InputError("the point light at %s is inside the object's bounding sphere (radius %.3g around %s): "
                         "place it outside" % (position.tolist(), radius, centre.tolist()))
    return distance
