"""Synthetic point-light inference cases: how close the current inference gets.

Renders a library material on a small sphere under a directional light with the
deterministic forward model, then runs ``inference.recover_light`` with
the light known and unknown, and prints the re-render error (mean |log error|),
the BRDF error on the constrained theta_h range and the light-direction error.
Work in progress for issue 4: the figures it prints are the tuning target.

    .venv/bin/python benchmarks/inference_synthetic.py [--iters 40] [--rounds 5]
"""
import argparse
import math
import time

import numpy as np

import mi_dsbrdf  # noqa: F401
from mi_dsbrdf import inference, model_data
from mi_dsbrdf.dsbrdf import Material
from mi_dsbrdf.forward import TexelSum
from mi_dsbrdf.scenes import sphere_scene

RES = 24


def sphere(bsdf):
    return sphere_scene(bsdf, RES)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--material", default="gold-metallic-paint")
    ap.add_argument("--iters", type=int, default=40)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--known-only", action="store_true")
    args = ap.parse_args()
    model = model_data.shipped_model()
    d = inference.direction_from_angles(1.1, 2.6)
    s = sphere({"type": "dsbrdf", "material": args.material})
    ts = TexelSum(s, s.shapes()[0], (1, 1))
    ts.set_directions(d[None], [1.0])
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(np.full((1, 3), 3.0))
    img = img.reshape(RES, RES, 3)
    half = math.acos(float(d @ np.array([0, 0, 1.0]))) / 2
    th, td = np.linspace(0.2, 1.0, 30), np.full(30, half)
    truth = model.library_material(args.material).eval(th, td)
    for known in (True,) if args.known_only else (True, False):
        s2 = sphere({"type": "dsbrdf"})
        ts2 = TexelSum(s2, s2.shapes()[0], (1, 1))
        cfg = inference.Config(max_rounds=1 if known else args.rounds, block_iters=args.iters)
        t0 = time.perf_counter()
        res, rows = inference.recover_light(ts2, img, ts2.mask, model, cfg,
                                                  known_light=(d, 3.0) if known else None)
        m = Material.from_basis(model.basis, res["psi"], res["chromaticity"])
        mean_log = rows[-1]["likelihood"] * cfg.likelihood_scale / (3 * ts2.mask.sum())
        brdf = np.abs(np.log(m.eval(th, td)) - np.log(truth)).max()
        ang = math.degrees(math.acos(min(1.0, float(res["direction"] @ d))))
        print("light %-7s  %5.1f s  re-render mean |log err| %.4f  BRDF max |log err| (theta_h 11-57 deg) %.3f  "
              "direction error %.3f deg" % ("known" if known else "unknown", time.perf_counter() - t0,
                                             mean_log, brdf, ang))


if __name__ == "__main__":
    main()
