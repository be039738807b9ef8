"""What :func:`mi_dsbrdf.recover` returns, and the result directory it saves.

Result directory (the stable output contract, written by :meth:`Result.save`
and ``mi-dsbrdf recover``):

    material.json       DSBRDF parameters (``dsbrdf`` plugin ``filename``, ``load_material``), and
                        where the image looked in (theta_h, theta_d) (``Material.observed``)
    illumination.exr    lat-long map, Mitsuba envmap convention (unseen texels black), each
                        texel as an 8 x 8 block (latlong.TEXEL_BLOCK)                          (envmap scenes)
    illumination_std.exr  the posterior's standard deviation of the map's natural log, per
                        texel and channel, laid out as illumination.exr (unseen texels 0)      (envmap scenes)
    light.json          {"type", "direction": unit vector object -> light, "intensity"
                         (irradiance, or W/sr for a point light, which also has "position")}
    scene.xml           the input scene with the recovered material and light (when the
                        scene came from a file or a dict, not an ``mi.Scene``)
    log.json            the package version, the Config, the image and map sizes, what the scene
                        needed and why, every round's posterior terms and time, each stage's
                        (checks, inference, re-render, observed directions, save) time and
                        peak memory, and "flags": one line for each part of the answer the
                        photograph may not support (``Recovery.flags``)
    input.png, rerender.png, residual.png, material.png (spheres), illumination.png    previews:
                        rerender.png is scene.xml as Mitsuba renders it (its longest side at most
                        1024 pixels; log.json's "rerender_png" says how, and how far it lies from
                        the forward model's re-render), residual.png the |log| difference between
                        the forward model's re-render and the image over the pixels inference used

The folder is written whole or not at all (:func:`~mi_dsbrdf.app.io.staged_output`).
"""
from __future__ import annotations

import dataclasses
import json
import os
import resource
import sys
import time

import numpy as np

from mi_dsbrdf.app.io import save_preview, staged_output, write_exr
from mi_dsbrdf.app.outputs import illumination_preview, material_preview, render_saved_scene, write_scene_xml
from mi_dsbrdf.brdf.dsbrdf import Material
from mi_dsbrdf.inference.latlong import texel_blocks

#: every file a result directory can hold (``--force`` replaces only such a folder)
RESULT_FILES = ("material.json", "illumination.exr", "illumination_std.exr", "light.json", "scene.xml", "log.json",
                "input.png", "rerender.png", "residual.png", "material.png", "illumination.png")


def stage_row(since) -> dict:
    """{"seconds": wall time since ``since`` (a ``time.perf_counter()``),
    "peak_memory_mb": the process's peak resident memory so far (``ru_maxrss``)}:
    one stage of a recovery in log.json."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss          # KB on Linux, bytes on macOS
    return {"seconds": time.perf_counter() - since,
            "peak_memory_mb": peak / (1 << 20) if sys.platform == "darwin" else peak / 1024}


@dataclasses.dataclass(frozen=True)
class Result:
    """The recovered material and light of one image (plain fields, like scipy's results).

    Attributes
    ----------
    material : the recovered :class:`~mi_dsbrdf.brdf.dsbrdf.Material`, recording
        where the used pixels looked (:meth:`~mi_dsbrdf.brdf.dsbrdf.Material.observed`)
    light : {"type": "directional" | "point", "direction": (3,) unit vector from
        the object towards the light, "intensity": irradiance or W/sr,
        "position": (3,) for a point light}; None under an illumination map
    illumination : (H, W, 3) float64 lat-long radiance map (Mitsuba's envmap
        convention; texels no pixel sees are 0), or None for a point or
        directional light
    seen : (H, W) bool texels some observed pixel sees, or None
    log : {"version", "config" (the Config's fields), "image_size" [H, W],
        "map_size" [H, W] (None without a map), "stages" {"checks", "inference",
        "re-render", "observed directions", and "highlight place" when a highlight is flagged:
        {"seconds", "peak_memory_mb"}} ("save" is added in log.json),
        "needs": one line per decision about the scene, "rounds": one dict per
        logged round (posterior terms, seconds), "seconds", "residual" (the
        re-render's relative L1 from the image over the used pixels),
        "highlight_doubt" (``Recovery``'s), "flags" (``Recovery.flags``, a doubted
        highlight with the place on the object it lights), "highlight_change" and
        "highlight_texels" (under a map: ``Recovery``'s), ...}; log.json adds
        "rerender_png": how rerender.png was rendered ({"renderer": "mitsuba", "spp",
        "size", "mitsuba_vs_rerender" (relative L1 over the used pixels, with
        Mitsuba's noise)} or {"renderer": "forward model"})
    image : (H, W, 3) float64 observed image (linear); used : (H, W) bool, the
        pixels inference used (an image larger than ``Config.working_pixels``: the
        pixels of the used blocks, :mod:`~mi_dsbrdf.app.working_grid`); rerender :
        (H, W, 3) float64, the image under the recovered material and light (the
        inference's forward model; a larger image's is rendered on the working grid,
        each block's value on its pixels that see the object)
    scene_source : the scene file (str) or dict it came from, rewritten into
        ``scene.xml`` by :meth:`save`; None for an ``mi.Scene``
    illumination_std : (H, W, 3) float64, the posterior's standard deviation of
        log ``illumination`` per texel (0 where no pixel sees), or None
    """
    material: Material
    light: dict
    illumination: np.ndarray
    seen: np.ndarray
    log: dict
    image: np.ndarray
    used: np.ndarray
    rerender: np.ndarray
    scene_source: object = None
    illumination_std: np.ndarray = None

    @property
    def seconds(self) -> float:
        return float(self.log["seconds"])

    def save(self, out, force=False, inputs=()) -> str:
        """Write the result directory ``out`` (see the module doc) and return its path.

        ``out`` must not exist or be empty, or, with ``force``, hold an earlier
        result (nothing else); ``inputs`` are files that must not lie inside it.
        Written into a fresh folder that replaces ``out`` at the end: an error
        or an interruption leaves ``out`` as it was.
        """
        out = os.path.abspath(os.fspath(out))
        sources = tuple(inputs) + ((self.scene_source,) if isinstance(self.scene_source, (str, os.PathLike)) else ())
        with staged_output(out, force, RESULT_FILES, sources) as tmp:
            self._write(tmp, out)
        return out

    def _write(self, tmp, out):
        """Files into ``tmp``; paths inside them name their final folder ``out``;
        log.json last, with the time and memory of writing the others."""
        began = time.perf_counter()
        material_file = os.path.join(tmp, "material.json")
        self.material.save(material_file)
        if self.illumination is not None:
            write_exr(os.path.join(tmp, "illumination.exr"), texel_blocks(self.illumination))
            if self.illumination_std is not None:
                write_exr(os.path.join(tmp, "illumination_std.exr"), texel_blocks(self.illumination_std))
            illumination_preview(self.illumination, os.path.join(tmp, "illumination.png"), seen=self.seen)
            light = {"type": "envmap", "filename": os.path.join(out, "illumination.exr")}
        else:
            light = self.light
            with open(os.path.join(tmp, "light.json"), "w") as f:
                json.dump(light, f, indent=1)
        if self.scene_source is not None:
            write_scene_xml(self.scene_source, os.path.join(tmp, "scene.xml"), light,
                            material_file=os.path.join(out, "material.json"),
                            bounce=bool(self.log.get("bounce_surfaces")))
        material_preview(material_file, os.path.join(tmp, "material.png"))
        save_preview(self.image.astype(np.float32), os.path.join(tmp, "input.png"))
        # rerender.png: the written scene.xml as Mitsuba renders it, what a user will get;
        # without a scene file, or if Mitsuba cannot render it, the forward model's re-render
        img, preview = self.rerender, {"renderer": "forward model"}
        if self.scene_source is not None:
            try:
                mitsuba, spp = render_saved_scene(os.path.join(tmp, "scene.xml"))
                img, preview = mitsuba, {"renderer": "mitsuba", "spp": spp, "size": list(mitsuba.shape[:2])}
                if mitsuba.shape == self.image.shape:
                    preview["mitsuba_vs_rerender"] = relative_residual(self.rerender, mitsuba, self.used)
            except Exception as e:  # noqa: BLE001  (a preview never costs the result)
                preview["mitsuba_error"] = str(e).splitlines()[-1] if str(e) else type(e).__name__
        save_preview(np.asarray(img, np.float32), os.path.join(tmp, "rerender.png"))
        eps = 1e-3 * self.image.mean()
        resid = np.empty(self.image.shape, np.float32)
        for r in range(0, resid.shape[0], 256):            # in bands of rows: a photograph's size in float64 once
            rows = slice(r, r + 256)
            resid[rows] = np.abs(np.log(self.rerender[rows] + eps) - np.log(self.image[rows] + eps)) \
                * self.used[rows, ..., None]
        save_preview(resid, os.path.join(tmp, "residual.png"))
        with open(os.path.join(tmp, "log.json"), "w") as f:
            stages = dict(self.log.get("stages", {}), save=stage_row(began))
            json.dump(dict(self.log, light=light, stages=stages, rerender_png=preview), f, indent=1, default=float)


def relative_residual(image, rerender, used, band=256) -> float:
    """How far the re-render is from the image over the ``used`` pixels (H, W):
    sum |rerender - image| / sum |image| (relative L1), in bands of rows."""
    num = den = 0.0
    for r in range(0, image.shape[0], band):
        u = used[r:r + band]
        a, b = image[r:r + band][u], rerender[r:r + band][u]
        num += float(np.abs(b - a).sum())
        den += float(np.abs(a).sum())
    return num / den if den > 0 else float("nan")
