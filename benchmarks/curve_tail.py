"""Is the grazing end of the recovered kappa/gamma curves worth its own estimate?

A sphere seen from one side shows theta_d > 67.5 deg (the last knot span of the
curves, control values 5 and 6 at 78.75 and 90 deg) only at its rim, lit from
behind it, by texels seen at no other angle: the image hardly tells the curve's
end there from the light behind the object. In the shipped code's validation run
the theta_d band 75-90 deg holds a median 24 % of Eq. 20's squared error (paper
convention) on 9 % of the MERL samples, too bright in half the cases and too
dark in the other half (``metrics.log_error_by_theta_d``).

For each case of a natural-light run (records with the recovered ``material``,
``natural_light.py`` since the sixteenth session) the recovered curves' last
control values are replaced, everything else kept, by

* ``regress``: their ridge regression on the seen control values, per lobe and
  curve, over the leave-one-out library;
* ``lib-steps``: the last seen control value plus the library mean's steps;
* ``oracle``: the measured material's own best basis fit's (not available to
  inference: how much any estimate of the end could gain),

and Eq. 20 (paper) is scored against doing nothing. Offline: no inference runs.
``--parts`` adds the oracle for other parts of the answer: each lobe's two
curves, the control values the image sees (0-3), and the chromaticity, each
spliced alone.

    .venv/bin/python benchmarks/curve_tail.py benchmarks/results/natural_light/theta_d_bands_validation [--parts]

Validation cases only. Prints a line per case and the medians; writes
benchmarks/results/curve_tail.json.
"""
from __future__ import annotations

import argparse
import glob
import json
import os

import numpy as np

from experiments import CACHE, DATA
from natural_light import ROOT

OUT = os.path.join(ROOT, "benchmarks", "results", "curve_tail.json")
#: the first control value replaced (0-based, of 6): 4 is the one at 78.75 deg
TAIL = 4
RIDGE = 1e-3


def main(argv=None):
    from mi_dsbrdf.brdf.dsbrdf import Material, clamp_controls
    from mi_dsbrdf.brdf.measured import MeasuredBRDF
    from mi_dsbrdf.evaluation import experiment as ex
    from mi_dsbrdf.evaluation.metrics import material_errors
    from mi_dsbrdf.model.fitting import fit_basis
    from mi_dsbrdf.model.samples import samples_from_table
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder", help="a natural-light results folder whose records hold the recovered material")
    ap.add_argument("--parts", action="store_true",
                    help="also the oracle for each lobe's curves and for the seen control values (0-3)")
    args = ap.parse_args(argv)
    nbrdf = os.path.join(DATA, "merl", "merl_nbrdf_weights.npz")
    per_material, rows = {}, {}
    for f in sorted(glob.glob(os.path.join(args.folder, "*-dsbrdf-*priors.json"))):
        rec = json.load(open(f))
        name = rec["case"]["material"]
        if name not in per_material:
            model = ex.loo_model(name, CACHE)
            samples = samples_from_table(MeasuredBRDF.from_nbrdf(nbrdf, name))
            library = np.stack([model.basis.control_values(model.library_material(n).psi) for n in model.library])
            fit = fit_basis(samples, model.basis).material
            per_material[name] = (model.basis, samples, library, model.basis.control_values(fit.psi),
                                  fit.chromaticity)
        basis, samples, library, fitted, fitted_chroma = per_material[name]
        chroma = np.array(rec["material"]["chromaticity"])
        ctrl = basis.control_values(np.array(rec["material"]["psi"]))      # (R, 2, 6)

        def ratio(c, chroma=chroma):
            mat = Material(*clamp_controls(c[:, 0], c[:, 1]), chroma, knots=basis.knots)
            return material_errors(mat, samples, conventions=("paper",))["paper"] / rec["baseline"]["brdf_eq20_paper"]

        regress, steps, oracle = ctrl.copy(), ctrl.copy(), ctrl.copy()
        mean = library.mean(axis=0)
        reg = RIDGE * len(library) * np.diag([0.0] + [1.0] * TAIL)      # the intercept unpenalised
        for r in range(ctrl.shape[0]):
            for q in range(2):
                X = np.c_[np.ones(len(library)), library[:, r, q, :TAIL]]
                W = np.linalg.solve(X.T @ X + reg, X.T @ library[:, r, q, TAIL:])     # every tail value at once
                regress[r, q, TAIL:] = np.r_[1.0, ctrl[r, q, :TAIL]] @ W
        steps[:, :, TAIL:] = ctrl[:, :, TAIL - 1:TAIL] + mean[:, :, TAIL:] - mean[:, :, TAIL - 1:TAIL]
        oracle[:, :, TAIL:] = fitted[:, :, TAIL:]
        row = {k: ratio(c) for k, c in (("as-is", ctrl), ("regress", regress), ("lib-steps", steps),
                                        ("oracle", oracle))}
        if args.parts:                      # the oracle for other parts: each lobe, the seen knots
            for r in range(ctrl.shape[0]):
                part = ctrl.copy()
                part[r] = fitted[r]
                row["oracle lobe %d" % r] = ratio(part)
            part = ctrl.copy()
            part[:, :, :TAIL] = fitted[:, :, :TAIL]
            row["oracle seen"] = ratio(part)
            row["oracle colour"] = ratio(ctrl, fitted_chroma)
        rows[os.path.basename(f)[:-5]] = row
        print("%-70s %s" % (os.path.basename(f)[:-5], "  ".join("%s %.2f" % kv for kv in row.items())), flush=True)
    keys = tuple(next(iter(rows.values())))
    a = np.array([[r[k] for k in keys] for r in rows.values()])
    print("median ratio to doing nothing: " + ", ".join("%s %.3f" % (k, v) for k, v in zip(keys, np.median(a, 0))))
    print("below doing nothing: " + ", ".join("%s %d" % (k, v) for k, v in zip(keys, (a < 1).sum(0))))
    print("lower than as-is: " + ", ".join("%s %d" % (k, (a[:, i] < a[:, 0]).sum()) for i, k in enumerate(keys)
                                           if i))
    json.dump({"folder": os.path.relpath(args.folder, ROOT), "cases": rows}, open(OUT, "w"), indent=1)


if __name__ == "__main__":
    main()
