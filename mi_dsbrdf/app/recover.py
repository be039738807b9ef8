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

import mitsuba as mi
import numpy as np
from tqdm import tqdm

from mi_dsbrdf.app.io import check_image, prepare_out, read_image, read_mask, saturated, save_preview, write_exr
from mi_dsbrdf.app.outputs import illumination_preview, material_preview, write_scene_xml
from mi_dsbrdf.config import Config
from mi_dsbrdf.errors import InputError
from mi_dsbrdf.inference.envmap import recover_envmap
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.inference.light import recover_light
from mi_dsbrdf.inference.scene_needs import decide, dsbrdf_object
from mi_dsbrdf.model.model_file import shipped_model


def recover_files(scene_file, image_file, out, mask_file=None, force=False, config: Config = None,
                  progress=True) -> dict:
    """Run the whole recovery and write the result directory; returns the log dict."""
    cfg = config or Config()
    for f, what in ((scene_file, "scene"), (image_file, "image")):
        if not os.path.exists(f):
            raise InputError("%s file %s does not exist" % (what, f))
    image = read_image(image_file)
    try:
        scene = mi.load_file(os.fspath(scene_file))
    except Exception as e:  # noqa: BLE001  (Mitsuba raises RuntimeError subclasses with varied text)
        raise InputError("scene %s does not load: %s" % (scene_file, str(e).splitlines()[-1])) from None
    film = scene.sensors()[0].film().crop_size()
    check_image(image, (int(film[0]), int(film[1])), image_file)
    mask = read_mask(mask_file, image.shape[:2]) if mask_file else None
    prepare_out(out, force)
    model = shipped_model()
    needs = decide(scene, image, mask, model.basis.n_lobes, model.basis.n_bases)
    obj = dsbrdf_object(scene)
    ts = TexelSum(scene, obj, cfg.map_size if needs.envmap_block else (1, 1), visibility=needs.visibility)
    keep = interior(ts.mask)
    if mask is not None:
        keep &= mask
    keep &= ~saturated(image)
    if not keep.any():
        raise InputError("no usable pixel: the object covers no interior, unsaturated pixel inside the mask")
    bar = tqdm(desc="recover", unit="round") if progress else None

    def report(row):
        if bar is not None:
            bar.set_postfix(nlp="%.4g" % row["neg_log_posterior"], refresh=False)
            bar.update()

    if needs.envmap_block:
        result = recover_envmap(ts, image, keep, model, cfg, colour=needs.colour_pass, progress=report)
        light = {"type": "envmap", "filename": os.path.join(out, "illumination.exr")}
        write_exr(light["filename"], result.illumination)
        illumination_preview(result.illumination, os.path.join(out, "illumination.png"), seen=result.seen)
        lit, L = ts, result.illumination.reshape(-1, 3)
    else:
        point = None
        if needs.light == "point":
            point = (centre(obj), point_light_distance(scene, obj))
        result = recover_light(ts, image, keep, model, cfg, progress=report, point=point)
        light = {"type": needs.light, "direction": [float(v) for v in result.light["direction"]],
                 "intensity": result.light["intensity"]}
        if point is not None:
            light["position"] = [float(v) for v in result.light["position"]]
            lit = ts.with_point(result.light["position"])
        else:
            lit = ts.with_directions(np.asarray(result.light["direction"])[None], [1.0])
        with open(os.path.join(out, "light.json"), "w") as f:
            json.dump(light, f, indent=1)
        L = np.full((1, 3), result.light["intensity"])
    if bar is not None:
        bar.close()
    material_file = os.path.join(out, "material.json")
    result.material.save(material_file)
    write_scene_xml(scene_file, os.path.join(out, "scene.xml"), material_file, light)
    material_preview(material_file, os.path.join(out, "material.png"))
    # previews: input, re-render with the recovered parameters, residual
    lit = lit.with_bsdf(mi.load_dict({"type": "dsbrdf", "filename": material_file}))
    rerender = np.zeros_like(image)
    rerender.reshape(-1, 3)[lit.pixels] = lit.render(L)
    save_preview(image.astype(np.float32), os.path.join(out, "input.png"))
    save_preview(rerender.astype(np.float32), os.path.join(out, "rerender.png"))
    resid = np.abs(np.log(rerender + 1e-3 * image.mean()) - np.log(image + 1e-3 * image.mean()))
    save_preview((resid * keep[..., None]).astype(np.float32), os.path.join(out, "residual.png"))
    rows = result.log
    log = {"scene": os.fspath(scene_file), "image": os.fspath(image_file), "needs": list(needs.reasons),
           "rounds": rows, "seconds": result.seconds, "light": light,
           "unseen_texels": rows[-1].get("unseen_texels") if rows else None}
    with open(os.path.join(out, "log.json"), "w") as f:
        json.dump(log, f, indent=1, default=float)
    return log


def interior(mask) -> np.ndarray:
    """(H, W) bool: pixels of ``mask`` whose four neighbours are in it too
    (silhouette pixels also see the background)."""
    keep = mask.copy()
    for axis in (0, 1):
        for shift in (1, -1):
            keep &= np.roll(mask, shift, axis=axis)
    return keep


def centre(shape) -> np.ndarray:
    """(3,) centre of a shape's bounding box."""
    bbox = shape.bbox()
    return (np.array(bbox.min, dtype=np.float64) + np.array(bbox.max, dtype=np.float64)) / 2


def point_light_distance(scene, shape) -> float:
    """Distance of the scene's point light from the object's centre: inference
    recovers the light's direction and intensity and keeps this distance (one
    image barely constrains it); InputError if the light is inside the object."""
    position = np.array(mi.traverse(scene.emitters()[0])["position"], dtype=np.float64).reshape(3)
    c = centre(shape)
    bbox = shape.bbox()
    radius = 0.5 * np.linalg.norm(np.array(bbox.max, dtype=np.float64) - np.array(bbox.min, dtype=np.float64))
    distance = float(np.linalg.norm(position - c))
    if distance <= radius:
        raise InputError("the point light at %s is inside the object's bounding sphere (radius %.3g around %s): "
                         "place it outside" % (position.tolist(), radius, c.tolist()))
    return distance
