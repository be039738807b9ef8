"""Natural-light recovery against doing nothing, on a validation and a report set (issue 15).

Each case is a synthetic probe case of ``benchmarks/experiments.py`` (64x64
sphere, the MERL material rendered under the probe at 64x128, a 32x64 map
recovered, leave-one-out model: the material's own fit is left out of the
bases and priors). Every result carries its own do-nothing baseline
(:func:`mi_dsbrdf.evaluation.experiment.run_case`, ``baseline``): the model's
mean material (psi = 0) for the BRDF and relighting, a constant map on the same
seen texels for the illumination.

Two disjoint sets of materials and probes:

* **validation** (:data:`VALIDATION_MATERIALS` x :data:`VALIDATION_PROBES`): the
  only cases settings and weights are chosen on (``--set validation
  --config w_entropy=300 ...`` runs one setting into its own folder);
* **report** (:data:`REPORT_MATERIALS` x :data:`REPORT_PROBES`): 12 materials
  spanning the four GMM clusters of the shipped model, 6 probes; run once with
  the shipped defaults, with principled + Adam and DSBRDF + Adam through
  ``prb`` at about this tool's median time beside them.

Measures, lower is better except PSNR: BRDF Eq. 20 in the paper's convention
log(f + 1e-6) and in the cosine-weighted log(1 + f cos theta_i); the
illumination map's scale-invariant log error; the relit images' (two other
probes) scale-invariant log error and Stanford-ORB PSNR (dB).

    .venv/bin/python benchmarks/natural_light.py --set validation            # 12 cases, ~3 min
    .venv/bin/python benchmarks/natural_light.py --set validation --config w_entropy=300 w_gradient=300
    .venv/bin/python benchmarks/natural_light.py --set report --adam         # 72 x 3 cases, ~1 h
    .venv/bin/python benchmarks/natural_light.py --set report --summary      # tables from the results
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import sys

import numpy as np

from experiments import DATA, make_case, run_on_cluster

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "benchmarks", "results", "natural_light")
#: validation: one material of each kind (acrylic, metallic paint, fabric,
#: plastic, foam, metal), an indoor probe and an urban outdoor panorama
VALIDATION_MATERIALS = ["violet-acrylic", "silver-metallic-paint", "blue-fabric", "yellow-plastic",
                        "polyurethane-foam", "nickel"]
VALIDATION_PROBES = ["probulator/wells.hdr", "polyhaven/pedestrian_overpass_1k.hdr"]
#: report: 12 other materials, by GMM cluster of the shipped model (0: foams and
#: fabrics; 1: metals, acrylics, phenolics; 2: paints, rubbers, fabrics; 3: the
#: rest), and six other probes (four indoor/outdoor probes, a hard low sun, a sunset)
REPORT_MATERIALS = ["light-brown-fabric",
                    "blue-acrylic", "alum-bronze", "specular-red-phenolic", "white-marble",
                    "pink-fabric", "orange-paint", "pure-rubber",
                    "gold-metallic-paint", "red-fabric", "pvc", "pink-felt"]
REPORT_PROBES = ["probulator/grace.hdr", "probulator/ennis.hdr", "probulator/pisa.hdr", "probulator/uffizi.hdr",
                 "polyhaven/blouberg_sunrise_2_1k.hdr", "polyhaven/venice_sunset_1k.hdr"]
#: Adam through prb at about this tool's median time on these cases (8 spp)
ADAM_ITERS, ADAM_SPP = 150, 8
#: (key, label, higher is better)
MEASURES = [("brdf_eq20_paper", "BRDF Eq. 20 paper", False), ("brdf_eq20_cosine", "BRDF Eq. 20 cosine", False),
            ("illumination_error", "illumination", False), ("relight", "relit", False),
            ("relight_psnr", "relit PSNR dB", True)]
assert not set(VALIDATION_MATERIALS) & set(REPORT_MATERIALS)
assert not set(VALIDATION_PROBES) & set(REPORT_PROBES)


def parse_config(items) -> dict:
    """``["w_entropy=300", "map_levels=1"]`` -> {"w_entropy": 300.0, "map_levels": 1}."""
    out = {}
    for item in items or []:
        k, _, v = item.partition("=")
        out[k] = int(v) if v.lstrip("-").isdigit() else float(v)
    return out


def setting_name(config) -> str:
    return "-".join("%s%g" % (k, v) for k, v in sorted(config.items())) or "defaults"


def cases(which, config=None, adam=False) -> list:
    mats, probes = ((VALIDATION_MATERIALS, VALIDATION_PROBES) if which == "validation"
                    else (REPORT_MATERIALS, REPORT_PROBES))
    out = []
    for m in mats:
        for p in probes:
            c = make_case(which, "probe", m, True, probe=p, weights=dict(config or {}))
            out.append(c)
            if adam:
                for method in ("principled-adam", "dsbrdf-adam"):
                    out.append(make_case(which, "probe", m, True, probe=p, method=method, iters=ADAM_ITERS,
                                         spp=ADAM_SPP))
    return out


def value(r, key):
    if key in ("relight", "relight_psnr"):
        return float(np.mean(list(r[key].values())))
    return r[key]


def summary(folder) -> str:
    """Markdown: per method and measure, the fraction of cases better than doing
    nothing and the median ratio (PSNR: median difference in dB), then every case."""
    rows = [json.load(open(f)) for f in sorted(glob.glob(os.path.join(folder, "*.json")))]
    by_method = {}
    for r in rows:
        by_method.setdefault(r["case"]["method"], []).append(r)
    md = ["| method | cases | seconds (median) | " + " | ".join(
        "%s: better than doing nothing, median %s" % (label, "gain" if hi else "ratio")
        for _, label, hi in MEASURES) + " |", "|---|---|---|" + "---|" * len(MEASURES)]
    for method, rs in sorted(by_method.items()):
        cells = []
        for key, _, hi in MEASURES:
            x = np.array([value(r, key) for r in rs])
            b = np.array([value(r["baseline"], key) for r in rs])
            if hi:
                cells.append("%d/%d, %+.1f dB" % ((x > b).sum(), len(x), np.median(x - b)))
            else:
                cells.append("%d/%d, %.2f×" % ((x < b).sum(), len(x), np.median(x / b)))
        md.append("| %s | %d | %.1f | %s |" % (method, len(rs), np.median([r["seconds"] for r in rs]),
                                               " | ".join(cells)))
    md += ["", "| case | seconds | " + " | ".join("%s (nothing)" % label for _, label, _ in MEASURES) + " |",
           "|---|---|" + "---|" * len(MEASURES)]
    for r in sorted(rows, key=lambda r: r["case"]["id"]):
        md.append("| %s | %.0f | %s |" % (r["case"]["id"], r["seconds"], " | ".join(
            "%.3f (%.3f)" % (value(r, k), value(r["baseline"], k)) for k, _, _ in MEASURES)))
    return "\n".join(md) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", choices=["validation", "report"], default="validation")
    ap.add_argument("--config", nargs="*", help="Config overrides, name=value (validation only)")
    ap.add_argument("--adam", action="store_true", help="principled + Adam and DSBRDF + Adam beside")
    ap.add_argument("--summary", action="store_true", help="only print the tables of finished cases")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--data", default=DATA)
    args = ap.parse_args(argv)
    config = parse_config(args.config)
    if config and args.set == "report":
        sys.exit("settings are chosen on the validation set; the report set runs the shipped defaults")
    out = os.path.join(OUT, args.set, setting_name(config))
    if not args.summary:
        if not os.path.exists(os.path.join(args.data, "merl", "merl_nbrdf_weights.npz")):
            sys.exit("needs the MERL fits under %s (see ../shared/data/README.md)" % args.data)
        run_on_cluster(cases(args.set, config, args.adam), out, args.data, args.workers)
    print("## %s, %s (%s)\n" % (args.set, setting_name(config), os.path.relpath(out, ROOT)))
    print(summary(out))


if __name__ == "__main__":
    main()
