"""What separates the inference's image formation from Mitsuba's on small, sharp
objects: the texel's directions, or the pixel's footprint.

The forward model (:class:`~mi_dsbrdf.inference.forward.TexelSum`) traces one ray
through each pixel's centre and lights it from ``texel_samples`` x
``texel_samples`` directions per texel; Mitsuba averages the radiance over each
pixel's area (box filter) and samples the map continuously. For a sphere of a
DSBRDF under a 32x64 map, Mitsuba's render (4096 spp, the map written as
``illumination.exr`` is, in 8x8 texel blocks) is compared with

* the forward model at 1, 2 and 8 directions per texel side (centre rays);
* the forward model at 2 directions per texel side, traced at ``k`` times the
  resolution and averaged over each pixel's k x k block (the pixel's area).

Relative L1 over the pixels on the sphere, for the library material
gold-metallic-paint and for the same with every lobe's gamma set to 4700 (a
sharp lobe, about 2.4 degrees wide in reflected direction), under the procedural
sky and, with ../shared/data, the grace probe.

    .venv/bin/python benchmarks/pixel_footprint.py        # ~3 min

Writes benchmarks/results/pixel_footprint.json.
"""
import argparse
import json
import os

import numpy as np

from mi_dsbrdf.evaluation.benchmark_cases import DATA, RESULTS, have_data

H, W = 32, 64
SAMPLES, SPP = (1, 2, 8), 4096


def relative_l1(a, b, mask) -> float:
    return float(np.abs(a[mask] - b[mask]).sum() / np.abs(b[mask]).sum())


def case(material, light, res, k) -> dict:
    import mitsuba as mi

    from mi_dsbrdf.app.result import texel_blocks
    from mi_dsbrdf.evaluation.experiment import dsbrdf_bsdf, render, texels
    from mi_dsbrdf.inference.scene_dicts import camera
    bsdf = dsbrdf_bsdf(material)
    scene = {"type": "scene", "integrator": {"type": "direct", "hide_emitters": True}, "sensor": camera(res),
             "object": {"type": "sphere", "bsdf": bsdf},
             "sky": {"type": "envmap", "bitmap": mi.Bitmap(texel_blocks(light))}}
    mitsuba = np.array(mi.render(mi.load_dict(scene), spp=SPP, seed=3), dtype=np.float64)
    mask = texels({"type": "dsbrdf"}, res, (H, W)).mask
    out = {}
    for s in SAMPLES:
        ts = texels({"type": "dsbrdf"}, res, (H, W), samples=s).with_bsdf(bsdf)
        out["centre_rays_samples_%d" % s] = relative_l1(render(ts, light.reshape(-1, 3)), mitsuba, mask)
    ts = texels({"type": "dsbrdf"}, res * k, (H, W), samples=2).with_bsdf(bsdf)
    area = render(ts, light.reshape(-1, 3)).reshape(res, k, res, k, 3).mean(axis=(1, 3))
    out["pixel_area_samples_2"] = relative_l1(area, mitsuba, mask)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DATA)
    ap.add_argument("--out", default=os.path.join(RESULTS, "pixel_footprint.json"))
    args = ap.parse_args(argv)
    import mi_dsbrdf  # noqa: F401  (variant, plugins)
    from mi_dsbrdf.brdf.dsbrdf import Material
    from mi_dsbrdf.evaluation.experiment import downsample
    from mi_dsbrdf.inference.images import read_image
    from mi_dsbrdf.inference.latlong import procedural_sky
    from mi_dsbrdf.model import model_file
    base = model_file.shipped_model().library_material("gold-metallic-paint")
    materials = {"gold-metallic-paint": base,
                 "gamma 4700": Material(base.log_kappa, np.full_like(base.log_gamma, np.log(4700.0)),
                                        base.chromaticity)}
    lights = {"sky": downsample(procedural_sky(256, 512).astype(np.float64), H, W)}
    if have_data(args.data):
        lights["grace"] = downsample(read_image(os.path.join(args.data, "envmaps", "probulator", "grace.hdr")), H, W)
    results = {}
    for (res, k) in ((32, 8), (64, 4)):
        for mname, material in materials.items():
            for lname, light in lights.items():
                r = case(material, light, res, k)
                results["%d px, %s, %s" % (res, mname, lname)] = r
                print("%3d px  %-20s %-6s  centre rays: %s   pixel area (%dx%d rays): %5.1f %%" % (
                    res, mname, lname, "  ".join("%d dirs %5.1f %%" % (s, 100 * r["centre_rays_samples_%d" % s])
                                                 for s in SAMPLES), k, k, 100 * r["pixel_area_samples_2"]),
                      flush=True)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump({"cases": results, "map": [H, W], "mitsuba_spp": SPP,
                   "command": "python benchmarks/pixel_footprint.py"}, f, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
