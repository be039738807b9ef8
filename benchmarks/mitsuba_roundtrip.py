"""What you recover is what Mitsuba renders: the saved ``scene.xml`` rendered by
Mitsuba against the tool's own re-render and against the photograph.

Each case is a photograph rendered by Mitsuba (``scenes/sphere_envmap.xml``: a
sphere of a MERL material, its measured data through Mitsuba's ``merl`` plugin,
under a light probe at full resolution, box filter, ``--photo-spp``), recovered
by :func:`mi_dsbrdf.recover` on a preset and saved; then the saved
``scene.xml`` is rendered by Mitsuba twice with different seeds
(``--spp`` each). Relative L1 over the pixels inference used:

* Mitsuba's render against the tool's re-render (``Result.rerender``);
* the re-render against the photograph, and Mitsuba's render against it;
* Mitsuba's render against its own second seed: the Monte Carlo noise floor,
  under which no other figure can be read.

Cases: the natural-light sets' materials x probes (``--set validation`` or
``report``, ``--limit`` the first N), at ``--res`` pixels; with ``--light point``
or ``directional``, the same materials under ``scenes/sphere_point.xml`` or
``sphere_directional.xml`` with the light placed at :data:`LIGHT_ANGLES` from the
camera instead of the probes (a point light at :data:`POINT_DISTANCE`); with ``--sharp`` also
a 32 px sphere of gold-metallic-paint's DSBRDF with every lobe's gamma at 4700 (a
lobe about 2.4 degrees wide in reflected direction, narrower than one pixel's
footprint) under the first probe. Needs ../shared/data.

    .venv/bin/python benchmarks/mitsuba_roundtrip.py --set validation --limit 8    # ~10 min
    .venv/bin/python benchmarks/mitsuba_roundtrip.py --set report --light point --limit 8

With ``--footprint``, no recovery: the forward model
(:class:`~mi_dsbrdf.inference.forward.TexelSum`, one ray through each pixel's
centre, ``texel_samples`` x ``texel_samples`` directions per texel) against
Mitsuba's render of the same sphere (box filter, 4096 spp, the map written as
``illumination.exr`` is, in 8x8 texel blocks) under a 32x64 map, at 32 and 64 px:

* the forward model at 1, 2 and 8 directions per texel side (centre rays);
* at 2 directions per texel side, traced at ``k`` times the resolution and
  averaged over each pixel's k x k block (the pixel's area);
* at 2 directions per texel side with the highlight pairs of 25 texels a pixel
  (:mod:`mi_dsbrdf.inference.highlights`, ``Config.highlight_texels``).

Relative L1 over the sphere without its silhouette ring
(:func:`~mi_dsbrdf.inference.pixels.interior`), beside Mitsuba's noise, for
gold-metallic-paint and the same with every lobe's gamma at 4700, under the
procedural sky and, with ../shared/data, the grace probe (~6 min; writes
benchmarks/results/pixel_footprint.json).

Writes the result folders under out/mitsuba_roundtrip/<set>/<setting>/, and the
summary (medians and worst cases, the command) to
benchmarks/results/mitsuba_roundtrip_<set>.json (with ``--config``, beside the
result folders; ``--out`` names another file).
"""
import argparse
import json
import os
import shutil
import sys
import time

import numpy as np

from mi_dsbrdf.evaluation.benchmark_cases import DATA, OUT, REPORT_MATERIALS, REPORT_PROBES, RESULTS, \
    VALIDATION_MATERIALS, VALIDATION_PROBES, have_data, parse_config, setting_name

MEASURES = [("mitsuba_vs_rerender", "Mitsuba vs re-render"), ("rerender_vs_photo", "re-render vs photo"),
            ("mitsuba_vs_photo", "Mitsuba vs photo"), ("noise", "Mitsuba noise (seed vs seed)")]


def relative_l1(a, b, mask) -> float:
    return float(np.abs(a[mask] - b[mask]).sum() / np.abs(b[mask]).sum())


#: --light point / directional: the light's placements, in degrees from the camera
#: (:func:`~mi_dsbrdf.evaluation.experiment.light_at`), one per natural-light probe slot
LIGHT_ANGLES = {"validation": (20.0, 55.0, 80.0), "report": (10.0, 30.0, 45.0, 60.0, 70.0, 85.0)}
#: the point light's distance from the sphere's centre (scene units; the sphere's radius is 1)
POINT_DISTANCE = 4.0


def cases(which, limit, light="envmap"):
    materials, probes = ((VALIDATION_MATERIALS, VALIDATION_PROBES) if which == "validation"
                         else (REPORT_MATERIALS, REPORT_PROBES))
    if light != "envmap":
        probes = LIGHT_ANGLES[which]
    out = [(m, p) for p in probes for m in materials]
    # interleave the probes so that a --limit slice sees every one of them
    out = [c for i in range(len(materials)) for c in out[i::len(materials)]]
    return out[:limit] if limit else out


#: the sharp case: its material's name, the gamma of its lobes, its image size
SHARP, SHARP_GAMMA, SHARP_RES = "sharp-gamma4700", 4700.0, 32


def photograph(folder, material, probe, res, args):
    """Render the case's photograph into ``folder``; returns (scene path, image path)."""
    import mitsuba as mi

    from mi_dsbrdf.app.io import write_exr
    from mi_dsbrdf.app.scenes import scene_path
    nbrdf = os.path.join(args.data, "merl", "merl_nbrdf_weights.npz")
    xml = open(scene_path("sphere_" + args.light)).read()
    if material == SHARP:
        from mi_dsbrdf.brdf.dsbrdf import Material
        from mi_dsbrdf.model import model_file
        base = model_file.shipped_model().library_material("gold-metallic-paint")
        truth_file = os.path.join(folder, "truth.json")
        Material(base.log_kappa, np.full_like(base.log_gamma, np.log(SHARP_GAMMA)), base.chromaticity).save(truth_file)
        bsdf = '<bsdf type="dsbrdf"><string name="filename" value="%s"/></bsdf>' % truth_file
    else:
        bsdf = ('<bsdf type="merl"><string name="nbrdf" value="%s"/><string name="material" value="%s"/></bsdf>'
                % (nbrdf, material))
    truth = xml.replace('<bsdf type="dsbrdf" id="material"/>', bsdf)
    if args.light == "envmap":
        light = {"envmap": os.path.join(args.data, "envmaps", probe)}
    else:
        from mi_dsbrdf.evaluation.experiment import light_at
        d = light_at(probe)
        light = ({"light_position": ", ".join("%r" % float(v) for v in POINT_DISTANCE * d)} if args.light == "point"
                 else {"light_direction": ", ".join("%r" % float(v) for v in -d)})
    scene = mi.load_string(truth, res=str(res), spp=str(args.photo_spp), **light)
    image = os.path.join(folder, "photo.exr")
    write_exr(image, np.array(mi.render(scene, seed=1), dtype=np.float32))
    # the scene as a user gives it: the film at the photograph's size (the light's
    # values are not used, but its file must load; a point light's distance is kept)
    scene_file = os.path.join(folder, "scene.xml")
    user = xml.replace('name="res" value="128"', 'name="res" value="%d"' % res)
    if args.light == "envmap":
        user = user.replace('value="textures/sky.exr"', 'value="%s"' % light["envmap"])
    user = user.replace('name="light_position" value="2.5, 2.0, 3.0"',
                        'name="light_position" value="0, 0, %r"' % POINT_DISTANCE)
    with open(scene_file, "w") as f:
        f.write(user)
    return scene_file, image


def case(material, probe, res, args) -> dict:
    import mitsuba as mi

    import dataclasses

    import mi_dsbrdf
    from mi_dsbrdf.config import preset
    name = "%s-%s" % (material, os.path.splitext(os.path.basename(probe))[0] if args.light == "envmap"
                      else "%s%g" % (args.light, probe))
    folder = os.path.join(OUT, "mitsuba_roundtrip", args.set + ("" if args.light == "envmap" else "-" + args.light),
                          args.setting_name, name)
    shutil.rmtree(folder, ignore_errors=True)
    os.makedirs(folder)
    scene_file, image = photograph(folder, material, probe, res, args)
    t0 = time.perf_counter()
    result = mi_dsbrdf.recover(scene_file, image, config=dataclasses.replace(preset(args.preset), **args.config))
    seconds = time.perf_counter() - t0
    saved = result.save(os.path.join(folder, "result"))
    renders = [np.array(mi.render(mi.load_file(os.path.join(saved, "scene.xml")), spp=args.spp, seed=s),
                        dtype=np.float64) for s in (7, 8)]
    mitsuba = 0.5 * (renders[0] + renders[1])
    used, photo = result.used, result.image
    return {"case": name, "seconds": seconds,
            "mitsuba_vs_rerender": relative_l1(mitsuba, result.rerender, used),
            "rerender_vs_photo": relative_l1(result.rerender, photo, used),
            "mitsuba_vs_photo": relative_l1(mitsuba, photo, used),
            # the two seeds differ by sqrt(2) times one render's noise, and their mean
            # has 1/sqrt(2) of it: half their difference is the mean's noise
            "noise": relative_l1(renders[0], renders[1], used) / 2,
            "highlight_change": result.log.get("highlight_change"),
            "highlight_texels": result.log.get("highlight_texels")}


#: --footprint: the map (texels), Mitsuba's samples per pixel, the forward model's
#: directions per texel side, and the highlight pairs measured (``Config.highlight_texels``)
FOOTPRINT_MAP, FOOTPRINT_SPP, FOOTPRINT_SAMPLES, HIGHLIGHT_TEXELS = (32, 64), 4096, (1, 2, 8), 25


def footprint_case(material, light, res, k) -> dict:
    """One sphere of ``material`` under ``light`` (H, W, 3) at ``res`` px; relative L1s (module doc)."""
    import mitsuba as mi

    from mi_dsbrdf.evaluation.experiment import dsbrdf_bsdf, render, texels
    from mi_dsbrdf.inference.latlong import texel_blocks
    from mi_dsbrdf.inference.pixels import interior
    from mi_dsbrdf.inference.scene_dicts import camera
    bsdf = dsbrdf_bsdf(material)
    scene = {"type": "scene", "integrator": {"type": "direct", "hide_emitters": True}, "sensor": camera(res),
             "object": {"type": "sphere", "bsdf": bsdf},
             "sky": {"type": "envmap", "bitmap": mi.Bitmap(texel_blocks(light))}}
    loaded = mi.load_dict(scene)
    seeds = [np.array(mi.render(loaded, spp=FOOTPRINT_SPP, seed=s), dtype=np.float64) for s in (3, 4)]
    mitsuba = 0.5 * (seeds[0] + seeds[1])
    mask = interior(texels({"type": "dsbrdf"}, res, FOOTPRINT_MAP).mask)
    out = {"mitsuba_noise": relative_l1(seeds[0], seeds[1], mask) / 2}
    for s in FOOTPRINT_SAMPLES:
        ts = texels({"type": "dsbrdf"}, res, FOOTPRINT_MAP, samples=s).with_bsdf(bsdf)
        out["centre_rays_samples_%d" % s] = relative_l1(render(ts, light.reshape(-1, 3)), mitsuba, mask)
    ts = texels({"type": "dsbrdf"}, res * k, FOOTPRINT_MAP, samples=2).with_bsdf(bsdf)
    area = render(ts, light.reshape(-1, 3)).reshape(res, k, res, k, 3).mean(axis=(1, 3))
    out["pixel_area_samples_2"] = relative_l1(area, mitsuba, mask)
    ts = texels({"type": "dsbrdf"}, res, FOOTPRINT_MAP).with_map_size(FOOTPRINT_MAP, 2)
    ts = ts.with_highlights(HIGHLIGHT_TEXELS)
    ts = ts.with_bsdf(bsdf)
    out["highlight_pairs_samples_2"] = relative_l1(render(ts, light.reshape(-1, 3)), mitsuba, mask)
    return out


def footprint(args):
    """The --footprint cases; writes ``args.out`` or results/pixel_footprint.json."""
    out = args.out or os.path.join(RESULTS, "pixel_footprint.json")
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
    lights = {"sky": downsample(procedural_sky(256, 512).astype(np.float64), *FOOTPRINT_MAP)}
    if have_data(args.data):
        grace = read_image(os.path.join(args.data, "envmaps", "probulator", "grace.hdr"))
        lights["grace"] = downsample(grace, *FOOTPRINT_MAP)
    results = {}
    for (res, k) in ((32, 8), (64, 4)):
        for mname, material in materials.items():
            for lname, light in lights.items():
                r = footprint_case(material, light, res, k)
                results["%d px, %s, %s" % (res, mname, lname)] = r
                centre = "  ".join("%d dirs %5.1f %%" % (s, 100 * r["centre_rays_samples_%d" % s])
                                   for s in FOOTPRINT_SAMPLES)
                print("%3d px  %-20s %-6s  Mitsuba noise %4.1f %%  centre rays: %s   pixel area (%dx%d rays): %5.1f %%"
                      "   highlight pairs: %5.1f %%" % (res, mname, lname, 100 * r["mitsuba_noise"], centre, k, k,
                                                        100 * r["pixel_area_samples_2"],
                                                        100 * r["highlight_pairs_samples_2"]), flush=True)
    os.makedirs(os.path.dirname(out), exist_ok=True)
    with open(out, "w") as f:
        json.dump({"cases": results, "map": list(FOOTPRINT_MAP), "mitsuba_spp": FOOTPRINT_SPP,
                   "command": "python benchmarks/mitsuba_roundtrip.py --footprint"}, f, indent=1, sort_keys=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", choices=("validation", "report"), default="validation")
    ap.add_argument("--limit", type=int, default=0, help="the first N cases (0: all)")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--sharp", action="store_true", help="add the sharp case (module doc)")
    ap.add_argument("--light", choices=("envmap", "point", "directional"), default="envmap",
                    help="the light of the photographs (module doc)")
    ap.add_argument("--preset", default="default")
    ap.add_argument("--photo-spp", type=int, default=1024)
    ap.add_argument("--spp", type=int, default=2048, help="samples per pixel of each of the two Mitsuba renders")
    ap.add_argument("--config", nargs="*", default=[], metavar="FIELD=VALUE", help="Config fields to change")
    ap.add_argument("--data", default=DATA)
    ap.add_argument("--out", default=None)
    ap.add_argument("--footprint", action="store_true",
                    help="the forward model's image formation against Mitsuba's, no recovery (module doc)")
    args = ap.parse_args(argv)
    if args.footprint:
        return footprint(args)
    args.config = parse_config(args.config)
    args.setting_name = setting_name(args.config) if args.config else "defaults"
    if not have_data(args.data):
        sys.exit("mitsuba_roundtrip: needs the shared data (%s)" % args.data)
    rows = []
    todo = [(m, p, args.res) for m, p in cases(args.set, args.limit, args.light)]
    if args.sharp and args.light == "envmap":
        todo.append((SHARP, cases(args.set, 1)[0][1], SHARP_RES))
    for material, probe, res in todo:
        r = case(material, probe, res, args)
        rows.append(r)
        print("%-40s %5.1f s  " % (r["case"], r["seconds"]) +
              "  ".join("%s %5.1f %%" % (label, 100 * r[k]) for k, label in MEASURES), flush=True)
    summary = {k: {"median": float(np.median([r[k] for r in rows])), "worst": float(max(r[k] for r in rows))}
               for k, _ in MEASURES}
    for k, label in MEASURES:
        print("%-30s median %5.1f %%  worst %5.1f %%" % (label, 100 * summary[k]["median"],
                                                          100 * summary[k]["worst"]))
    excess = [r["mitsuba_vs_photo"] - r["rerender_vs_photo"] for r in rows]
    print("Mitsuba vs photo minus re-render vs photo: median %+.1f %%, worst %+.1f %% (target <= +1 %%)"
          % (100 * np.median(excess), 100 * max(excess)))
    refined = [r["case"] for r in rows if r.get("highlight_texels")]
    print("fitted with the highlight pairs: %d of %d (%s); median time %.1f s"
          % (len(refined), len(rows), ", ".join(refined) or "none", np.median([r["seconds"] for r in rows])))
    run = args.set + ("" if args.light == "envmap" else "-" + args.light)
    out = args.out or (os.path.join(OUT, "mitsuba_roundtrip", run, args.setting_name, "summary.json")
                       if args.config else os.path.join(RESULTS, "mitsuba_roundtrip_%s%s.json" % (
                           args.set, "" if args.light == "envmap" else "_" + args.light)))
    os.makedirs(os.path.dirname(out), exist_ok=True)
    command = "python benchmarks/mitsuba_roundtrip.py --set %s%s%s%s%s%s" % (
        args.set, "" if args.light == "envmap" else " --light " + args.light,
        " --limit %d" % args.limit if args.limit else "", " --sharp" if args.sharp else "",
        "" if args.preset == "default" else " --preset " + args.preset,
        " --config " + " ".join("%s=%s" % kv for kv in args.config.items()) if args.config else "")
    with open(out, "w") as f:
        json.dump({"summary": summary, "cases": rows, "light": args.light, "res": args.res, "spp": args.spp,
                   "photo_spp": args.photo_spp,
                   "preset": args.preset, "config": args.config, "command": command}, f, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
