"""How far is the texel-centre forward model from the image of the same map?

:class:`~mi_dsbrdf.inference.forward.TexelSum` lights each pixel from the
centre of every texel of the lat-long map, each with its texel's solid angle.
A camera (or an independent renderer) sees the map as a piecewise-constant
function of direction, integrated over each texel's footprint. For a lobe
narrower than the texel spacing the two differ: the centre sum sparkles where
the integral is smooth. This script measures that difference, with the
measured (MERL) material, per map size:

* **centre vs integrated**: the image of a map of H x W texels from their
  centres, against the same map integrated over 256 x 512 directions (each
  texel as 256 / H x 512 / W of them, each its share of the solid angle);
* **the truth's convergence**: the experiments render their truth from the probe
  downsampled to 64 x 128 (centres); against the probe at its own resolution
  (up to 256 x 512) integrated the same way.

The error is the mean and 90th percentile over the sphere's pixels of
|log(a + o) - log(b + o)|, o = 1e-3 x the mean radiance: the likelihood's
measure (Eq. 19), whose scale b is ``Config.likelihood_scale`` (0.05).
Validation materials and probes only (``natural_light.py``).

    .venv/bin/python benchmarks/texel_sampling.py [--workers 2]   # ~12 min on one worker, 5 GB each
    .venv/bin/python benchmarks/texel_sampling.py --speed   # inference time of five settings side by side, ~4 min

``--speed`` times ``inference_cases.py``'s natural-light case (a 128x128 sphere,
32x64 map, two passes) at the texel centres throughout, at the shipped setting
(centres in the start and the grey pass, 2 x 2 in the colour pass, the colour
split on, one start candidate), the same with the colour split off or with
two start candidates, and at 2 x 2 throughout
(:data:`SPEED_SETTINGS`), in turn, twice each, in one process, and stores the
figures under ``"speed"``.

Writes ``benchmarks/results/texel_sampling.json`` and prints the table.
"""
from __future__ import annotations

import json
import os
import time

import numpy as np

from experiments import DATA
from natural_light import VALIDATION_MATERIALS, VALIDATION_PROBES

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "texel_sampling.json")
#: map sizes of the inference (the start's, the benchmarked one's) and of the experiments' truth
SIZES = [(16, 32), (32, 64), (64, 128)]
#: the truth's reference resolution
FINE = (256, 512)
RES = 64


def log_error(a, b) -> tuple:
    """(mean, 90th percentile) of |log(a + o) - log(b + o)| over pixels and channels."""
    o = 1e-3 * float(np.mean(b))
    e = np.abs(np.log(a + o) - np.log(b + o))
    return float(e.mean()), float(np.percentile(e, 90))


def measure(material, data=DATA) -> list:
    """One row per validation probe (the transports do not depend on the probe)."""
    import mi_dsbrdf  # noqa: F401  (variant)
    from mi_dsbrdf.app.io import read_image
    from mi_dsbrdf.evaluation import experiment as ev
    from mi_dsbrdf.inference.forward import apply_transport
    merl = {"type": "merl", "nbrdf": os.path.join(data, "merl", "merl_nbrdf_weights.npz"), "material": material}
    fine_ts = ev.texels(merl, RES, FINE)
    fine = fine_ts.transport()                    # (3, P, 256 * 512) float32, about 5 GB
    coarse = {hw: ev.texels(merl, RES, hw).transport() for hw in SIZES}
    rows = []
    for probe in VALIDATION_PROBES:
        env = read_image(os.path.join(data, "envmaps", probe))[..., :3]
        row = {"material": material, "probe": probe}
        for (h, w), T in coarse.items():
            m = ev.downsample(env, h, w)
            f = FINE[0] // h                      # each texel as f x f fine directions
            integrated = apply_transport(fine, np.repeat(np.repeat(m, f, axis=0), f, axis=1))
            row["%dx%d" % (h, w)] = log_error(apply_transport(T, m), integrated)
        # the probe at its own resolution up to 256 x 512 (the probulator probes are 128 x 256)
        h0 = min(env.shape[0], FINE[0])
        f = FINE[0] // h0
        probe_map = np.repeat(np.repeat(ev.downsample(env, h0, 2 * h0), f, axis=0), f, axis=1)
        truth = apply_transport(coarse[(64, 128)], ev.downsample(env, 64, 128))
        row["truth_64x128_vs_probe"] = log_error(truth, apply_transport(fine, probe_map))
        rows.append(row)
    return rows


def table(rows) -> str:
    keys = ["%dx%d" % s for s in SIZES] + ["truth_64x128_vs_probe"]
    lines = ["| material | probe | " + " | ".join(k.replace("_", " ") for k in keys) + " |",
             "|---|---|" + "---|" * len(keys)]
    for r in rows:
        lines.append("| %s | %s | " % (r["material"], os.path.basename(r["probe"]).split(".")[0])
                     + " | ".join("%.3f (%.3f)" % tuple(r[k]) for k in keys) + " |")
    return "\n".join(lines)


#: the settings ``--speed`` times: Config overrides of the benchmarked preset (the texel
#: sampling of the start and the grey pass, of the colour pass; the colour split; the
#: number of starts that run the grey pass)
SPEED_SETTINGS = {"centres": dict(grey_texel_samples=1, texel_samples=1), "shipped": {},
                  "shipped, colour split off": dict(w_chromaticity=0.0, w_light_colour=0.0),
                  "shipped, two start candidates": dict(start_candidates=2),
                  "2 throughout": dict(grey_texel_samples=2, texel_samples=2)}


def speed() -> dict:
    """Seconds of the natural-light inference at each of SPEED_SETTINGS, twice
    each in turn (one process, so that the machine's drift hits all alike)."""
    import dataclasses
    import mi_dsbrdf  # noqa: F401
    from inference_cases import envmap_case
    from mi_dsbrdf.config import PRESETS
    from mi_dsbrdf.inference import recover_envmap
    from mi_dsbrdf.inference.pixels import usable_pixels
    from mi_dsbrdf.model import model_file as model_data
    model = model_data.shipped_model()
    _, img, ts = envmap_case()
    mask = usable_pixels(ts.mask, img)     # the app's pixels, as inference_cases.py
    out = {k: [] for k in SPEED_SETTINGS}
    for _ in range(2):
        for name, overrides in SPEED_SETTINGS.items():
            cfg = dataclasses.replace(PRESETS["benchmarked"], **overrides)
            t0 = time.perf_counter()
            recover_envmap(ts, img, mask, model, cfg)
            out[name].append(time.perf_counter() - t0)
            print("%s (grey pass %d, colour pass %d, colour split %s, %d start candidates): %.1f s"
                  % (name, cfg.grey_texel_samples, cfg.texel_samples, "on" if cfg.colour_split else "off",
                     cfg.start_candidates, out[name][-1]), flush=True)
    centres = np.median(out["centres"])
    return {"seconds": out, "settings": SPEED_SETTINGS,
            "ratio_to_centres": {k: float(np.median(v) / centres) for k, v in out.items()}}


def main(argv=None):
    import argparse
    from concurrent.futures import ProcessPoolExecutor
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2, help="processes (each holds a 5 GB transport)")
    ap.add_argument("--speed", action="store_true",
                    help="time the inference at the texel centres, the shipped setting, the shipped setting without "
                         "the colour split or with two start candidates, and 2 x 2 throughout instead")
    args = ap.parse_args(argv)
    if args.speed:
        with open(OUT) as f:
            stored = json.load(f)
        stored["speed"] = dict(speed(), command="python benchmarks/texel_sampling.py --speed")
        with open(OUT, "w") as f:
            json.dump(stored, f, indent=1)
        print("against the texel centres throughout: " + ", ".join(
            "%s %.2fx" % kv for kv in stored["speed"]["ratio_to_centres"].items()))
        return
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:   # processes: Dr.Jit in two threads can crash
        rows = [r for rows in pool.map(measure, VALIDATION_MATERIALS) for r in rows]
    with open(OUT, "w") as f:
        json.dump({"command": "python benchmarks/texel_sampling.py", "fine": FINE, "res": RES, "rows": rows,
                   "seconds": time.perf_counter() - t0}, f, indent=1)
    print("mean (90th percentile) |log error| per pixel and channel; Config.likelihood_scale is 0.05\n")
    print(table(rows))


if __name__ == "__main__":
    main()
