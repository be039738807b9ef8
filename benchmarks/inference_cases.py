"""Inference run time against the issue's targets on this machine.

* a 128x128 sphere under a 32x64 map, full two-pass inference (target <= 120 s);
* a 128x128 sphere under a point light (target <= 30 s).

Truth: a library material rendered by the deterministic forward model (the sky
at twice the map's resolution). The accuracy on MERL materials (leave-one-out
models, point lights and probes, with and without priors) is measured by
``benchmarks/experiments.py``.

    .venv/bin/python benchmarks/inference_cases.py

Writes benchmarks/results/inference.json (the README quotes it).
"""
import dataclasses
import json
import os
import time

import numpy as np

import mi_dsbrdf  # noqa: F401
from mi_dsbrdf.config import PRESETS
from mi_dsbrdf.inference import recover_envmap, recover_light
from mi_dsbrdf.model import model_file as model_data
from mi_dsbrdf.evaluation.experiment import POINT_DISTANCE, light_at, render, texels
from mi_dsbrdf.evaluation.metrics import direction_error_deg
from mi_dsbrdf.inference.latlong import procedural_sky

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MATERIAL = {"type": "dsbrdf", "material": "gold-metallic-paint"}


def runtime_cases():
    model = model_data.shipped_model()
    out = {}
    sky = procedural_sky(64, 128).astype(np.float64)
    img = render(texels(MATERIAL, 128, (64, 128)), sky.reshape(-1, 3))
    cfg = PRESETS["benchmarked"]
    ts = texels({"type": "dsbrdf"}, 128, (32, 64))
    t0 = time.perf_counter()
    rows = recover_envmap(ts, img, ts.mask, model, cfg).log
    out["envmap_128px_32x64_two_pass"] = {"seconds": time.perf_counter() - t0, "rounds": len(rows),
                                          "target_seconds": 120}
    pos = POINT_DISTANCE * light_at(40)
    img = render(texels(MATERIAL, 128), point=pos)
    ts = texels({"type": "dsbrdf"}, 128)
    t0 = time.perf_counter()
    res = recover_light(ts, img, ts.mask, model, dataclasses.replace(cfg, block_iters=20),
                        point=(np.zeros(3), POINT_DISTANCE))
    rows = res.log
    out["point_light_128px"] = {"seconds": time.perf_counter() - t0, "rounds": len(rows), "target_seconds": 30,
                                "direction_error_deg": direction_error_deg(res.light["direction"], pos)}
    for k, v in out.items():
        print("%-32s %6.1f s (target %d s)" % (k, v["seconds"], v["target_seconds"]), flush=True)
    return out


def main():
    path = os.path.join(ROOT, "benchmarks", "results", "inference.json")
    results = {"runtime": runtime_cases(), "command": "python benchmarks/inference_cases.py"}
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump(results, f, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
