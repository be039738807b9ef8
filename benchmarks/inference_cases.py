"""Inference run time and peak memory against their targets, beside Mitsuba's Adam recipe in the same run.

* natural light: a 128x128 sphere under a 32x64 map, full two-pass inference
  (target <= 20 s, and <= 1.5x principled + Adam), on the shipped pixel budget
  (``Config.map_pairs``: 4096 of the image's 12.4k usable pixels) and, to show what
  the budget costs in accuracy, on all of them; every method on the app's pixels
  (:func:`mi_dsbrdf.inference.pixels.usable_pixels`: the silhouette ring dropped);
  beside it, the same without the highlight check (``highlight_texels`` 0), for its cost;
* principled + envmap by Adam through ``prb``, 150 iterations at 8 spp, on the
  same image (the recipe of Mitsuba's tutorials, :mod:`mi_dsbrdf.evaluation.adam`);
* a point light: a 128x128 sphere photographed through 8x8 rays a pixel (target <= 5 s),
  recovered with the shipped rays a pixel (``Config.pixel_rays``) and, beside it for the
  ratio, with the centre ray alone.

``--sizes 128 512 2048 ...`` runs instead the photograph at its own size: a sphere
covering about half the frame (camera fov 34 degrees) under the sky, rendered by
Mitsuba (the same samples per 128 px working pixel at every size), recovered from
its EXR by :func:`mi_dsbrdf.recover` with the defaults and saved (what ``mi-dsbrdf
recover`` does). Each size is photographed ``--seeds`` times, each with its own
camera noise: a recovery's error swings by up to 1.3x between photographs that
differ only by noise, so one photograph a size cannot tell a size's effect from
chance. It prints every run, then each size's medians (time, both conventions of
Eq. 20, the map's error; the largest peak memory) and their ratios to the 128 px
medians (targets: time <= 1.5x, peak memory <= 1.5 GB more, errors no worse).

Truth: a library material rendered by the deterministic forward model (the sky
at twice the map's resolution). Each case runs in a fresh process (spawned one
after the other, never two at once), which reports its wall time and peak
resident memory (``ru_maxrss``, so the figure includes Mitsuba's and the
interpreter's own footprint). Accuracy is measured by ``benchmarks/experiments.py``
and ``benchmarks/error_vs_time.py``; the error of these runs is printed as a check
(the map's, and the BRDF's against the true material in both conventions of Eq. 20).

    .venv/bin/python benchmarks/inference_cases.py      # ~3 min
    .venv/bin/python benchmarks/inference_cases.py --sizes 128 512 1024 --seeds 3   # ~1 min a run

Writes benchmarks/results/inference.json (the README quotes it) with the default
``--out``; ``--sizes`` writes benchmarks/results/inference_sizes.json.
"""
import argparse
import json
import multiprocessing as mp
import os
import platform

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MATERIAL = "gold-metallic-paint"
TARGETS = {"envmap_128px_32x64_two_pass": 20.0, "point_light_128px": 5.0}
MAX_RATIO_TO_ADAM = 1.5
#: --sizes: the targets against the 128 px run (time ratio, extra peak memory in MB)
MAX_SIZE_TIME_RATIO, MAX_SIZE_EXTRA_MB = 1.5, 1536
#: --sizes: camera field of view (degrees; the unit sphere covers about half the frame),
#: Mitsuba samples per pixel at 128 px (fewer at larger sizes: the same per working pixel)
SIZE_FOV, SIZE_SPP_128 = 34.0, 2048


def envmap_case(res=128):
    """The natural-light case: (sky (64, 128, 3), the image of MATERIAL under it
    (res x res, from the sky's texel centres), a ``dsbrdf`` view at 32x64)."""
    import numpy as np
    from mi_dsbrdf.evaluation.experiment import render, texels
    from mi_dsbrdf.inference.latlong import procedural_sky
    sky = procedural_sky(64, 128).astype(np.float64)
    img = render(texels({"type": "dsbrdf", "material": MATERIAL}, res, (64, 128)), sky.reshape(-1, 3))
    return sky, img, texels({"type": "dsbrdf"}, res, (32, 64))


def _case(name, queue):
    import dataclasses
    import resource
    import time

    import numpy as np

    import mi_dsbrdf  # noqa: F401  (imports Mitsuba, registers the plugins)
    from mi_dsbrdf.config import Config
    from mi_dsbrdf.evaluation.adam import adam_recover
    from mi_dsbrdf.evaluation.experiment import PHOTO_PIXEL_RAYS, POINT_DISTANCE, downsample, light_at, render, texels
    from mi_dsbrdf.evaluation.metrics import direction_error_deg, material_errors, scale_invariant_log_error
    from mi_dsbrdf.inference import recover_envmap, recover_light
    from mi_dsbrdf.inference.pixels import usable_pixels
    from mi_dsbrdf.model import model_file as model_data
    from mi_dsbrdf.model.samples import samples_from_function

    model = model_data.shipped_model()
    cfg = Config()                       # the defaults
    truth = {"type": "dsbrdf", "material": MATERIAL}
    out = {}
    if name.startswith("point_light_128px"):
        pos = POINT_DISTANCE * light_at(40)
        img = render(texels(truth, 128, pixel_rays=PHOTO_PIXEL_RAYS), point=pos)
        # the shipped rays a pixel, or the centre ray alone (beside it, for the ratio)
        ts = texels({"type": "dsbrdf"}, 128, pixel_rays=1 if name.endswith("centre_ray") else cfg.pixel_rays)
        t0 = time.perf_counter()
        res = recover_light(ts, img, usable_pixels(ts.mask, img), model, dataclasses.replace(cfg, block_iters=20),
                            point=(np.zeros(3), POINT_DISTANCE))
        out["seconds"] = time.perf_counter() - t0
        out["direction_error_deg"] = direction_error_deg(res.light["direction"], pos)
    else:
        sky, img, ts = envmap_case()
        t0 = time.perf_counter()
        if name == "principled_adam_150it_8spp":
            fit = adam_recover(img, usable_pixels(ts.mask, img), 128, (32, 64), "principled-adam", spp=8, iters=150)
            out["seconds"] = time.perf_counter() - t0
            recovered = fit["map"]
        else:
            if name.endswith("all_pixels"):
                cfg = dataclasses.replace(cfg, map_pairs=1 << 40)
            if name.endswith("no_highlight_check"):
                cfg = dataclasses.replace(cfg, highlight_texels=0)
            res = recover_envmap(ts, img, usable_pixels(ts.mask, img), model, cfg)
            out["seconds"] = time.perf_counter() - t0
            out["rounds"] = len(res.log)
            out["highlight_change"], out["highlight_texels"] = res.highlight_change, res.highlight_texels
            recovered = res.illumination
            true_material = model.library_material(MATERIAL)
            samples = samples_from_function(lambda th, td, pd: true_material.eval(th, td))
            out["brdf_eq20"] = material_errors(res.material, samples)
        small = downsample(sky, 32, 64)
        out["illumination_error"] = scale_invariant_log_error(recovered, small, np.ones((32, 64), bool))
    out["peak_memory_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    queue.put(out)


def _sphere_scene(res, bsdf, sky):
    import mitsuba as mi
    from mi_dsbrdf.inference.scene_dicts import camera
    return {"type": "scene", "integrator": {"type": "direct", "hide_emitters": True},
            "sensor": camera(res, SIZE_FOV), "object": {"type": "sphere", "bsdf": bsdf},
            "light": {"type": "envmap", "bitmap": mi.Bitmap(sky)}}


def _render_size(res, seed, path, queue):
    """Render the truth at ``res`` pixels with Mitsuba's ``seed`` into ``path`` (a
    process of its own)."""
    import mitsuba as mi
    import numpy as np

    import mi_dsbrdf  # noqa: F401
    from mi_dsbrdf.app.io import write_exr
    from mi_dsbrdf.inference.latlong import procedural_sky
    sky = procedural_sky(64, 128).astype(np.float32)
    spp = max(1, round(SIZE_SPP_128 * (128 / res) ** 2))
    img = mi.render(mi.load_dict(_sphere_scene(res, {"type": "dsbrdf", "material": MATERIAL}, sky)), spp=spp, seed=seed)
    write_exr(path, np.array(img, dtype=np.float32))
    queue.put({"spp": spp})


def _size_case(res, path, out, queue):
    """Recover the sphere of ``res`` pixels from its EXR ``path`` and save it into
    ``out``: seconds, peak memory, working grid and errors."""
    import resource
    import time

    import numpy as np

    import mi_dsbrdf
    from mi_dsbrdf.evaluation.experiment import downsample, dsbrdf_bsdf, render, texels
    from mi_dsbrdf.evaluation.metrics import material_errors, scale_invariant_log_error
    from mi_dsbrdf.inference.latlong import procedural_sky
    from mi_dsbrdf.model import model_file as model_data
    from mi_dsbrdf.model.samples import samples_from_function

    sky = procedural_sky(64, 128)
    scene = _sphere_scene(res, {"type": "dsbrdf"}, sky.astype(np.float32))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    t0 = time.perf_counter()
    result = mi_dsbrdf.recover(scene, path)
    seconds = time.perf_counter() - t0
    result.save(out)
    total = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    model = model_data.shipped_model()
    truth = model.library_material(MATERIAL)
    samples = samples_from_function(lambda th, td, pd: truth.eval(th, td))
    H, W = result.illumination.shape[:2]
    all_texels = np.ones((H, W), bool)
    # relit: a 48 px sphere under the sky turned by 90 degrees, against the truth's
    turned = np.roll(downsample(sky, 32, 64), 16, axis=1).reshape(-1, 3)
    relit_truth = render(texels({"type": "dsbrdf", "material": MATERIAL}, 48, (32, 64)), turned)
    on = texels({"type": "dsbrdf"}, 48, (32, 64)).mask

    def relit(material):
        return scale_invariant_log_error(render(texels(dsbrdf_bsdf(material), 48, (32, 64)), turned),
                                         relit_truth, on)
    errors = material_errors(result.material, samples)
    mean = material_errors(model.mean_material(), samples)
    queue.put({"seconds": seconds, "seconds_with_save": total, "memory_before_mb": before, "peak_memory_mb": peak,
               "working_grid": result.log["working_grid"], "used_pixels": result.log["used_pixels"],
               "brdf_eq20": {"paper": errors["paper"], "cosine": errors["cosine"]},
               "illumination_error": scale_invariant_log_error(result.illumination, downsample(sky, H, W),
                                                               all_texels),
               "relit_error": relit(result.material),
               # doing nothing: the model's mean material, a constant map
               "do_nothing": {"brdf_eq20": {"paper": mean["paper"], "cosine": mean["cosine"]},
                              "illumination_error": scale_invariant_log_error(
                                  np.ones((H, W, 3)), downsample(sky, H, W), all_texels),
                              "relit_error": relit(model.mean_material())}})


def _median(runs, *keys):
    import numpy as np
    values = []
    for r in runs:
        for k in keys:
            r = r[k]
        values.append(r)
    return float(np.median(values))


def run_sizes(sizes, seeds, out_json):
    """``--sizes``: each size rendered with each of ``seeds`` (its own camera noise),
    then recovered, in fresh processes, one after the other; the table on stdout and
    in ``out_json``. A size's figures are the medians over its seeds (the peak memory
    is the largest), and its ratios are to the 128 px medians."""
    import tempfile
    sizes = [128] + [s for s in sizes if s != 128]        # the reference first
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for res in sizes:
            runs = []
            for seed in seeds:
                path = os.path.join(tmp, "sphere_%d_%d.exr" % (res, seed))
                rendered = run(_render_size, res, seed, path)
                r = dict(run(_size_case, res, path, os.path.join(tmp, "result_%d_%d" % (res, seed))),
                         seed=seed, **rendered)
                runs.append(r)
                print("%5d px  seed %d  %6.1f s  peak %6.0f MB  BRDF Eq. 20 paper %.3f, cosine %.3f  map %.3f  "
                      "relit %.3f" % (res, seed, r["seconds"], r["peak_memory_mb"], r["brdf_eq20"]["paper"],
                                      r["brdf_eq20"]["cosine"], r["illumination_error"], r["relit_error"]),
                      flush=True)
            results[res] = r = {
                "runs": runs, "working_grid": runs[0]["working_grid"], "spp": runs[0]["spp"],
                "seconds": _median(runs, "seconds"),
                "peak_memory_mb": max(x["peak_memory_mb"] for x in runs),
                "brdf_eq20": {"paper": _median(runs, "brdf_eq20", "paper"),
                              "cosine": _median(runs, "brdf_eq20", "cosine")},
                "illumination_error": _median(runs, "illumination_error"),
                "relit_error": _median(runs, "relit_error"), "do_nothing": runs[0]["do_nothing"]}
            ref = results[128]
            r["time_ratio"] = r["seconds"] / ref["seconds"]
            r["extra_memory_mb"] = r["peak_memory_mb"] - ref["peak_memory_mb"]
            r["error_ratios"] = {"paper": r["brdf_eq20"]["paper"] / ref["brdf_eq20"]["paper"],
                                 "cosine": r["brdf_eq20"]["cosine"] / ref["brdf_eq20"]["cosine"],
                                 "map": r["illumination_error"] / ref["illumination_error"],
                                 "relit": r["relit_error"] / ref["relit_error"]}
    print("median over seeds %s; ratios to the 128 px medians:" % ", ".join(map(str, seeds)))
    for res, r in results.items():
        g = r["working_grid"]
        print("%5d px  %6.1f s (%4.2fx)  peak %6.0f MB (%+6.0f)  grid %dx%d /%d  "
              "BRDF Eq. 20 paper %.3f (%4.2fx), cosine %.3f (%4.2fx)  map %.3f (%4.2fx)  relit %.3f (%4.2fx)" % (
                  res, r["seconds"], r["time_ratio"], r["peak_memory_mb"], r["extra_memory_mb"],
                  g["working"][0], g["working"][1], g["block"], r["brdf_eq20"]["paper"],
                  r["error_ratios"]["paper"], r["brdf_eq20"]["cosine"], r["error_ratios"]["cosine"],
                  r["illumination_error"], r["error_ratios"]["map"], r["relit_error"], r["error_ratios"]["relit"]))
    nothing = results[128]["do_nothing"]
    print("doing nothing (the model's mean material, a constant map): BRDF Eq. 20 paper %.3f, cosine %.3f  "
          "map %.3f  relit %.3f" % (nothing["brdf_eq20"]["paper"], nothing["brdf_eq20"]["cosine"],
                                    nothing["illumination_error"], nothing["relit_error"]))
    print("targets against 128 px: time <= %gx, peak memory <= %+d MB, errors no worse (ratios <= 1)"
          % (MAX_SIZE_TIME_RATIO, MAX_SIZE_EXTRA_MB))
    os.makedirs(os.path.dirname(out_json), exist_ok=True)
    with open(out_json, "w") as f:
        json.dump({"sizes": {str(k): v for k, v in results.items()}, "material": MATERIAL, "fov": SIZE_FOV,
                   "seeds": list(seeds),
                   "targets": {"time_ratio": MAX_SIZE_TIME_RATIO, "extra_memory_mb": MAX_SIZE_EXTRA_MB},
                   "machine": "%s, %d cores" % (platform.machine(), os.cpu_count()),
                   "command": "python benchmarks/inference_cases.py --sizes %s --seeds %d"
                              % (" ".join(map(str, sizes)), len(seeds))},
                  f, indent=1, sort_keys=True)


def run(target, *args) -> dict:
    """``target(*args, queue)`` in a fresh process: the dict it puts on the queue
    (seconds, peak_memory_mb, ...). Raises if the process dies without one."""
    import queue as queues
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=target, args=args + (queue,))
    proc.start()
    while True:
        try:
            out = queue.get(timeout=2.0)
            break
        except queues.Empty:
            if not proc.is_alive():
                try:
                    out = queue.get(timeout=2.0)
                    break
                except queues.Empty:
                    raise RuntimeError("%s%r ended with exit code %s and no result"
                                       % (target.__name__, args, proc.exitcode)) from None
    proc.join()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=None,
                    help="the summary file (default benchmarks/results/inference.json, with --sizes "
                         "inference_sizes.json)")
    ap.add_argument("--sizes", type=int, nargs="+", default=None, metavar="PX",
                    help="instead: the sphere photographed at each of these sizes (square, pixels)")
    ap.add_argument("--seeds", type=int, default=3, metavar="N",
                    help="with --sizes: photographs a size, each with its own camera noise (default 3); "
                         "a size's figures are their medians")
    args = ap.parse_args(argv)
    if args.sizes:
        return run_sizes(args.sizes, range(1, args.seeds + 1),
                         args.out or os.path.join(ROOT, "benchmarks", "results", "inference_sizes.json"))
    results = {name: run(_case, name) for name in
               ("envmap_128px_32x64_two_pass", "envmap_128px_32x64_two_pass_no_highlight_check",
                "principled_adam_150it_8spp", "point_light_128px", "point_light_128px_centre_ray",
                "envmap_128px_32x64_two_pass_all_pixels")}
    ratio = results["envmap_128px_32x64_two_pass"]["seconds"] / results["principled_adam_150it_8spp"]["seconds"]
    for name, r in results.items():
        target = TARGETS.get(name)
        print("%-40s %6.1f s  peak %5.0f MB%s%s%s" % (
            name, r["seconds"], r["peak_memory_mb"], "  (target <= %g s)" % target if target else "",
            "  illumination error %.3f" % r["illumination_error"] if "illumination_error" in r else
            "  direction error %.3f deg" % r["direction_error_deg"],
            "  BRDF Eq. 20 paper %.3f, cosine %.3f" % (r["brdf_eq20"]["paper"], r["brdf_eq20"]["cosine"])
            if "brdf_eq20" in r else ""))
    print("natural light / principled + Adam: %.2fx (target <= %g)" % (ratio, MAX_RATIO_TO_ADAM))
    from mi_dsbrdf.config import Config
    rays = Config().pixel_rays
    print("point light, %d x %d rays a pixel / the centre ray: %.2fx" % (
        rays, rays,
        results["point_light_128px"]["seconds"] / results["point_light_128px_centre_ray"]["seconds"]))
    print("natural light, with the highlight check / without (highlight_texels 0): %.2fx, peak %+.0f MB" % (
        results["envmap_128px_32x64_two_pass"]["seconds"]
        / results["envmap_128px_32x64_two_pass_no_highlight_check"]["seconds"],
        results["envmap_128px_32x64_two_pass"]["peak_memory_mb"]
        - results["envmap_128px_32x64_two_pass_no_highlight_check"]["peak_memory_mb"]))
    path = args.out or os.path.join(ROOT, "benchmarks", "results", "inference.json")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump({"runtime": results, "ratio_to_principled_adam": ratio, "targets_seconds": TARGETS,
                   "machine": "%s, %d cores" % (platform.machine(), os.cpu_count()),
                   "command": "python benchmarks/inference_cases.py"}, f, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
