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
  resolution and averaged over each pixel's k x k block (the pixel's area);
* the forward model at 2 directions per texel side with the highlight pairs of
  25 texels a pixel (:mod:`mi_dsbrdf.inference.highlights`, ``--highlight-texels 25``).

Relative L1 over the pixels inference would use (the sphere without its
silhouette ring, :func:`~mi_dsbrdf.inference.pixels.interior`), beside the
noise of Mitsuba's render itself (half the relative L1 between two seeds), for
the library material
gold-metallic-paint and for the same with every lobe's gamma set to 4700 (a
sharp lobe, about 2.4 degrees wide in reflected direction), under the procedural
sky and, with ../shared/data, the grace probe.

    .venv/bin/python benchmarks/pixel_footprint.py        # ~6 min

Writes benchmarks/results/pixel_footprint.json.
"""
import argparse
import json
import os

import numpy as np

from mi_dsbrdf.evaluation.benchmark_cases import DATA, RESULTS, have_data

H, W = 32, 64
SAMPLES, SPP = (1, 2, 8), 4096
#: the highlight pairs measured (``Config.highlight_texels``)
HIGHLIGHT_TEXELS = 25


def relative_l1(a, b, mask) -> float:
    return float(np.abs(a[mask] - b[mask]).sum() / np.abs(b[mask]).sum())


def case(material, light, res, k) -> dict:
    import mitsuba as mi

    from mi_dsbrdf.inference.latlong import texel_blocks
    from mi_dsbrdf.evaluation.experiment import dsbrdf_bsdf, render, texels
    from mi_dsbrdf.inference.pixels import interior
    from mi_dsbrdf.inference.scene_dicts import camera
    bsdf = dsbrdf_bsdf(material)
    scene = {"type": "scene", "integrator": {"type": "direct", "hide_emitters": True}, "sensor": camera(res),
             "object": {"type": "sphere", "bsdf": bsdf},
             "sky": {"type": "envmap", "bitmap": mi.Bitmap(texel_blocks(light))}}
    loaded = mi.load_dict(scene)
    seeds = [np.array(mi.render(loaded, spp=SPP, seed=s), dtype=np.float64) for s in (3, 4)]
    mitsuba = 0.5 * (seeds[0] + seeds[1])
    mask = interior(texels({"type": "dsbrdf"}, res, (H, W)).mask)
    out = {"mitsuba_noise": relative_l1(seeds[0], seeds[1], mask) / 2}
    for s in SAMPLES:
        ts = texels({"type": "dsbrdf"}, res, (H, W), samples=s).with_bsdf(bsdf)
        out["centre_rays_samples_%d" % s] = relative_l1(render(ts, light.reshape(-1, 3)), mitsuba, mask)
    ts = texels({"type": "dsbrdf"}, res * k, (H, W), samples=2).with_bsdf(bsdf)
    area = render(ts, light.reshape(-1, 3)).reshape(res, k, res, k, 3).mean(axis=(1, 3))
    out["pixel_area_samples_2"] = relative_l1(area, mitsuba, mask)
    ts = texels({"type": "dsbrdf"}, res, (H, W)).with_map_size((H, W), 2, HIGHLIGHT_TEXELS).with_bsdf(bsdf)
    out["highlight_pairs_samples_2"] = relative_l1(render(ts, light.reshape(-1, 3)), mitsuba, mask)
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
                centre = "  ".join("%d dirs %5.1f %%" % (s, 100 * r["centre_rays_samples_%d" % s]) for s in SAMPLES)
                print("%3d px  %-20s %-6s  Mitsuba noise %4.1f %%  centre rays: %s   pixel area (%dx%d rays): %5.1f %%"
                      "   highlight pairs: %5.1f %%" % (res, mname, lname, 100 * r["mitsuba_noise"], centre, k, k,
                                                        100 * r["pixel_area_samples_2"],
                                                        100 * r["highlight_pairs_samples_2"]), flush=True)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump({"cases": results, "map": [H, W], "mitsuba_spp": SPP,
                   "command": "python benchmarks/pixel_footprint.py"}, f, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
