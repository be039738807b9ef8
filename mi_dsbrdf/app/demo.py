"""``mi-dsbrdf demo``: recover a shipped material under a generated sky, and report.

Runs on what the package ships (no ``../shared``):

1. truth: a sphere with a library material (default ``gold-metallic-paint``)
   under Mitsuba's ``sunsky`` emitter, rendered by Mitsuba (``direct``);
2. ``mi-dsbrdf recover`` on that image, with a scene whose envmap is a
   placeholder (the illumination is unknown to it);
3. report: the BRDF error (Eq. 20 on the MERL grid, both conventions), the
   illumination error after the best scale (both conventions), the recovered
   material and the truth relit under a second sky, side by side, each beside
   doing nothing (the model's mean material, a constant map), as
   ``report.md``, ``report.json`` and ``comparison.png``.
"""
from __future__ import annotations

import json
import os
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_dsbrdf import load_material
from mi_dsbrdf.app.io import save_preview, staged_output, write_exr
from mi_dsbrdf.app.recover import recover_files, resolve_config
from mi_dsbrdf.app.scenes import camera
from mi_dsbrdf.config import Config
from mi_dsbrdf.evaluation.metrics import (band_scores, log_rmse_scale_invariant, material_errors, observed_errors,
                                          scale_invariant_log_error)
from mi_dsbrdf.inference.latlong import direction_to_uv, texel_solid_angles
from mi_dsbrdf.model.model_file import shipped_model
from mi_dsbrdf.model.samples import samples_from_function

#: The sun of the observed image and of the relighting sky (world, y up, towards the sun).
SUN = (0.5, 0.6, 0.62)
RELIGHT_SUN = (-0.7, 0.35, 0.6)


#: the files of a demo folder (``--force`` replaces only such a folder)
DEMO_FILES = ("placeholder.exr", "observed.exr", "scene.xml", "recovered", "comparison.png", "report.json",
              "report.md")


def sunsky(sun, sun_scale=1.0) -> dict:
    """A Mitsuba ``sunsky`` emitter with its sun towards the world direction ``sun``
    (``sun_direction`` is taken in world space; ``to_world`` turns the plugin's
    z-up sky dome to this scene's y-up)."""
    s = np.asarray(sun, dtype=np.float64) / np.linalg.norm(sun)
    return {"type": "sunsky", "sun_direction": [float(v) for v in s], "sun_scale": sun_scale,
            "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90)}


def latlong_of(emitter_dict, height=16, width=32, samples=1 << 20, seed=0) -> np.ndarray:
    """(H, W, 3) mean radiance per texel of an environment emitter, estimated by
    splatting the emitter's own direction samples (it samples its sun, which a
    grid of directions would miss)."""
    scene = mi.load_dict({"type": "scene", "e": emitter_dict})
    em = scene.emitters()[0]
    rng = np.random.default_rng(seed)
    it = dr.zeros(mi.Interaction3f, samples)
    u = rng.random((samples, 2)).astype(np.float32)
    ds, w = em.sample_direction(it, mi.Point2f(u[:, 0], u[:, 1]))
    d = np.array(ds.d, dtype=np.float64).T
    w = np.nan_to_num(np.array(w, dtype=np.float64).T)
    uv = direction_to_uv(d)
    j = np.minimum((uv[:, 0] * width).astype(int), width - 1)
    i = np.minimum((uv[:, 1] * height).astype(int), height - 1)
    acc = np.zeros((height * width, 3))
    np.add.at(acc, i * width + j, w)
    return (acc / samples).reshape(height, width, 3) / texel_solid_angles(height, width)[..., None]


def scene_xml(res, envmap) -> str:
    """The recovery scene: :func:`~mi_dsbrdf.app.scenes.camera` (fov 32), a sphere with
    a bare ``dsbrdf`` and an envmap whose file only stands in for the unknown light."""
    return """<scene version="3.0.0">
    <integrator type="direct"/>
    <sensor type="perspective">
        <float name="fov" value="32"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="%d"/><integer name="height" value="%d"/>
            <rfilter type="box"/></film>
    </sensor>
    <shape type="sphere"><bsdf type="dsbrdf"/></shape>
    <emitter type="envmap"><string name="filename" value="%s"/></emitter>
</scene>
""" % (res, res, envmap)


def truth_samples(truth):
    """The MERL grid cells the fits use, valued by ``truth`` (a library material)."""
    return samples_from_function(lambda th, td, pd: truth.eval(th, td))


def brdf_errors(material, truth) -> dict:
    """Eq. 20 of ``material`` against ``truth`` (a library material) on the MERL
    grid cells the fits use, in both conventions: ``{"paper": .., "cosine": ..}``."""
    return material_errors(material, truth_samples(truth))


def map_panels(truth, found, seen, height):
    """The true and the recovered map as two (height, 2 height, 3) panels for a
    preview beside images of the object: texels repeated to the panel's size, the
    recovered map at the truth's scale (the geometric mean of their ratio over the
    texels both see), each divided by the truth's 90th percentile (a sun clips,
    the sky stays visible)."""
    lit = seen & (found.mean(axis=2) > 0) & (truth.mean(axis=2) > 0)
    scale = float(np.exp(np.mean(np.log(truth[lit].mean(axis=1) / found[lit].mean(axis=1))))) if lit.any() else 1.0
    level = 0.5 / max(float(np.percentile(truth, 90)), 1e-30)
    rows = np.arange(height) * truth.shape[0] // height
    cols = np.arange(2 * height) * truth.shape[1] // (2 * height)
    return [(m * level)[rows][:, cols].astype(np.float32) for m in (truth, found * scale)]


def run(out, material="gold-metallic-paint", res=64, config: Config | str = "fast", spp=256,
        force=False) -> dict:
    """Render, recover (with ``config``, a Config or a preset name) and report into the
    folder ``out`` (written whole at the end, see :func:`~mi_dsbrdf.app.io.staged_output`);
    returns the report dict."""
    config = resolve_config(config)
    with staged_output(out, force, DEMO_FILES) as tmp:
        return _run(tmp, material, res, config, spp)


def _run(out, material, res, config, spp) -> dict:
    map_size = config.map_size
    t0 = time.perf_counter()
    # 1. the observed image
    write_exr(os.path.join(out, "placeholder.exr"), np.ones((8, 16, 3), dtype=np.float32))
    params = {"type": "scene", "integrator": {"type": "direct"}, "sky": sunsky(SUN), "sensor": camera(res, 32),
              "object": {"type": "sphere", "bsdf": {"type": "dsbrdf", "material": material}}}
    image = np.array(mi.render(mi.load_dict(params), spp=spp, seed=0), dtype=np.float32)
    write_exr(os.path.join(out, "observed.exr"), image)
    # 2. recovery
    scene_file = os.path.join(out, "scene.xml")
    with open(scene_file, "w") as f:
        f.write(scene_xml(res, "placeholder.exr"))
    rec = os.path.join(out, "recovered")
    result = recover_files(scene_file, os.path.join(out, "observed.exr"), rec, config=config)
    log = result.log
    # 3. report
    truth = load_material(material)
    samples = truth_samples(truth)
    found = load_material(os.path.join(rec, "material.json"))
    sky_truth = latlong_of(sunsky(SUN), *map_size)
    sky_found = result.illumination
    seen = sky_found.mean(axis=2) > 0
    relit = []
    # truth, recovered, and doing nothing: the model's mean material (a bare dsbrdf)
    for bsdf in ({"type": "dsbrdf", "material": material},
                 {"type": "dsbrdf", "filename": os.path.join(rec, "material.json")}, {"type": "dsbrdf"}):
        p = dict(params, sky=sunsky(RELIGHT_SUN), object={"type": "sphere", "bsdf": bsdf})
        relit.append(np.array(mi.render(mi.load_dict(p), spp=spp, seed=1), dtype=np.float64))
    lit = relit[0].mean(axis=2) > 1e-2 * relit[0].mean()
    scale_img = np.median(relit[0][lit] / np.maximum(relit[1][lit], 1e-30))
    save_preview(np.concatenate([image, *map_panels(sky_truth, sky_found, seen, res), relit[0].astype(np.float32),
                                 (relit[1] * scale_img).astype(np.float32)], axis=1),
                 os.path.join(out, "comparison.png"))
    report = {"material": material, "image": [res, res], "map_size": list(map_size),
              "recover_seconds": log["seconds"], "total_seconds": time.perf_counter() - t0,
              **{"brdf_eq20_%s" % c: e for c, e in material_errors(found, samples).items()},
              **{"mean_material_eq20_%s" % c: e
                 for c, e in material_errors(shipped_model().mean_material(), samples).items()},
              # where the image looked (Material.observed > 0), and the directions it did not show
              **{"brdf_eq20_%s_%s" % (part, c): e
                 for part, errors in observed_errors(found, samples).items() for c, e in errors.items()},
              **{"illumination_%s_after_scale" % c: scale_invariant_log_error(sky_found, sky_truth, seen, c)
                 for c in ("cosine", "paper")},
              **{"constant_map_%s_after_scale" % c: scale_invariant_log_error(np.ones_like(sky_truth), sky_truth,
                                                                               seen, c) for c in ("cosine", "paper")},
              "relit_log_rmse_after_scale": scale_invariant_log_error(relit[1], relit[0], lit),
              "mean_material_relit_log_rmse_after_scale": scale_invariant_log_error(relit[2], relit[0], lit),
              # the posterior's 90 % band against the truth (after Eq. 20's best scale)
              **{"band_%s" % k: v for k, v in band_scores(
                  found, samples, found.observed(samples.theta_h, samples.theta_d) > 0,
                  log_rmse_scale_invariant(found.eval(samples.theta_h, samples.theta_d), samples.values,
                                           samples.cos_i)[1]).items()},
              "flags": log.get("flags") or [],
              "unseen_texels": log.get("unseen_texels"), "rounds": len(log["rounds"]),
              "final_neg_log_posterior": log["rounds"][-1]["neg_log_posterior"]}
    with open(os.path.join(out, "report.json"), "w") as f:
        json.dump(report, f, indent=1)
    with open(os.path.join(out, "report.md"), "w") as f:
        f.write(_markdown(report))
    return report


def _markdown(r) -> str:
    return """# mi-dsbrdf demo

A sphere of `{material}` ({image[0]}x{image[1]} pixels) under Mitsuba's `sunsky`,
recovered with a {map_size[0]}x{map_size[1]} illumination map in {recover_seconds:.0f} s.

![observed | true map | recovered map | truth relit | recovered relit](comparison.png)

*From the left: the observed image; the true illumination map and the recovered one
(lat-long, at the truth's scale; texels no pixel sees are black); the true material
under a second sky, and the recovered material under that sky (overall scale
matched: one image cannot fix it).*

| measure | value |
|---|---|
| BRDF error, Eq. 20 in the paper's convention log(f + 1e-6), recovered | {brdf_eq20_paper:.3f} |
| same for the model's mean material (no inference) | {mean_material_eq20_paper:.3f} |
| BRDF error, Eq. 20 cosine-weighted log(1 + f cos θi), recovered | {brdf_eq20_cosine:.3f} |
| same for the model's mean material | {mean_material_eq20_cosine:.3f} |
| BRDF error, Eq. 20 paper, on the (θh, θd) the image showed | {brdf_eq20_observed_paper:.3f} |
| same on the (θh, θd) it did not show (the model's prior) | {brdf_eq20_unobserved_paper:.3f} |
| BRDF error, Eq. 20 cosine, on the (θh, θd) the image showed | {brdf_eq20_observed_cosine:.3f} |
| same on the (θh, θd) it did not show | {brdf_eq20_unobserved_cosine:.3f} |
| illumination error after the best scale, log(1 + L / mean), recovered | {illumination_cosine_after_scale:.3f} |
| same for a constant map on the same texels (no inference) | {constant_map_cosine_after_scale:.3f} |
| illumination error after the best scale, log(L / mean + 1e-6), recovered | {illumination_paper_after_scale:.3f} |
| same for a constant map | {constant_map_paper_after_scale:.3f} |
| relit image log-RMSE after the best scale, recovered | {relit_log_rmse_after_scale:.3f} |
| same for the model's mean material | {mean_material_relit_log_rmse_after_scale:.3f} |
| the 90 % posterior band holds the truth: where the image looked / elsewhere | \
{band_coverage_observed:.0%} / {band_coverage_unobserved:.0%} |
| the band's median width in log(f + 1e-6): where the image looked / elsewhere | \
{band_width_observed:.2f} / {band_width_unobserved:.2f} |
| what the photograph may not support (log.json's flags) | {flag_text} |
| illumination texels no pixel sees (left black) | {unseen_texels} |
| rounds / final negative log posterior | {rounds} / {final_neg_log_posterior:.4g} |

Files: `observed.exr`, `recovered/` (the `mi-dsbrdf recover` result directory),
`comparison.png`, `report.json`.
""".format(flag_text="; ".join(r["flags"]) or "none", **r)
