"""dsbrdf vs Mitsuba's built-in roughconductor: render time ratio and BSDF throughput.

Renders the same sphere-under-envmap scene (same resolution, spp, integrator)
with each BSDF in one process, alternating them over several repetitions after
a warm-up (kernel compilation), and prints median times, their ratio (target
<= 1.5) and BSDF evaluations per second. Writes benchmarks/results/bsdf.json.

    .venv/bin/python benchmarks/bench_bsdf.py [--res 256] [--spp 64] [--reps 5]
"""
import argparse
import json
import os
import platform
import time

import numpy as np

import mi_dsbrdf  # noqa: F401
import drjit as dr
import mitsuba as mi
from mi_dsbrdf.app.scenes import scene_path

BSDFS = {
    "dsbrdf": {"type": "dsbrdf", "lobes": 2, "kappa_0": "0.5", "gamma_0": "1",
               "kappa_1": "2 2 2.5 3 4 6", "gamma_1": "120", "chromaticity_1": "0.45 0.35 0.2"},
    "roughconductor": {"type": "roughconductor", "material": "Au", "alpha": 0.1},
}


def scene_with(bsdf, res, spp):
    scene = mi.load_file(scene_path("sphere_envmap"), res=str(res), spp=str(spp))
    d = {"type": "scene", "integrator": {"type": "direct"}, "sensor": scene.sensors()[0],
         "object": {"type": "sphere", "bsdf": bsdf}, "emitter": scene.emitters()[0]}
    return mi.load_dict(d)


def time_render(scene, spp, seed):
    t0 = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    return time.perf_counter() - t0


def bsdf_throughput(bsdf, n=2_000_000, reps=5):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    rng = np.random.default_rng(0)
    ct = rng.uniform(0.05, 1, n)
    st = np.sqrt(1 - ct ** 2)
    si.wi = mi.Vector3f(st, 0 * st, ct)
    wo = dr.normalize(mi.Vector3f(rng.normal(size=n), rng.normal(size=n), np.abs(rng.normal(size=n))))
    ctx = mi.BSDFContext()
    dr.eval(si, wo)
    times = []
    for _ in range(reps + 1):
        t0 = time.perf_counter()
        dr.eval(bsdf.eval(ctx, si, wo))
        dr.sync_thread()
        times.append(time.perf_counter() - t0)
    return n / float(np.median(times[1:]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "results", "bsdf.json"))
    args = ap.parse_args()
    scenes = {k: scene_with(v, args.res, args.spp) for k, v in BSDFS.items()}
    for k, s in scenes.items():  # warm-up: compile kernels
        time_render(s, args.spp, 0)
    times = {k: [] for k in scenes}
    for rep in range(args.reps):  # alternate, so machine noise hits both alike
        for k, s in scenes.items():
            times[k].append(time_render(s, args.spp, rep + 1))
    med = {k: float(np.median(v)) for k, v in times.items()}
    ratio = med["dsbrdf"] / med["roughconductor"]
    evals = {k: bsdf_throughput(mi.load_dict(v)) for k, v in BSDFS.items()}
    result = {"res": args.res, "spp": args.spp, "reps": args.reps, "median_seconds": med,
              "time_ratio_dsbrdf_over_roughconductor": ratio, "target_ratio": 1.5,
              "bsdf_evals_per_second": evals, "machine": platform.processor() or platform.machine(),
              "cores": os.cpu_count(), "mitsuba": mi.__version__, "drjit": dr.__version__}
    for k in scenes:
        print("%-15s median render %.3f s   BSDF eval %.3g evals/s" % (k, med[k], evals[k]))
    print("time ratio dsbrdf / roughconductor: %.2f (target <= 1.5)" % ratio)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(result, f, indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
