"""How heavy a tail should the GMM prior have? The held-out density of the library by degrees of freedom.

The GMM prior (Eq. 6) acts on materials it has not seen. A held-out material can
lie far from every component, where the Gaussian's cost grows as d^2 / 2 (d the
Mahalanobis distance) and outweighs the image
(``benchmarks/results/truth_posterior.json``: a held-out foam's basis fit pays
the GMM 30000 against the recovered answer's 5000). A Student-t tail of nu
degrees of freedom (:class:`~mi_dsbrdf.model.priors.GaussianMixture`, ``dof``)
keeps the Gaussian's curvature at each centre and grows as log d^2 far out.

For each of the library's 100 materials the shipped structure (4 diagonal
components, reg 0.001) is refitted without it, and the material's negative log
density is scored at each nu (``volume`` 1: normalised densities). The nu of the
lowest mean is the library's own choice, made without any image. Also printed:
the held-out materials' Mahalanobis distance to the nearest component against
the library's own.

    .venv/bin/python benchmarks/gmm_tail.py        # ~1 min -> benchmarks/results/gmm_tail.json

The psi are the shipped library's (its basis); a leave-one-out model also
refits the basis, which moves a held-out material further out than this.
"""
from __future__ import annotations

import json
import math
import os

import numpy as np

from mi_dsbrdf.model import model_file
from mi_dsbrdf.model.build import SEED, gmm_structure
from mi_dsbrdf.model.priors import fit_gmm

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "gmm_tail.json")
DOFS = (1, 2, 3, 5, 10, 15, 20, 30, 50, 100, math.inf)


def mahalanobis2(gmm, x) -> np.ndarray:
    """(C,) squared Mahalanobis distance of x to each component."""
    d = x[None] - gmm.means
    return np.einsum("ci,cij,cj->c", d, np.linalg.inv(gmm.covariances), d)


def main():
    model = model_file.shipped_model()
    X = np.asarray(model.arrays["library_psi"], dtype=np.float64)
    names = [str(n) for n in model.arrays["library_names"]]
    ct, c, reg = gmm_structure(str(model.arrays["gmm_structure"]))
    nll = {dof: [] for dof in DOFS}
    held_out, own = [], []
    for i in range(X.shape[0]):
        rest = np.delete(X, i, axis=0)
        g, _ = fit_gmm(rest, c, ct, seed=SEED, reg=reg)
        for dof in DOFS:
            nll[dof].append(g.nll(X[i], 1.0, dof))
        held_out.append(float(mahalanobis2(g, X[i]).min()))
        own.append(float(np.median([mahalanobis2(g, x).min() for x in rest])))
    rows = [{"dof": dof, "mean": float(np.mean(v)), "median": float(np.median(v)), "max": float(np.max(v))}
            for dof, v in nll.items()]
    best = min(rows, key=lambda r: r["mean"])
    print("structure %s:%d:%g, the library's %d materials held out one at a time" % (ct, c, reg, X.shape[0]))
    print("| nu | held-out -log p: mean | median | max |\n|---|---|---|---|")
    for r in rows:
        print("| %s | %.2f | %.2f | %.2f |" % (r["dof"], r["mean"], r["median"], r["max"]))
    print("lowest mean: nu = %s" % best["dof"])
    q = np.percentile(held_out, [50, 90, 100])
    print("squared Mahalanobis distance to the nearest component: held out median %.1f, p90 %.1f, max %.1f "
          "(the library's own, median over the refits: %.1f; k = %d)" % (*q, float(np.median(own)), X.shape[1]))
    far = np.argsort(held_out)[::-1][:6]
    print("furthest out: " + ", ".join("%s %.1f" % (names[i], held_out[i]) for i in far))
    with open(OUT, "w") as f:
        json.dump({"structure": [ct, c, reg], "rows": [dict(r, dof=str(r["dof"])) for r in rows],
                   "choice": str(best["dof"]), "held_out_d2": dict(zip(names, held_out))}, f, indent=1)


if __name__ == "__main__":
    main()
