"""The learned reflectance model file: curve bases, priors, material library.

One ``.npz`` file (shipped as ``mi_dsbrdf/data/model.npz`` once built by
``mi-dsbrdf build-model``) with at least

    knots            (9,)          spline knots of all curves
    mean             (R, 2, 6)     mean log-curve control values (b_mu, Eq. 2-3)
    bases            (k, R, 2, 6)  basis functions b_i
    library_names    (M,)          names of the library materials
    library_psi      (M, k)        their basis coefficients
    library_chroma   (M, R, 3)     their lobe chromaticities

and the priors

    gmm_weights (C,), gmm_means (C, k), gmm_covariances (C, k, k)   Eq. 6
    hue_kappa   ()                                                  Eq. 7-12

and the priors' data, what the GMM, the hue prior, the chromaticity prior
(:class:`~mi_dsbrdf.model.priors.ChromaticityPrior`, learned on first use) and
inference's box on the curves are fitted to (optional; a file without them
uses the library's)

    prior_psi    (M, k)        the library materials' FPCA scores
    prior_chroma (M, R, 3)     their full fits' chromaticities

plus what the build keeps for leave-one-out rebuilds and reports (written by
:mod:`mi_dsbrdf.model.build`): ``fpca_bases``, ``fpca_variance``, the full fits
``fit_names``, ``fit_controls``, ``fit_chroma``, ``fit_flags``, their Eq. 5 errors on
the fit samples in the paper's and the cosine-weighted convention ``fit_error``,
``fit_error_cosine``, ``library_error``, ``library_error_cosine``, ``excluded``
and ``build_info`` (JSON, with the fit objective). Other arrays are ignored.
"""
from __future__ import annotations

import functools
import json
import os
import weakref

import numpy as np

from mi_dsbrdf.brdf.curves import CurveBasis
from mi_dsbrdf.brdf.dsbrdf import Material
from mi_dsbrdf.errors import MaterialError, ModelError
from mi_dsbrdf.model.priors import ChromaticityPrior, GaussianMixture, HuePrior

SHIPPED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "model.npz")
REQUIRED = ("knots", "mean", "bases", "library_names", "library_psi", "library_chroma")


#: models built in memory, by their ``source`` name, so that the ``dsbrdf``
#: plugin's ``model`` parameter (a string) can name them as it names a file
_IN_MEMORY = weakref.WeakValueDictionary()


class ReflectanceModel:
    """Curve basis + library (+ priors) from a model file's arrays.

    ``source`` is the file it was read from; a model made from arrays in memory
    (``source`` None) gets the name ``memory:<n>``, which :func:`load_model` and
    the plugin's ``<string name="model" value="..."/>`` accept while it lives.
    """

    def __init__(self, arrays: dict, source: str = None):
        if source is None:
            source = "memory:%d" % id(self)
            _IN_MEMORY[source] = self
        missing = [k for k in REQUIRED if k not in arrays]
        if missing:
            raise ModelError("%s lacks the arrays %s" % (source, ", ".join(missing)))
        try:
            self.basis = CurveBasis(arrays["mean"], arrays["bases"], arrays["knots"])
        except ValueError as e:
            raise ModelError("%s: %s" % (source, e)) from None
        names = [str(n) for n in arrays["library_names"]]
        psi = np.asarray(arrays["library_psi"], dtype=np.float64)
        chroma = np.asarray(arrays["library_chroma"], dtype=np.float64)
        m, k, r = len(names), self.basis.n_bases, self.basis.n_lobes
        if psi.shape != (m, k) or chroma.shape != (m, r, 3):
            raise ModelError("%s: library_psi must be (%d, %d) and library_chroma (%d, %d, 3), got %s and %s"
                             % (source, m, k, m, r, psi.shape, chroma.shape))
        if not (np.all(np.isfinite(psi)) and np.all(np.isfinite(chroma))):
            raise ModelError("%s: library_psi and library_chroma must be finite" % source)
        self.library = {n: (psi[i], chroma[i]) for i, n in enumerate(names)}
        # the priors' data (the build's FPCA scores and full fits' colours), else the library's
        self.prior_psi = np.asarray(arrays.get("prior_psi", psi), dtype=np.float64)
        self.prior_chroma = np.asarray(arrays.get("prior_chroma", chroma), dtype=np.float64)
        if self.prior_psi.shape != (m, k) or self.prior_chroma.shape != (m, r, 3):
            raise ModelError("%s: prior_psi must be (%d, %d) and prior_chroma (%d, %d, 3), got %s and %s"
                             % (source, m, k, m, r, self.prior_psi.shape, self.prior_chroma.shape))
        if not (np.all(np.isfinite(self.prior_psi)) and np.all(np.isfinite(self.prior_chroma))):
            raise ModelError("%s: prior_psi and prior_chroma must be finite" % source)
        self.arrays = arrays
        self.source = source
        self.gmm = None
        if "gmm_weights" in arrays:
            try:
                self.gmm = GaussianMixture(arrays["gmm_weights"], arrays["gmm_means"], arrays["gmm_covariances"])
            except (KeyError, ValueError) as e:
                raise ModelError("%s: bad Gaussian mixture prior: %s" % (source, e)) from None
            if self.gmm.dim != k:
                raise ModelError("%s: the Gaussian mixture is over %d coefficients but the basis has %d"
                                 % (source, self.gmm.dim, k))
        self.hue_prior = None
        if "hue_kappa" in arrays:
            try:
                self.hue_prior = HuePrior(float(arrays["hue_kappa"]))
            except (TypeError, ValueError) as e:
                raise ModelError("%s: bad hue prior: %s" % (source, e)) from None
        try:
            self.info = json.loads(str(arrays["build_info"])) if "build_info" in arrays else {}
        except ValueError:
            raise ModelError("%s: build_info is not JSON" % source) from None

    @functools.cached_property
    def chromaticity_prior(self) -> ChromaticityPrior:
        """The chromaticity prior learned from the library (built on first use:
        only the colour split under a map needs it, so a small model still loads
        and serves point lights or inference with the split off), from the
        priors' data ``prior_chroma``."""
        try:
            return ChromaticityPrior(self.prior_chroma)
        except ValueError as e:
            raise ModelError("%s: bad chromaticity prior: %s (the colour split needs it: turn the split off "
                             "with --no-colour-split, or Config.with_colour_split(False))" % (self.source, e)) from None

    @property
    def excluded(self) -> list:
        """Materials the model was built without (leave-one-out)."""
        return [str(n) for n in self.arrays.get("excluded", [])]

    def mean_material(self) -> Material:
        """All coefficients zero; grey chromaticity."""
        return Material.from_basis(self.basis, np.zeros(self.basis.n_bases),
                                   np.full((self.basis.n_lobes, 3), 1 / 3), name="mean")

    def library_material(self, name) -> Material:
        psi, chroma = self.library[name]
        return Material.from_basis(self.basis, psi, chroma, name=name)


def load_model(path) -> ReflectanceModel:
    """Read and validate a model file (or name a model in memory); ModelError names what is wrong."""
    path = os.fspath(path)
    if path in _IN_MEMORY:
        return _IN_MEMORY[path]
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
    except FileNotFoundError:
        raise ModelError("model file %s does not exist" % path) from None
    except (OSError, ValueError, EOFError) as e:
        raise ModelError("model file %s is unreadable: %s" % (path, e)) from None
    try:
        return ReflectanceModel(arrays, source=path)
    except MaterialError as e:
        raise ModelError("%s: %s" % (path, e)) from None


@functools.lru_cache(maxsize=1)
def shipped_model():
    """The model shipped with the package, or None when none is installed."""
    return load_model(SHIPPED) if os.path.exists(SHIPPED) else None
