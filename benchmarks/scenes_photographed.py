"""Scenes as photographed: path-traced photographs of an object standing on a ground
plane, recovered from the scene as a user gives it, beside the same object alone.

Each map case is a held-out MERL material (its measured data through Mitsuba's
``merl`` plugin; recovered with its leave-one-out model,
:func:`~mi_dsbrdf.model.build.loo_model`) on an object standing on a diffuse grey
ground plane under a light probe at full resolution:

* the object: the sphere, or the shipped non-convex torus (tilted, so that it
  shows much of its sphere of normals and shadows itself);
* the photograph: Mitsuba's ``path`` integrator (max depth :data:`MAX_DEPTH`, so
  that the ground's light reaches the object and the torus lights itself), a
  perspective camera looking down at :data:`RES` px, box filter, :data:`PHOTO_SPP`
  spp; then shot noise (:data:`PHOTONS` photons at the object's mean pixel,
  :func:`~mi_dsbrdf.evaluation.experiment.shot_noise`) and every channel clipped
  at a white level (:data:`WHITE_QUANTILE` of the object's pixels' brightest
  channel), which the tool is not told;
* the scene given to :func:`mi_dsbrdf.recover`: the same camera, the object with a
  ``dsbrdf``, the ground with its diffuse BSDF (its shadows and its light are
  modelled, :mod:`mi_dsbrdf.inference.bounce`), an envmap; the default preset.

Its *clean* twin: the same object alone under the same probe, rendered by the
``direct`` integrator (with nothing else in the scene, what the tool models
exactly), no noise, no clipping, recovered alike. Scores, for both:

* ``brdf_eq20_paper``, ``brdf_eq20_cosine``: Eq. 20 on the MERL grid in the paper's
  convention, log(f + 1e-6), and the graphics-fitting one, log(1 + f cos theta_i);
* ``map_paper``, ``map_cosine``: the recovered map's scale-invariant log error
  against the probe at its resolution, on the texels it saw; beside a constant map;
* ``relit``: the recovered material on a lone sphere (64 px) under two probes
  other than the case's, rendered by Mitsuba (``direct``, :data:`RELIT_SPP` spp)
  against the measured material rendered alike (scale-invariant log error,
  cosine convention, the sphere without its silhouette ring);
* ``seconds``: the recovery's wall time;
* doing nothing: the leave-one-out model's mean material (BRDF, relit) and a
  constant map, on the same case;
* the Mitsuba recipe (``adam``): ``principled`` + an envmap of the recovered map's
  size fitted to the same photograph by Adam through ``prb`` (max depth 3, the
  scene's ground in it; :data:`ADAM_SPP` spp, the clipped pixels left out) for as
  long as the recovery took, scored alike.

The point case: a sphere on the ground beside a small blocker that shadows part of
it, under a point light, photographed and recovered alike (``direction_error_deg``
against the true direction from the sphere's centre), beside its clean twin (the
sphere alone).

Sets: ``--set validation`` (the validation materials and probes) or ``report``;
case i is material i under probe i mod (number of probes), on each object;
``--limit`` the first N materials. Needs ../shared/data. One process, the cases in
turn; a case's result is kept under out/scenes_photographed/<set>/ and reused
(``--fresh`` reruns). Prints the table and writes
benchmarks/results/scenes_photographed_<set>.json (``--res`` another image side:
``..._<set>_<res>.json``). With ``--bounce``, no recovery: how much of the
path-traced image the forward model misses without the ground's light, and what
its one-bounce term recovers (:func:`bounce_case`; ``..._bounce_<set>.json``).

    .venv/bin/python benchmarks/scenes_photographed.py --set validation --limit 4   # ~13 min
    .venv/bin/python benchmarks/scenes_photographed.py --set report                  # ~40 min
"""
import argparse
import json
import os
import sys
import time

import numpy as np

from mi_dsbrdf.evaluation.benchmark_cases import (CACHE, DATA, OUT, REPORT_MATERIALS, REPORT_PROBES, RESULTS,
                                                  VALIDATION_MATERIALS, VALIDATION_PROBES, have_data)

#: the photograph: image side (px), path depth, samples per pixel, photons at the
#: object's mean pixel, and the quantile of the object's pixels the camera clips at
RES, MAX_DEPTH, PHOTO_SPP, PHOTONS, WHITE_QUANTILE = 256, 5, 256, 2000, 0.99
PATH = {"type": "path", "max_depth": MAX_DEPTH}
#: the torus turned about x (degrees) to stand 60 degrees from flat, facing the camera;
#: the ground's height under each object (it stands on it) and its albedo
TORUS_TILT = -30.0
GROUND_Y, GROUND_ALBEDO = {"sphere": -1.0, "torus": -0.906}, (0.35, 0.33, 0.30)
#: the relit sphere: image side, samples per pixel, probes (the first two that differ
#: from the case's)
RELIT_RES, RELIT_SPP = 64, 512
RELIT_PROBES = ["probulator/pisa.hdr", "probulator/uffizi.hdr", "probulator/ennis.hdr"]
#: the point case: light angle from the camera (degrees) and distance; the blocker's
#: centre (a fraction of the way to the light, then sideways) and radius
POINT_ANGLE, POINT_DISTANCE = 45.0, 4.0
BLOCKER_ALONG, BLOCKER_SIDE, BLOCKER_RADIUS = 0.5, 0.55, 0.25
OBJECTS = ("sphere", "torus")
#: the Mitsuba recipe: samples per pixel of each Adam iteration, and at most this many
#: iterations (it stops at the recovery's wall time)
ADAM_SPP, ADAM_MAX_ITERS = 8, 2000


def camera(res):
    import mitsuba as mi
    return {"type": "perspective", "fov": 40.0,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 1.2, 4], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}}


def scene_dict(obj, bsdf, light, integrator, ground=True, blocker=None, res=RES) -> dict:
    """A Mitsuba scene dict: ``obj`` carrying ``bsdf`` under ``light`` (an emitter
    dict), on the ground unless ``ground`` is False, with a diffuse sphere at
    ``blocker`` (centre) if given."""
    import mitsuba as mi

    from mi_dsbrdf.inference.scene_dicts import shape_dict
    d = {"type": "scene", "integrator": integrator, "sensor": camera(res), "object": shape_dict(obj, bsdf),
         "light": light}
    if obj == "torus":
        d["object"]["to_world"] = mi.ScalarTransform4f().rotate([1, 0, 0], TORUS_TILT)
    grey = {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(GROUND_ALBEDO)}}
    if ground:
        d["ground"] = {"type": "rectangle", "bsdf": grey,
                       "to_world": mi.ScalarTransform4f().translate([0, GROUND_Y[obj], 0]).scale(6)
                       .rotate([1, 0, 0], -90)}
    if blocker is not None:
        d["blocker"] = {"type": "sphere", "center": [float(v) for v in blocker], "radius": BLOCKER_RADIUS,
                        "bsdf": grey}
    return d


def photograph(scene, seed, clean) -> tuple:
    """(the photograph, (H, W) bool: the object's pixels): ``scene`` rendered; unless
    ``clean``, with shot noise and clipped at the white level."""
    import mitsuba as mi

    from mi_dsbrdf.evaluation.experiment import shot_noise
    from mi_dsbrdf.inference.rays import centre_hits
    s = mi.load_dict(scene)
    img = np.array(mi.render(s, spp=PHOTO_SPP, seed=1), dtype=np.float64)
    obj = [sh for sh in s.shapes() if sh.id() == "object"][0]
    _, hit = centre_hits(s, s.sensors()[0], obj)
    mask = hit.reshape(img.shape[:2])
    if not clean:
        img = shot_noise(img, mask, PHOTONS, seed)
        white = float(np.quantile(img[mask].max(axis=1), WHITE_QUANTILE))
        img = np.minimum(img, white)
    return img, mask


def relit(material, truth_bsdf, probe, data) -> float:
    """Mean over the relighting probes of the relit error (module doc)."""
    import mitsuba as mi

    from mi_dsbrdf.evaluation.experiment import dsbrdf_bsdf
    from mi_dsbrdf.evaluation.metrics import scale_invariant_log_error
    from mi_dsbrdf.inference.pixels import interior
    from mi_dsbrdf.inference.rays import centre_hits
    from mi_dsbrdf.inference.scene_dicts import camera as front_camera, shape_dict
    errors = []
    fitted = dsbrdf_bsdf(material) if hasattr(material, "log_kappa") else material      # else a Mitsuba BSDF
    for p in [p for p in RELIT_PROBES if p != probe][:2]:
        light = {"type": "envmap", "filename": os.path.join(data, "envmaps", p)}
        images = []
        for bsdf in (truth_bsdf, fitted):
            s = mi.load_dict({"type": "scene", "integrator": {"type": "direct", "hide_emitters": True},
                              "sensor": front_camera(RELIT_RES), "object": shape_dict("sphere", bsdf),
                              "light": light})
            images.append(np.array(mi.render(s, spp=RELIT_SPP, seed=3), dtype=np.float64))
        _, hit = centre_hits(s, s.sensors()[0], s.shapes()[0])
        errors.append(scale_invariant_log_error(images[1], images[0], interior(hit.reshape(RELIT_RES, RELIT_RES))))
    return float(np.mean(errors))


def recover_case(scene, image, model) -> tuple:
    import mi_dsbrdf
    t0 = time.perf_counter()
    result = mi_dsbrdf.recover(scene, image, model=model)
    return result, time.perf_counter() - t0


def brdf_scores(material, samples) -> dict:
    from mi_dsbrdf.evaluation.metrics import CONVENTIONS, bsdf_values, log_rmse_scale_invariant
    values = material.eval(samples.theta_h, samples.theta_d) if hasattr(material, "log_kappa") else \
        bsdf_values(material, samples)
    return {"brdf_eq20_" + c: log_rmse_scale_invariant(values, samples.values, samples.cos_i, c)[0]
            for c in CONVENTIONS}


def map_scores(recovered, seen, truth) -> dict:
    from mi_dsbrdf.evaluation.metrics import scale_invariant_log_error
    return {"map_paper": scale_invariant_log_error(recovered, truth, seen, "paper"),
            "map_cosine": scale_invariant_log_error(recovered, truth, seen, "cosine")}


def map_case(material, probe, obj, data, clean=None, res=RES) -> dict:
    """One map case and its clean twin, scored (module doc); ``clean``: the clean
    twin's scores when they are known (they do not depend on the scene's other shapes)."""
    from mi_dsbrdf.brdf.measured import MeasuredBRDF
    from mi_dsbrdf.evaluation.experiment import downsample
    from mi_dsbrdf.inference.images import read_image
    from mi_dsbrdf.model.build import loo_model
    from mi_dsbrdf.model.samples import samples_from_table
    nbrdf = os.path.join(data, "merl", "merl_nbrdf_weights.npz")
    truth_bsdf = {"type": "merl", "nbrdf": nbrdf, "material": material}
    light = {"type": "envmap", "filename": os.path.join(data, "envmaps", probe)}
    model = loo_model(material, CACHE)
    samples = samples_from_table(MeasuredBRDF.from_nbrdf(nbrdf, material))
    probe_map = read_image(os.path.join(data, "envmaps", probe))
    name = "%s-%s-%s" % (material, os.path.splitext(os.path.basename(probe))[0], obj)
    out = {"case": name, "material": material, "probe": probe, "object": obj}
    if clean is not None:
        out["clean"] = clean
    for kind, ground, integrator in (("scene", True, PATH), ("clean", False, {"type": "direct"})):
        if kind in out:
            continue
        img, mask = photograph(scene_dict(obj, truth_bsdf, light, integrator, ground, res=res), name,
                               kind == "clean")
        result, seconds = recover_case(scene_dict(obj, {"type": "dsbrdf"}, light, {"type": "direct"}, ground,
                                                  res=res), img.astype(np.float32), model)
        rec = result.illumination
        truth = downsample(probe_map, *rec.shape[:2])
        row = {"seconds": seconds, "relit": relit(result.material, truth_bsdf, probe, data),
               "needs": result.log["needs"], "residual": result.log["residual"]}
        row.update(brdf_scores(result.material, samples))
        row.update(map_scores(rec, result.seen, truth))
        out[kind] = row
        if kind == "scene":
            nothing = {"relit": relit(model.mean_material(), truth_bsdf, probe, data)}
            nothing.update(brdf_scores(model.mean_material(), samples))
            nothing.update(map_scores(np.ones_like(truth), result.seen, truth))
            out["nothing"] = nothing
            out["adam"] = adam_case(scene_dict(obj, {"type": "dsbrdf"}, None, None, ground, res=res), img, mask,
                                    seconds, rec.shape[:2], truth_bsdf, probe, data, samples, result.seen, truth)
    return out


def adam_case(scene, img, mask, seconds, map_hw, truth_bsdf, probe, data, samples, seen, truth) -> dict:
    """The Mitsuba recipe on the photograph ``img`` of ``scene`` (a dict without its
    light) for ``seconds``, scored as the recovery (module doc)."""
    from mi_dsbrdf.evaluation.adam import adam_recover
    usable = mask & (img.max(axis=2) < img[mask].max())        # the clipped pixels left out, as the tool does
    t0 = time.perf_counter()
    fit = adam_recover(img, usable, img.shape[0], map_hw, "principled-adam", spp=ADAM_SPP, iters=ADAM_MAX_ITERS,
                       scene={k: v for k, v in scene.items() if k not in ("light", "integrator")},
                       seconds=seconds)
    row = {"seconds": time.perf_counter() - t0, "iterations": len(fit["rows"]),
           "relit": relit(fit["bsdf"], truth_bsdf, probe, data)}
    row.update(brdf_scores(fit["bsdf"], samples))
    row.update(map_scores(fit["map"], seen, truth))
    return row


def point_case(material, data, clean=None, res=RES) -> dict:
    """The point light with a blocker, and its clean twin (module doc; ``clean`` as
    :func:`map_case`'s)."""
    from mi_dsbrdf.evaluation.experiment import light_at
    from mi_dsbrdf.evaluation.metrics import direction_error_deg
    from mi_dsbrdf.model.build import loo_model
    nbrdf = os.path.join(data, "merl", "merl_nbrdf_weights.npz")
    truth_bsdf = {"type": "merl", "nbrdf": nbrdf, "material": material}
    d = light_at(POINT_ANGLE)
    # the camera looks down from +y: light_at's viewer is +z, so tilt it up as the camera is
    side = np.cross(d, [0.0, 1.0, 0.0])
    blocker = (1.0 + BLOCKER_ALONG * (POINT_DISTANCE - 1.0)) * d + BLOCKER_SIDE * side / np.linalg.norm(side)
    light = {"type": "point", "position": [float(v) for v in POINT_DISTANCE * d], "intensity":
             {"type": "rgb", "value": [40.0, 40.0, 40.0]}}
    model = loo_model(material, CACHE)
    name = "%s-point%g-blocker" % (material, POINT_ANGLE)
    out = {"case": name, "material": material, "object": "sphere"}
    if clean is not None:
        out["clean"] = clean
    for kind, ground, integrator in (("scene", True, PATH), ("clean", False, {"type": "direct"})):
        if kind in out:
            continue
        stop = blocker if kind == "scene" else None
        img, mask = photograph(scene_dict("sphere", truth_bsdf, light, integrator, ground, stop, res), name,
                               kind == "clean")
        result, seconds = recover_case(scene_dict("sphere", {"type": "dsbrdf"}, light, {"type": "direct"}, ground,
                                                  stop, res), img.astype(np.float32), model)
        out[kind] = {"seconds": seconds, "direction_error_deg": direction_error_deg(result.light["direction"], d),
                     "needs": result.log["needs"], "residual": result.log["residual"]}
        if kind == "scene":
            lit = img[mask].max(axis=1)
            out["scene"]["shadowed_fraction"] = float(np.mean(lit < 0.05 * np.quantile(lit, 0.9)))
    return out


def cases(which, limit):
    materials, probes = ((VALIDATION_MATERIALS, VALIDATION_PROBES) if which == "validation"
                         else (REPORT_MATERIALS, REPORT_PROBES))
    materials = materials[:limit] if limit else materials
    return [(m, probes[i % len(probes)], o) for i, m in enumerate(materials) for o in OBJECTS]


#: --bounce: the forward model's image side and map (texels), Mitsuba's spp
BOUNCE_RES, BOUNCE_MAP, BOUNCE_SPP = 96, (32, 64), 1024


def bounce_case(material, probe, obj, data) -> dict:
    """How much of a path-traced image the forward model misses by leaving out the
    ground's light, and how much its one-bounce term (:mod:`mi_dsbrdf.inference.bounce`)
    recovers.

    The object carries ``material``'s DSBRDF fit (the shipped library's: no
    material error), under the probe at :data:`BOUNCE_MAP` written in texel blocks
    (both renderers see one map). Relative L1 over the object's interior pixels of
    the texel sum (2 x 2 directions a texel, shadow rays through the scene), without
    and with the ground's bounce, against Mitsuba's ``direct`` render (what the sum
    without the bounce models) and its ``path`` render (max depth :data:`MAX_DEPTH`)."""
    import mitsuba as mi

    from mi_dsbrdf.evaluation.experiment import downsample, dsbrdf_bsdf
    from mi_dsbrdf.inference.forward import TexelSum
    from mi_dsbrdf.inference.images import read_image
    from mi_dsbrdf.inference.latlong import texel_blocks
    from mi_dsbrdf.inference.lobes import LobeSum
    from mi_dsbrdf.inference.pixels import interior
    from mi_dsbrdf.model.model_file import shipped_model
    L = downsample(read_image(os.path.join(data, "envmaps", probe)), *BOUNCE_MAP).astype(np.float32)
    fit = shipped_model().library_material(material)
    bsdf = dsbrdf_bsdf(fit)
    light = {"type": "envmap", "bitmap": mi.Bitmap(texel_blocks(L))}
    scene = mi.load_dict(scene_dict(obj, bsdf, light, {"type": "direct", "hide_emitters": True}, True,
                                    res=BOUNCE_RES))
    shape = [x for x in scene.shapes() if x.id() == "object"][0]
    others = tuple(x for x in scene.shapes() if x.id() != "object")
    images = {}
    for name, surfaces in (("sum", ()), ("sum_bounce", others)):
        ts = TexelSum(scene, shape, BOUNCE_MAP, visibility=True, samples=2, surfaces=surfaces)
        images[name] = LobeSum(ts).render(fit, L.reshape(-1, 3))
    keep = interior(ts.mask).reshape(-1)[ts.pixels]
    out = {"case": "%s-%s-%s" % (material, os.path.splitext(os.path.basename(probe))[0], obj),
           "ground_pairs": float(ts.bounces[0].blocked.mean())}
    for name, integrator in (("direct", {"type": "direct"}), ("path", PATH)):
        s = mi.load_dict(scene_dict(obj, bsdf, light, integrator, True, res=BOUNCE_RES))
        photo = np.array(mi.render(s, spp=BOUNCE_SPP, seed=2), dtype=np.float64).reshape(-1, 3)[ts.pixels][keep]
        for model, image in images.items():
            out["%s_vs_%s" % (model, name)] = float(np.abs(image[keep] - photo).sum() / np.abs(photo).sum())
    return out


MEASURES = ("brdf_eq20_paper", "brdf_eq20_cosine", "map_paper", "map_cosine", "relit")


def summarise(rows, point, command) -> dict:
    """Medians, ratios and counts of the map cases (the issue's targets), and the point case."""
    def med(kind, key):
        return float(np.median([r[kind][key] for r in rows]))
    out = {"command": command, "cases": len(rows), "median": {}, "better_than_nothing": {}, "better_than_adam": {}}
    for kind in ("scene", "clean", "nothing", "adam"):
        out["median"][kind] = {k: med(kind, k) for k in MEASURES}
    for k in MEASURES:
        out["better_than_nothing"][k] = int(sum(r["scene"][k] < r["nothing"][k] for r in rows))
        out["better_than_adam"][k] = int(sum(r["scene"][k] < r["adam"][k] for r in rows))
    out["adam_iterations"] = med("adam", "iterations")
    out["relit_scene_over_clean"] = float(np.median([r["scene"]["relit"] / r["clean"]["relit"] for r in rows]))
    out["time_scene_over_clean"] = float(np.median([r["scene"]["seconds"] / r["clean"]["seconds"] for r in rows]))
    out["seconds"] = {"scene": med("scene", "seconds"), "clean": med("clean", "seconds")}
    out["point"] = point
    out["rows"] = [{"case": r["case"], **{"%s_%s" % (kind, k): round(r[kind][k], 4)
                                          for kind in ("scene", "clean", "nothing", "adam") for k in MEASURES},
                    "scene_seconds": round(r["scene"]["seconds"], 1),
                    "clean_seconds": round(r["clean"]["seconds"], 1)} for r in rows]
    return out


def table(s) -> str:
    n = s["cases"]
    lines = ["%d map cases: median (scene as photographed | clean twin | doing nothing | principled + Adam at "
             "the same time, median %d iterations), and how many of the scene's beat doing nothing and Adam"
             % (n, s["adam_iterations"]),
             "%-18s %8s %8s %8s %8s  %s" % ("measure", "scene", "clean", "nothing", "adam", "beats: nothing, adam")]
    for k in MEASURES:
        lines.append("%-18s %8.3f %8.3f %8.3f %8.3f   %d, %d of %d" % (
            k, s["median"]["scene"][k], s["median"]["clean"][k], s["median"]["nothing"][k], s["median"]["adam"][k],
            s["better_than_nothing"][k], s["better_than_adam"][k], n))
    lines.append("relit, scene over clean twin (median of ratios): %.2f (target <= 1.25)"
                 % s["relit_scene_over_clean"])
    lines.append("time, scene over clean twin (median of ratios): %.2f (target <= 1.5); median %.1f s against %.1f s"
                 % (s["time_scene_over_clean"], s["seconds"]["scene"], s["seconds"]["clean"]))
    p = s.get("point")
    if p:
        lines.append("point light with a blocker (%s): %.2f deg off (target <= 2; clean twin %.2f deg), "
                     "%.0f %% of the sphere's pixels in shadow, %.1f s against %.1f s" % (
                         p["case"], p["scene"]["direction_error_deg"], p["clean"]["direction_error_deg"],
                         100 * p["scene"]["shadowed_fraction"], p["scene"]["seconds"], p["clean"]["seconds"]))
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", choices=("validation", "report"), default="validation")
    ap.add_argument("--limit", type=int, default=0, help="the first N materials (0: all)")
    ap.add_argument("--fresh", action="store_true", help="rerun cases whose results are kept")
    ap.add_argument("--bounce", action="store_true",
                    help="no recovery: the forward model against Mitsuba's direct and path renders, with and "
                         "without a one-bounce ground term (bounce_case), on the set's cases")
    ap.add_argument("--clean-from", metavar="FOLDER",
                    help="take the clean twins' results from out/scenes_photographed/FOLDER (they do not depend "
                         "on the scene's other shapes)")
    ap.add_argument("--res", type=int, default=RES, help="the photographs' side in pixels (default %(default)s)")
    ap.add_argument("--tag", default="", help="suffix of the result folder and the summary's name")
    ap.add_argument("--data", default=DATA)
    args = ap.parse_args(argv)
    if not have_data(args.data):
        sys.exit("needs ../shared/data (MERL fits and light probes)")
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    if args.bounce:
        rows = [bounce_case(m, p, o, args.data) for m, p, o in cases(args.set, args.limit)]
        keys = ("sum_vs_direct", "sum_vs_path", "sum_bounce_vs_path", "sum_bounce_vs_direct")
        print("%-44s %s" % ("case (relative L1, interior pixels)", " ".join("%20s" % k for k in keys)))
        for r in rows:
            print("%-44s %s" % (r["case"], " ".join("%20.3f" % r[k] for k in keys)), flush=True)
        summary = {"command": "python benchmarks/scenes_photographed.py --bounce --set %s%s" % (
            args.set, " --limit %d" % args.limit if args.limit else ""),
            "median": {k: float(np.median([r[k] for r in rows])) for k in keys}, "rows": rows}
        print("median", " ".join("%s %.3f" % kv for kv in summary["median"].items()))
        with open(os.path.join(RESULTS, "scenes_photographed_bounce_%s.json" % args.set), "w") as f:
            json.dump(summary, f, indent=1)
        return
    tag = args.set + ("" if args.res == RES else "_%d" % args.res) + ("_" + args.tag if args.tag else "")
    folder = os.path.join(OUT, "scenes_photographed", tag)
    os.makedirs(folder, exist_ok=True)

    def run(name, fn, *a):
        path = os.path.join(folder, name + ".json")
        if os.path.exists(path) and not args.fresh:
            with open(path) as f:
                return json.load(f)
        t0 = time.perf_counter()
        clean = None
        twin = args.clean_from and os.path.join(OUT, "scenes_photographed", args.clean_from, name + ".json")
        if twin and os.path.exists(twin):
            with open(twin) as f:
                clean = json.load(f)["clean"]
        r = fn(*a, args.data, clean, args.res)
        with open(path, "w") as f:
            json.dump(r, f, indent=1)
        print("%-48s %.0f s: relit scene %s clean %s" % (
            name, time.perf_counter() - t0, *(("%.3f" % r[k]["relit"]) if "relit" in r[k] else
                                             ("%.2f deg" % r[k]["direction_error_deg"]) for k in ("scene", "clean"))),
              flush=True)
        return r
    rows = [run("%s-%s-%s" % (m, os.path.splitext(os.path.basename(p))[0], o), map_case, m, p, o)
            for m, p, o in cases(args.set, args.limit)]
    materials = VALIDATION_MATERIALS if args.set == "validation" else REPORT_MATERIALS
    point = run("%s-point-blocker" % materials[0], point_case, materials[0])
    command = "python benchmarks/scenes_photographed.py --set %s%s%s%s" % (
        args.set, " --limit %d" % args.limit if args.limit else "", "" if args.res == RES else " --res %d" % args.res,
        " --tag " + args.tag if args.tag else "")
    s = summarise(rows, point, command)
    print(table(s))
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, "scenes_photographed_%s.json" % tag), "w") as f:
        json.dump(s, f, indent=1)


if __name__ == "__main__":
    main()
