"""Build the data-driven reflectance model from MERL (paper §3): the command
behind ``mi-dsbrdf build-model``.

    measured BRDFs ──fit_full──▶ 3-lobe B-spline DSBRDF per material (Eq. 5)
                   ──fpca─────▶ mean b_mu + bases b_i of the log curves (Eq. 2-3)
                   ──fit_basis─▶ psi (k) + chromaticity per material (library)
                   ──priors───▶ GMM on the FPCA scores psi (Eq. 6, structure GMM),
                                hue kappa_h on the full fits' chromaticities (Eq. 7-12)
                   ──▶ model.npz

The full fits of a material do not depend on the other materials, so they are
kept in the model file (``fit_*`` arrays) and a leave-one-out model
(:func:`build_from_fits` with ``exclude``) rebuilds the bases, the library and
the priors without the excluded materials from them, in seconds.

Deterministic: the fits are deterministic and the GMM's EM is seeded.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
import dataclasses
import glob
import hashlib
import json
import multiprocessing
import os
import platform
import sys
import time

import numpy as np
from tqdm import tqdm

from mi_dsbrdf.backend import one_blas_thread
from mi_dsbrdf.brdf import measured
from mi_dsbrdf.brdf.curves import CurveBasis
from mi_dsbrdf.brdf.measured import nbrdf_names
from mi_dsbrdf.errors import MeasuredFileError, ModelError
from mi_dsbrdf.model import samples
from mi_dsbrdf.model.fit_problem import OBJECTIVE, FitObjective
from mi_dsbrdf.model.fitting import fit_basis, fit_full
from mi_dsbrdf.model.fpca import fpca
from mi_dsbrdf.model.model_file import SHIPPED, load_model
from mi_dsbrdf.model.priors import fit_gmm, fit_hue_concentration, select_gmm

DEFAULT_K = 10
SEED = 0
#: the GMM prior's structure (:func:`gmm_structure`): "bic", or
#: "covariance:components:reg". Four diagonal components: BIC's four full ones
#: leave near-Lambertian materials glossy under natural light.
GMM = "diag:4:0.001"


def gmm_structure(text) -> tuple:
    """``"bic"`` -> ("bic",): 1-5 components of full and diagonal covariances, the
    lowest BIC; ``"full:2:0.01"`` -> ("full", 2, 0.01): that covariance type (full,
    diag or tied: one shared by the components, :func:`~mi_dsbrdf.model.priors.fit_gmm`) and
    number of components, ``reg`` times the mean variance added to each
    covariance (:func:`~mi_dsbrdf.model.priors.fit_gmm`). ModelError otherwise."""
    text = str(text).strip().lower()
    if text == "bic":
        return ("bic",)
    parts = text.split(":")
    try:
        ct, c, reg = parts[0], int(parts[1]), float(parts[2])
        ok = len(parts) == 3 and ct in ("full", "diag", "tied") and 1 <= c <= 10 and 0 <= reg < 10
    except (IndexError, ValueError):
        ok = False
    if not ok:
        raise ModelError("GMM structure %r: give 'bic' or 'full|diag|tied:components:reg', e.g. 'full:2:0.01'"
                         % text)
    return ct, c, reg


def fit_gmm_prior(psi, structure=GMM) -> dict:
    """The GMM arrays of a model file (Eq. 6) for the library's ``psi`` (M, k)."""
    s = gmm_structure(structure)
    if s[0] == "bic":
        sel = select_gmm(psi, seed=SEED)
        gmm, ct = sel.gmm, sel.covariance_type
        extra = {"gmm_bic": np.array([(1.0 if t == "full" else 0.0, c, ll, bic) for t, c, ll, bic in sel.table])}
    else:
        ct, c, reg = s
        gmm, _ = fit_gmm(psi, c, ct, seed=SEED, reg=reg)
        extra = {"gmm_reg": np.array(reg)}
    return {"gmm_weights": gmm.weights, "gmm_means": gmm.means, "gmm_covariances": gmm.covariances,
            "gmm_covariance_type": np.array(ct), "gmm_structure": np.array(":".join(map(str, s))), **extra}


# --- sources -----------------------------------------------------------------------

def source_names(source) -> list:
    """Material names of a source: a ``merl_nbrdf_weights.npz`` or a folder of ``.binary`` files."""
    source = os.fspath(source)
    if os.path.isdir(source):
        files = sorted(glob.glob(os.path.join(source, "*.binary")))
        if not files:
            raise MeasuredFileError("no MERL .binary files in %s" % source)
        return [os.path.splitext(os.path.basename(f))[0] for f in files]
    if not os.path.exists(source):
        raise MeasuredFileError("MERL source %s does not exist (give a merl_nbrdf_weights.npz or a folder "
                                "of .binary files)" % source)
    return nbrdf_names(source)


def load_samples(source, name, subset=None):
    """:class:`~mi_dsbrdf.model.samples.Samples` of one material of a source."""
    source = os.fspath(source)
    if os.path.isdir(source):
        return samples.samples_from_table(measured.MeasuredBRDF.from_binary(os.path.join(source, name + ".binary")),
                                          subset)
    w = measured.load_nbrdf_weights(source, name)
    return samples.samples_from_function(lambda th, td, pd: measured.eval_nbrdf(w, th, td, pd), subset, name)


def source_kind(source) -> str:
    if os.path.isdir(os.fspath(source)):
        return "MERL .binary files"
    return "MERL neural fits (NBRDF, Sztrajman et al. 2021)"


# --- per-material work (runs in worker processes) ------------------------------------

def _fit_full_job(args):
    source, name, objective = args
    t0 = time.perf_counter()
    f = fit_full(load_samples(source, name), objective=objective)
    return (name, f.variables, f.material.chromaticity, (f.error, f.error_cosine), f.at_bounds,
            time.perf_counter() - t0)


def _fit_basis_job(args):
    source, name, mean, bases, knots, psi0, chroma0 = args
    f = fit_basis(load_samples(source, name), CurveBasis(mean, bases, knots), psi0, chroma0)
    return name, f.variables, f.material.chromaticity, (f.error, f.error_cosine)


def _map(fn, jobs, workers, desc, progress):
    """Run ``fn`` over ``jobs`` in ``workers`` processes, in job order, with a progress bar."""
    bar = tqdm(total=len(jobs), desc=desc, disable=not progress, unit="mat", file=sys.stderr)
    out = []
    if workers <= 1:
        for j in jobs:
            out.append(fn(j))
            bar.update()
    else:
        one_blas_thread()
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as ex:
            for r in ex.map(fn, jobs):
                out.append(r)
                bar.update()
    bar.close()
    return out


# --- the build -----------------------------------------------------------------------

def fit_all(source, names=None, workers=2, progress=True, objective: FitObjective = OBJECTIVE) -> dict:
    """Full 3-lobe B-spline fits of every material of ``source`` (minimising ``objective``).

    Returns ``{"names", "controls" (M, 3, 2, 6), "chroma" (M, 3, 3), "error" (M,)
    and "error_cosine" (M,) (Eq. 5 on the fit's samples in the paper's and the
    cosine-weighted convention), "flags" [list of str per material], "seconds" (M,)}``.
    """
    names = source_names(source) if names is None else list(names)
    rows = _map(_fit_full_job, [(os.fspath(source), n, objective) for n in names], workers, "full DSBRDF fits",
                progress)
    return {"names": [r[0] for r in rows], "controls": np.array([r[1] for r in rows]),
            "chroma": np.array([r[2] for r in rows]), "error": np.array([r[3][0] for r in rows]),
            "error_cosine": np.array([r[3][1] for r in rows]),
            "flags": [list(r[4]) for r in rows], "seconds": np.array([r[5] for r in rows])}


def build_from_fits(fits: dict, k=DEFAULT_K, exclude=(), source=None, workers=2, progress=True,
                    refit=True, gmm=GMM) -> dict:
    """Bases, library and priors from full fits, without the ``exclude``d materials.

    With ``refit`` (and a ``source``), every kept material is refitted in the
    basis model (psi + chromaticity, Eq. 5) for the library; otherwise its psi is
    its FPCA score and its chromaticity that of the full fit (fast, for
    leave-one-out studies). Either way the priors are fitted to the FPCA scores
    and the full fits' chromaticities (paper §3: psi are the FPCA coefficients),
    so that a leave-one-out model's priors are the build's (priors fitted to the
    refits recover held-out materials worse from images). Returns the arrays of a
    model file.
    """
    names = list(fits["names"])
    exclude = list(exclude)
    unknown = [n for n in exclude if n not in names]
    if unknown:
        raise ModelError("cannot exclude %s: not among the fitted materials" % ", ".join(unknown))
    keep = [i for i, n in enumerate(names) if n not in exclude]
    if len(keep) < k + 2:
        raise ModelError("%d materials are too few for %d bases" % (len(keep), k))
    kept = [names[i] for i in keep]
    pca = fpca(fits["controls"][keep])
    basis = pca.basis(k)
    scores, fit_chroma = pca.scores[:, :k], fits["chroma"][keep]     # the priors' data, refit or not
    if refit:
        if source is None:
            raise ModelError("refitting in the basis needs the measurement source")
        jobs = [(os.fspath(source), n, basis.mean, basis.bases, basis.knots, scores[j], fit_chroma[j])
                for j, n in enumerate(kept)]
        rows = _map(_fit_basis_job, jobs, workers, "basis refits (k=%d)" % k, progress)
        psi = np.array([r[1] for r in rows])
        chroma = np.array([r[2] for r in rows])
        err = np.array([r[3] for r in rows])                   # (M, 2): paper, cosine
    else:
        psi, chroma, err = scores, fit_chroma, np.full((len(keep), 2), np.nan)
    kappa_h, n_pairs = fit_hue_concentration(fit_chroma)
    return {
        "knots": np.array(basis.knots), "mean": basis.mean, "bases": basis.bases,
        "fpca_bases": pca.bases, "fpca_variance": pca.variance,
        "library_names": np.array(kept), "library_psi": psi, "library_chroma": chroma,
        "library_error": err[:, 0], "library_error_cosine": err[:, 1],
        "fit_names": np.array(names), "fit_controls": fits["controls"], "fit_chroma": fits["chroma"],
        "fit_error": fits["error"], "fit_error_cosine": fits["error_cosine"],
        "fit_flags": np.array(["; ".join(f) for f in fits["flags"]]),
        "prior_psi": scores, "prior_chroma": fit_chroma,
        **fit_gmm_prior(scores, gmm),
        "hue_kappa": np.array(kappa_h), "hue_pairs": np.array(n_pairs),
        "excluded": np.array(exclude, dtype=str),
    }


def build_model(source, out, k=DEFAULT_K, exclude=(), workers=2, progress=True, fits_from=None,
                gmm=GMM, objective: FitObjective = OBJECTIVE) -> dict:
    """The whole build, written to ``out`` (a ``.npz``). ``fits_from``: a model
    file whose stored full fits are reused instead of refitting them; ``gmm``: the
    GMM's structure (:func:`gmm_structure`); ``objective``: what the full fits
    minimise (recorded; with ``fits_from`` the stored fits' own). Returns the arrays."""
    gmm_structure(gmm)                                        # a bad structure fails before the fits
    if not isinstance(k, int) or isinstance(k, bool) or k < 1:
        raise ModelError("--k must be an integer >= 1 (basis functions), got %r" % (k,))
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise ModelError("--workers must be an integer >= 1, got %r" % (workers,))
    t0 = time.perf_counter()
    if fits_from is not None:
        if objective != OBJECTIVE:
            raise ModelError("a fit objective of its own needs new fits, not the ones stored in %s" % fits_from)
        a = load_model(fits_from).arrays
        if "fit_controls" not in a:
            raise ModelError("%s holds no full fits to reuse" % fits_from)
        fits = stored_fits(a)
        fitted_by = json.loads(str(a["build_info"])).get("fit_objective") if "build_info" in a else None
    else:
        fits = fit_all(source, workers=workers, progress=progress, objective=objective)
        fitted_by = dataclasses.asdict(objective)
    arrays = build_from_fits(fits, k=k, exclude=exclude, source=source, workers=workers, progress=progress,
                             gmm=gmm)
    info = {"source": source_kind(source), "source_file": os.path.basename(os.fspath(source)),
            "k": k, "excluded": list(exclude), "seed": SEED, "gmm": str(gmm),
            "fit_objective": fitted_by, "seconds": round(time.perf_counter() - t0, 1),
            "python": platform.python_version(), "numpy": np.__version__,
            "command": build_command(source, out, k, exclude, fits_from, gmm)}
    arrays["build_info"] = np.array(json.dumps(info))
    save_model(out, arrays)
    return arrays


def build_command(source, out, k=DEFAULT_K, exclude=(), fits_from=None, gmm=GMM) -> str:
    """The ``mi-dsbrdf build-model`` command line that repeats a build of
    :func:`build_model`'s arguments (files by their names; options only where
    they differ from the defaults)."""
    def name(path):
        return os.path.basename(os.fspath(path))

    words = ["mi-dsbrdf build-model --merl %s --out %s" % (name(source), name(out))]
    words += ["--k %d" % k] if k != DEFAULT_K else []
    words += ["--exclude %s" % n for n in exclude]
    words += ["--fits-from %s" % name(fits_from)] if fits_from is not None else []
    words += ["--gmm %s" % gmm] if gmm != GMM else []
    return " ".join(words)


def stored_fits(arrays) -> dict:
    """The full fits a model file keeps (``fit_*`` arrays), in the form
    :func:`fit_all` returns and :func:`build_from_fits` takes."""
    a = arrays
    return {"names": [str(n) for n in a["fit_names"]], "controls": a["fit_controls"], "chroma": a["fit_chroma"],
            "error": a["fit_error"], "error_cosine": a["fit_error_cosine"],
            "flags": [f.split("; ") if f else [] for f in a["fit_flags"].tolist()]}


def save_model(path, arrays) -> None:
    """Write a model file atomically (a temporary file of this process renamed
    into place: parallel workers may write the same model)."""
    path = os.fspath(path)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = "%s.%d.tmp.npz" % (path, os.getpid())
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


def loo_model(name, cache, gmm=None, k=None, fits_from=None):
    """The reflectance model rebuilt without ``name`` (bases, GMM, hue prior and
    library from the other 99 fits; the GMM of structure ``gmm``, default the
    build's, :func:`~mi_dsbrdf.model.build.gmm_structure`; ``k`` bases, default
    the build's ``DEFAULT_K``; the full fits stored in the model file
    ``fits_from``, default the shipped one, :func:`~mi_dsbrdf.model.build.build_from_fits`), cached as
    ``cache/loo-<name>-<h>-<gmm>[-k<k>].npz``, h the first 12 hex digits of that
    model file's SHA-256, so that a rebuilt model never reuses a leave-one-out
    model of the one before.

    The library is not refitted in the leave-one-out basis (its psi are the FPCA
    scores; seconds instead of minutes): inference does not use it, and the
    priors, as in a build, are fitted to the scores.
    """
    gmm = GMM if gmm is None else gmm
    k = DEFAULT_K if k is None else int(k)
    tag = "-".join(map(str, gmm_structure(gmm))) + ("" if k == DEFAULT_K else "-k%d" % k)
    source = SHIPPED if fits_from is None else fits_from
    path = os.path.join(cache, "loo-%s-%s-%s.npz" % (name, model_file_hash(source), tag))
    if not os.path.exists(path):
        arrays = load_model(source).arrays
        save_model(path, build_from_fits(stored_fits(arrays), k=k, exclude=[name], refit=False, progress=False,
                                         gmm=gmm))  # atomic
    return load_model(path)


def model_file_hash(path=None) -> str:
    """First 12 hex digits of the SHA-256 of the shipped model file (or of ``path``)."""
    with open(SHIPPED if path is None else path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()[:12]
