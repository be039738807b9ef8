"""Inference run time and peak memory against their targets, beside Mitsuba's Adam recipe in the same run.

* natural light: a 128x128 sphere under a 32x64 map, full two-pass inference
  (target <= 20 s, and <= 1.5x principled + Adam), on the shipped pixel budget
  (``Config.map_pairs``: 4096 of the image's 12.4k usable pixels) and, to show what
  the budget costs in accuracy, on all of them; every method on the app's pixels
  (:func:`mi_dsbrdf.inference.pixels.usable_pixels`: the silhouette ring dropped);
* principled + envmap by Adam through ``prb``, 150 iterations at 8 spp, on the
  same image (the recipe of Mitsuba's tutorials, :mod:`mi_dsbrdf.evaluation.adam`);
* a point light: a 128x128 sphere (target <= 5 s).

Truth: a library material rendered by the deterministic forward model (the sky
at twice the map's resolution). Each case runs in a fresh process (spawned one
after the other, never two at once), which reports its wall time and peak
resident memory (``ru_maxrss``, so the figure includes Mitsuba's and the
interpreter's own footprint). Accuracy is measured by ``benchmarks/experiments.py``
and ``benchmarks/error_vs_time.py``; the error of these runs is printed as a check
(the map's, and the BRDF's against the true material in both conventions of Eq. 20).

    .venv/bin/python benchmarks/inference_cases.py      # ~3 min

Writes benchmarks/results/inference.json (the README quotes it) with the default
``--out``.
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
    from mi_dsbrdf.evaluation.experiment import POINT_DISTANCE, downsample, light_at, render, texels
    from mi_dsbrdf.evaluation.metrics import direction_error_deg, material_errors, scale_invariant_log_error
    from mi_dsbrdf.inference import recover_envmap, recover_light
    from mi_dsbrdf.inference.pixels import usable_pixels
    from mi_dsbrdf.model import model_file as model_data
    from mi_dsbrdf.model.samples import samples_from_function

    model = model_data.shipped_model()
    cfg = Config()                       # the defaults
    truth = {"type": "dsbrdf", "material": MATERIAL}
    out = {}
    if name == "point_light_128px":
        pos = POINT_DISTANCE * light_at(40)
        img = render(texels(truth, 128), point=pos)
        ts = texels({"type": "dsbrdf"}, 128)
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
            res = recover_envmap(ts, img, usable_pixels(ts.mask, img), model, cfg)
            out["seconds"] = time.perf_counter() - t0
            out["rounds"] = len(res.log)
            recovered = res.illumination
            true_material = model.library_material(MATERIAL)
            samples = samples_from_function(lambda th, td, pd: true_material.eval(th, td))
            out["brdf_eq20"] = material_errors(res.material, samples)
        small = downsample(sky, 32, 64)
        out["illumination_error"] = scale_invariant_log_error(recovered, small, np.ones((32, 64), bool))
    out["peak_memory_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    queue.put(out)


def run(name) -> dict:
    """One case in a fresh process: its figures (seconds, peak_memory_mb, ...)."""
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_case, args=(name, queue))
    proc.start()
    out = queue.get()
    proc.join()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "inference.json"),
                    help="the summary file (default %(default)s)")
    args = ap.parse_args(argv)
    results = {name: run(name) for name in
               ("envmap_128px_32x64_two_pass", "principled_adam_150it_8spp", "point_light_128px",
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
    path = args.out
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump({"runtime": results, "ratio_to_principled_adam": ratio, "targets_seconds": TARGETS,
                   "machine": "%s, %d cores" % (platform.machine(), os.cpu_count()),
                   "command": "python benchmarks/inference_cases.py"}, f, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
