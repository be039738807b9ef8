"""What a natural-light run's BRDF losses are: the cases whose recovered BRDF
(Eq. 20, paper convention) is no better than doing nothing (the model's mean
material), taken apart.

For each such case of a results folder (records of ``natural_light.py``, which
keep the recovered ``material``), offline, no inference:

* ``ratio``: Eq. 20 (paper) of the answer over the mean material's;
* ``relit``: the relit error over the mean material's (below 1: the answer
  relights better than doing nothing although its BRDF scores worse);
* ``fit_colour``: the ratio with the answer's lobe chromaticities replaced by
  those of the measured material's own basis fit (colour the cause?);
* ``grey``: the same with grey chromaticities;
* ``basis_fit``: the measured material's basis fit's ratio (can the basis draw it?);
* ``theta_d``: the share of the squared error in each theta_d band and its mean
  log error there (``metrics.log_error_by_theta_d``, stored in the record).

    .venv/bin/python benchmarks/brdf_losses.py benchmarks/results/natural_light/report-interior/defaults

Prints a line per case and a summary; writes ``benchmarks/results/brdf_losses-<set>-<setting>.json``.
A diagnostic: nothing is chosen on it (the twenty-eighth session ran it on the
report set to describe the misses of the shipped code).
"""
from __future__ import annotations

import argparse
import json
import os

import numpy as np

from experiments import CACHE, DATA
from natural_light import ROOT, load_results, own_rows, value


def losses(rows) -> list:
    """The rows of this tool whose BRDF (Eq. 20 paper) is not below doing nothing's."""
    return [r for r in own_rows(rows) if not r["brdf_eq20_paper"] < r["baseline"]["brdf_eq20_paper"]]


def main(argv=None):
    from mi_dsbrdf.brdf.dsbrdf import Material
    from mi_dsbrdf.brdf.measured import MeasuredBRDF
    from mi_dsbrdf.evaluation import experiment as ex
    from mi_dsbrdf.evaluation.metrics import material_errors
    from mi_dsbrdf.model.fitting import fit_basis
    from mi_dsbrdf.model.samples import samples_from_table
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder", help="a natural-light results folder (records with the recovered material)")
    args = ap.parse_args(argv)
    folder = os.path.abspath(args.folder)
    nbrdf = os.path.join(DATA, "merl", "merl_nbrdf_weights.npz")
    fits, out = {}, {}
    for r in losses(load_results(folder)):
        name = r["case"]["material"]
        if name not in fits:
            c = r["case"]
            model = ex.loo_model(name, CACHE, c.get("gmm"), c.get("bases"), c.get("fits_from"))
            samples = samples_from_table(MeasuredBRDF.from_nbrdf(nbrdf, name))
            fits[name] = (model.basis, samples, fit_basis(samples, model.basis).material)
        basis, samples, fit = fits[name]
        nothing = r["baseline"]["brdf_eq20_paper"]
        psi = np.array(r["material"]["psi"])

        def ratio(chroma, psi=psi):
            m = Material.from_basis(basis, psi, np.asarray(chroma))
            return material_errors(m, samples, conventions=("paper",))["paper"] / nothing

        row = {"ratio": r["brdf_eq20_paper"] / nothing,
               "relit": value(r, "relight") / value(r["baseline"], "relight"),
               "fit_colour": ratio(fit.chromaticity), "grey": ratio(np.full((basis.n_lobes, 3), 1 / 3)),
               "basis_fit": ratio(fit.chromaticity, fit.psi),
               "theta_d": {k: {"share": v["share"], "mean": v["mean"]}
                           for k, v in r["brdf_eq20_paper_by_theta_d"].items()}}
        key = "%s × %s" % (name, os.path.basename(r["case"]["probe"]).split(".")[0])
        out[key] = row
        print("%-44s ratio %.2f relit %.2f | fit's colour %.2f grey %.2f | basis fit %.2f | theta_d shares %s" % (
            key, row["ratio"], row["relit"], row["fit_colour"], row["grey"], row["basis_fit"],
            " ".join("%s %.2f (%+.1f)" % (k, v["share"], v["mean"]) for k, v in row["theta_d"].items())),
            flush=True)
    if out:
        relit = np.array([v["relit"] for v in out.values()])
        print("%d BRDF losses; %d relight better than doing nothing (median relit ratio %.2f)"
              % (len(out), int((relit < 1).sum()), float(np.median(relit))))
    setting = "-".join(os.path.relpath(folder, os.path.join(ROOT, "benchmarks", "results", "natural_light"))
                       .split(os.sep))
    path = os.path.join(ROOT, "benchmarks", "results", "brdf_losses-%s.json" % setting)
    with open(path, "w") as f:
        json.dump({"folder": os.path.relpath(folder, ROOT), "cases": out}, f, indent=1)
    print("->", os.path.relpath(path, ROOT))


if __name__ == "__main__":
    main()
