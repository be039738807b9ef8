"""The Directional-Statistics BRDF (paper Eq. 4), colour-separated:

    rho_lambda(theta_d, theta_h) = sum_r c_{r,lambda} (exp[kappa_r(theta_d) cos^{gamma_r(theta_d)} theta_h] - 1)

with R lobes, each a pair of log-spline curves (:mod:`mi_dsbrdf.brdf.curves`) and a
chromaticity c_r (non-negative RGB weights that sum to one; the magnitude lives
in kappa). Values are in 1/sr.

:func:`lobe_rgb` is the formula, written once for numpy and Dr.Jit: the numpy
float64 evaluation (:meth:`Material.eval`) is the reference the tests hold the
Dr.Jit plugin (``plugins/dsbrdf.py``) to.

Numerical guards, identical in both backends: log kappa <= log 60 (values and
derivatives finite in float32, see KAPPA_MAX), gamma in [1e-4, 1e6], cos theta_h >= 1e-30 (finite gradients
at theta_h = 90 deg), and a stable expm1 for tiny kappa.
"""
from __future__ import annotations

import json
import math
import os

import numpy as np
from scipy.special import gammaln, logsumexp

from mi_dsbrdf.brdf.angles import log_cos_h
from mi_dsbrdf.brdf.chromaticity import chroma_logits, softmax_chroma
from mi_dsbrdf.brdf.curves import DEFAULT_KNOTS, N_CONTROL, check_knots, eval_log_curve, spline_basis
from mi_dsbrdf.brdf.observed import DirectionWeights
from mi_dsbrdf.brdf.xp import expm1, ops
from mi_dsbrdf.errors import MaterialError

MAX_LOBES = 3
#: kappa <= 60 keeps every derivative of a lobe finite in float32: the chain rule
#: multiplies e^kappa by kappa gamma (<= 1e6), and e^60 * 60 * 1e6 = 7e33 < 3.4e38
#: (at 85 the NaN/Inf reached 0.26 deg around the peak); the library's kappa stay below 11
KAPPA_MAX = 60.0
GAMMA_MIN, GAMMA_MAX = 1e-4, 1e6
COS_H_MIN = 1e-30
LOG_KAPPA_MAX = math.log(KAPPA_MAX)
LOG_GAMMA_MIN, LOG_GAMMA_MAX = math.log(GAMMA_MIN), math.log(GAMMA_MAX)
LOG_COS_H_MIN = math.log(COS_H_MIN)
FORMAT = "mi-dsbrdf/material"
#: the parameters of one lobe (:meth:`Material.parameters`): log kappa and log gamma
#: control values, two chromaticity variables
LOBE_PARAMETERS = 2 * N_CONTROL + 2
#: the floor of the chromaticities whose variables :meth:`Material.parameters` gives
CHROMA_FLOOR = 1e-12


def lobe_curves(theta_d, log_kappa, log_gamma, knots=DEFAULT_KNOTS):
    """kappa_r(theta_d), gamma_r(theta_d) for every lobe (guards applied).

    ``log_kappa``, ``log_gamma``: per lobe, 6 control values (numpy floats or
    Dr.Jit scalars). Returns two lists of R arrays shaped like ``theta_d``.
    """
    o = ops(theta_d)
    basis = spline_basis(theta_d, knots)
    kappa = [o.exp(o.fmin(eval_log_curve(basis, a), LOG_KAPPA_MAX)) for a in log_kappa]
    gamma = [o.exp(o.clip(eval_log_curve(basis, g), LOG_GAMMA_MIN, LOG_GAMMA_MAX)) for g in log_gamma]
    return kappa, gamma


def clamp_controls(log_kappa, log_gamma):
    """Control values clamped into the valid range (log kappa <= log 60, gamma in
    [1e-4, 1e6]): how a point of a learned basis, which is unbounded, becomes a
    material. numpy arrays or Dr.Jit arrays; the fit applies the same clamp, so a
    fitted psi is the material it was fitted as."""
    o = ops(log_kappa, log_gamma)
    return o.fmin(log_kappa, LOG_KAPPA_MAX), o.clip(log_gamma, LOG_GAMMA_MIN, LOG_GAMMA_MAX)


def passed_through(log_kappa, log_gamma):
    """Where :func:`clamp_controls` leaves a control value as it is (its derivative
    is 1 there, 0 where it clamps): two bool numpy arrays shaped like the inputs."""
    lk, lg = np.asarray(log_kappa), np.asarray(log_gamma)
    return lk < LOG_KAPPA_MAX, (lg > LOG_GAMMA_MIN) & (lg < LOG_GAMMA_MAX)


def lobe_value(log_cos_h, kappa, gamma):
    """One lobe of Eq. 4 without its chromaticity: exp[kappa cos^gamma theta_h] - 1
    (1/sr), from log cos theta_h (guarded at log 1e-30) and the lobe's curves at theta_d."""
    o = ops(log_cos_h, kappa, gamma)
    return expm1(kappa * o.exp(gamma * o.fmax(log_cos_h, LOG_COS_H_MIN)))


def log_lobe_energy(log_kappa, log_gamma, terms=240):
    """log of one lobe's integral over cos theta_h, int_0^1 (exp[kappa u^gamma] - 1) du,
    and its derivatives in log kappa and log gamma, at control values (any shape;
    numpy float64; guards of :func:`clamp_controls` applied, where the derivatives are 0).

    The integral is the series sum_n kappa^n / (n! (n gamma + 1)), summed in log
    space (``terms`` terms: exact to float64 for kappa <= 60). It is a lobe's
    brightness as a whole: kappa alone is its peak, while a broad lobe (small
    gamma) of the same peak reflects far more light."""
    lk, lg = np.asarray(log_kappa, np.float64), np.asarray(log_gamma, np.float64)
    free_k, free_g = passed_through(lk, lg)
    lk, lg = clamp_controls(lk, lg)
    n = np.arange(1, terms + 1, dtype=np.float64)
    g = np.exp(lg)[..., None]
    t = n * lk[..., None] - gammaln(n + 1) - np.log1p(n * g)
    le = logsumexp(t, axis=-1)
    w = np.exp(t - le[..., None])                         # each term's share of the sum
    return le, (w * n).sum(-1) * free_k, -(w * n * g / (1 + n * g)).sum(-1) * free_g


def lobe_rgb(log_cos_h, theta_d, log_kappa, log_gamma, chromaticity, knots=DEFAULT_KNOTS):
    """Eq. 4: the RGB DSBRDF value as three arrays (1/sr).

    ``log_cos_h``: log cos theta_h (>= log 1e-30); ``theta_d`` in radians.
    """
    kappa, gamma = lobe_curves(theta_d, log_kappa, log_gamma, knots)
    rgb = [0.0, 0.0, 0.0]
    for k, g, c in zip(kappa, gamma, chromaticity):
        lobe = lobe_value(log_cos_h, k, g)
        rgb = [acc + c_l * lobe for acc, c_l in zip(rgb, c)]
    return rgb


#: a peak / off-peak ratio (:func:`highlight_ratio`) below this is no highlight
NO_HIGHLIGHT = 1.5


def highlight_ratio(values, theta_h, theta_d) -> float:
    """How much of a highlight a BRDF has: the median over samples near the
    half-vector peak (theta_h < 5 deg) over the median at theta_h 40-50 deg,
    both at theta_d < 30 deg, mean over channels. About 1 for a Lambertian
    surface; a glossy one is far above (inf: nothing off the peak). ``values``
    (N, 3) in 1/sr at the angles ``theta_h``, ``theta_d`` (N,) (radians), e.g.
    MERL samples."""
    v = np.asarray(values, dtype=np.float64)
    th, td = np.asarray(theta_h), np.asarray(theta_d)
    near = (th < math.radians(5)) & (td < math.radians(30))
    off = (th > math.radians(40)) & (th < math.radians(50)) & (td < math.radians(30))
    if not near.any() or not off.any():
        raise ValueError("the samples hold no angles near theta_h = 0 or 45 deg at theta_d < 30 deg")
    with np.errstate(over="ignore"):      # a peak over 1e8 with nothing off it: inf, all highlight
        return float(np.mean(np.median(v[near], axis=0) / np.maximum(np.median(v[off], axis=0), 1e-300)))


class Material:
    """A DSBRDF material: R lobes of log-spline kappa/gamma curves + chromaticity.

    Parameters
    ----------
    log_kappa, log_gamma : (R, 6) array_like
        Spline control values of log kappa_r and log gamma_r.
    chromaticity : (R, 3) array_like
        Per-lobe RGB chromaticity, non-negative, each row summing to one.
    knots : 9 floats, optional
        Spline knot vector on [0, pi/2].
    name : str, optional
    psi : array_like, optional
        Basis coefficients, when the material came from a learned basis
        (kept for provenance and as the starting point of refits).
    observed : :class:`~mi_dsbrdf.brdf.observed.DirectionWeights` or its dict, optional
        Where the image it was recovered from looked (:meth:`observed`).
    covariance_factor : (LOBE_PARAMETERS R, m) array_like, optional
        F with the posterior covariance F F^T of :meth:`parameters` (a recovered
        material: the Laplace approximation at the MAP, with the light held at
        its MAP); :meth:`sample` and :meth:`band` draw from it.
    """

    def __init__(self, log_kappa, log_gamma, chromaticity, knots=DEFAULT_KNOTS, name=None, psi=None,
                 observed=None, covariance_factor=None):
        self.log_kappa = _as_lobe_array(log_kappa, N_CONTROL, "log_kappa")
        self.log_gamma = _as_lobe_array(log_gamma, N_CONTROL, "log_gamma")
        self.chromaticity = _as_lobe_array(chromaticity, 3, "chromaticity")
        r = self.log_kappa.shape[0]
        if not (1 <= r <= MAX_LOBES):
            raise MaterialError("a material has 1 to %d lobes, got %d" % (MAX_LOBES, r))
        if self.log_gamma.shape[0] != r or self.chromaticity.shape[0] != r:
            raise MaterialError("log_kappa, log_gamma and chromaticity must have one row per lobe: "
                                "got %d, %d and %d rows" % (r, self.log_gamma.shape[0], self.chromaticity.shape[0]))
        try:
            self.knots = check_knots(knots)
        except ValueError as e:
            raise MaterialError(str(e)) from None
        if np.any(self.log_kappa > LOG_KAPPA_MAX + 1e-9):
            raise MaterialError("kappa must be <= %g (beyond, its derivatives overflow float32); "
                                "largest control value is %s" % (KAPPA_MAX, _exp_text(self.log_kappa.max())))
        if np.any(self.log_gamma < LOG_GAMMA_MIN - 1e-9) or np.any(self.log_gamma > LOG_GAMMA_MAX + 1e-9):
            raise MaterialError("gamma control values must lie in [%g, %g], got [%s, %s]" % (
                GAMMA_MIN, GAMMA_MAX, _exp_text(self.log_gamma.min()), _exp_text(self.log_gamma.max())))
        check_chromaticity(self.chromaticity)
        self.name = name
        self.psi = None if psi is None else np.asarray(psi, dtype=np.float64).reshape(-1)
        self._observed = observed if observed is None or isinstance(observed, DirectionWeights) \
            else DirectionWeights.from_dict(observed)
        self.covariance_factor = None
        if covariance_factor is not None:
            try:
                F = np.array(covariance_factor, dtype=np.float64)
            except (TypeError, ValueError):
                raise MaterialError("covariance_factor must be a table of numbers") from None
            if F.ndim != 2 or F.shape[0] != LOBE_PARAMETERS * r or not np.all(np.isfinite(F)):
                raise MaterialError("covariance_factor must be a finite (%d, m) table for %d lobe%s, got shape %s"
                                    % (LOBE_PARAMETERS * r, r, "" if r == 1 else "s", F.shape))
            self.covariance_factor = F

    # --- construction ------------------------------------------------------
    @classmethod
    def from_curves(cls, kappa, gamma, chromaticity, **kw):
        """From positive kappa/gamma control values (linear space, (R, 6))."""
        kappa = _as_lobe_array(kappa, N_CONTROL, "kappa")
        gamma = _as_lobe_array(gamma, N_CONTROL, "gamma")
        if np.any(kappa <= 0):
            raise MaterialError("kappa control values must be > 0, got min %g" % kappa.min())
        if np.any(gamma <= 0):
            raise MaterialError("gamma control values must be > 0, got min %g" % gamma.min())
        return cls(np.log(kappa), np.log(gamma), chromaticity, **kw)

    @classmethod
    def from_basis(cls, basis, psi, chromaticity, **kw):
        """From coefficients ``psi`` of a learned :class:`~mi_dsbrdf.brdf.curves.CurveBasis`
        (control values clamped by :func:`clamp_controls`)."""
        ctrl = basis.control_values(psi)
        log_kappa, log_gamma = clamp_controls(ctrl[:, 0], ctrl[:, 1])
        return cls(log_kappa, log_gamma, chromaticity, knots=basis.knots, psi=psi, **kw)

    @property
    def n_lobes(self) -> int:
        return self.log_kappa.shape[0]

    def with_observed(self, observed) -> "Material":
        """This material recording ``observed`` (a
        :class:`~mi_dsbrdf.brdf.observed.DirectionWeights`), as a new Material."""
        return Material(self.log_kappa, self.log_gamma, self.chromaticity, knots=self.knots, name=self.name,
                        psi=self.psi, observed=observed, covariance_factor=self.covariance_factor)

    def with_covariance(self, factor) -> "Material":
        """This material with the posterior covariance ``factor`` F F^T of its
        :meth:`parameters` (``covariance_factor``), as a new Material."""
        return Material(self.log_kappa, self.log_gamma, self.chromaticity, knots=self.knots, name=self.name,
                        psi=self.psi, observed=self._observed, covariance_factor=factor)

    # --- the posterior -------------------------------------------------------
    def parameters(self) -> np.ndarray:
        """(LOBE_PARAMETERS R,) the material as one vector: log kappa control values
        (R, 6), log gamma control values (R, 6), chromaticity variables (R, 2)
        (:func:`~mi_dsbrdf.brdf.chromaticity.chroma_logits`), flattened in that order."""
        return np.concatenate([self.log_kappa.ravel(), self.log_gamma.ravel(),
                               chroma_logits(self.chromaticity, floor=CHROMA_FLOOR).ravel()])

    @property
    def covariance(self):
        """(LOBE_PARAMETERS R, LOBE_PARAMETERS R) posterior covariance of
        :meth:`parameters`, or None for a material without one."""
        F = self.covariance_factor
        return None if F is None else F @ F.T

    def sample(self, n, seed=0) -> list:
        """``n`` materials drawn from the posterior (parameters ~ N(:meth:`parameters`,
        :attr:`covariance`); control values clamped as a basis point's are).
        MaterialError for a material without a covariance."""
        if self.covariance_factor is None:
            raise MaterialError("this material has no posterior covariance (only a recovered one does)")
        R, F = self.n_lobes, self.covariance_factor
        theta = self.parameters()[None] + np.random.default_rng(seed).standard_normal((int(n), F.shape[1])) @ F.T
        out = []
        for t in theta:
            log_kappa, log_gamma = clamp_controls(t[:N_CONTROL * R].reshape(R, N_CONTROL),
                                                  t[N_CONTROL * R:2 * N_CONTROL * R].reshape(R, N_CONTROL))
            out.append(Material(log_kappa, log_gamma, softmax_chroma(t[2 * N_CONTROL * R:].reshape(R, 2)),
                                knots=self.knots, name=self.name))
        return out

    def band(self, theta_h, theta_d, level=0.9, n=256, seed=0) -> tuple:
        """(lo, hi), each (N, 3) float64 in 1/sr: the central ``level`` band of the
        BRDF at half/difference angles (radians) over ``n`` posterior samples
        (:meth:`sample`). Where :meth:`observed` is zero the band is the prior's."""
        if not 0 < level < 1:
            raise ValueError("level must lie in (0, 1), got %r" % (level,))
        values = np.stack([m.eval(theta_h, theta_d) for m in self.sample(n, seed)])
        return tuple(np.quantile(values, [(1 - level) / 2, (1 + level) / 2], axis=0))

    def highlight_draws(self, n=128, seed=1) -> tuple:
        """(materials, ratios (n,)): the posterior samples a highlight is judged on
        (:meth:`sample`) and their :meth:`highlight_ratio`. MaterialError for a
        material without a covariance."""
        draws = self.sample(n, seed)
        return draws, np.array([m.highlight_ratio() for m in draws])

    def no_highlight_probability(self, below=NO_HIGHLIGHT) -> float:
        """The posterior's probability that the material has no highlight: the share
        of :meth:`highlight_draws` whose ratio is below ``below``."""
        return float(np.mean(self.highlight_draws()[1] < below))

    def observed(self, theta_h, theta_d):
        """How much of the image's light-weighted pixel x light pairs saw each
        (theta_h, theta_d) (radians; the share of its cell,
        :mod:`~mi_dsbrdf.brdf.observed`), or None for a material not recovered
        from an image. Zero: the image says nothing there, the model's prior does."""
        return None if self._observed is None else self._observed(theta_h, theta_d)

    # --- evaluation (float64 reference) -----------------------------------
    def curves(self, theta_d):
        """(kappa, gamma), each (N, R) float64, at angles ``theta_d`` (radians)."""
        th = np.asarray(theta_d, dtype=np.float64).reshape(-1)
        kappa, gamma = lobe_curves(th, self.log_kappa, self.log_gamma, self.knots)
        return np.stack(kappa, axis=-1), np.stack(gamma, axis=-1)

    def eval(self, theta_h, theta_d) -> np.ndarray:
        """BRDF values (N, 3) float64 in 1/sr at half/difference angles (radians)."""
        th = np.asarray(theta_h, dtype=np.float64).reshape(-1)
        td = np.asarray(theta_d, dtype=np.float64).reshape(-1)
        if th.shape != td.shape:
            raise ValueError("theta_h and theta_d must have the same length, got %d and %d" % (th.size, td.size))
        log_cos = log_cos_h(np.cos(th), np.sin(th) ** 2)
        return np.stack(lobe_rgb(log_cos, td, self.log_kappa, self.log_gamma, self.chromaticity, self.knots), -1)

    def highlight_ratio(self) -> float:
        """:func:`highlight_ratio` of this material on the MERL grid's (theta_h,
        theta_d) cells (the curves do not depend on phi_d)."""
        from mi_dsbrdf.brdf.measured import grid_angles
        th, td = np.meshgrid(*grid_angles()[:2], indexing="ij")
        return highlight_ratio(self.eval(th.ravel(), td.ravel()), th.ravel(), td.ravel())

    # --- files ---------------------------------------------------------------
    def to_dict(self) -> dict:
        d = {"format": FORMAT, "version": 1, "name": self.name, "lobes": self.n_lobes,
             "knots": list(self.knots), "log_kappa": self.log_kappa.tolist(),
             "log_gamma": self.log_gamma.tolist(), "chromaticity": self.chromaticity.tolist()}
        if self.psi is not None:
            d["psi"] = self.psi.tolist()
        if self._observed is not None:
            d["observed"] = self._observed.to_dict()
        if self.covariance_factor is not None:
            d["covariance_factor"] = self.covariance_factor.tolist()
        return d

    @classmethod
    def from_dict(cls, d: dict, source: str = "material"):
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise MaterialError("%s is not a mi-dsbrdf material (expected \"format\": %r)" % (source, FORMAT))
        missing = [k for k in ("log_kappa", "log_gamma", "chromaticity") if k not in d]
        if missing:
            raise MaterialError("%s lacks %s" % (source, ", ".join(missing)))
        try:
            m = cls(d["log_kappa"], d["log_gamma"], d["chromaticity"], knots=d.get("knots", DEFAULT_KNOTS),
                    name=d.get("name"), psi=d.get("psi"), observed=d.get("observed"),
                    covariance_factor=d.get("covariance_factor"))
        except MaterialError as e:
            raise MaterialError("%s: %s" % (source, e)) from None
        lobes = d.get("lobes", m.n_lobes)
        if not isinstance(lobes, int) or isinstance(lobes, bool) or lobes != m.n_lobes:
            raise MaterialError("%s: \"lobes\": %r but log_kappa, log_gamma and chromaticity have %d row%s"
                                % (source, lobes, m.n_lobes, "" if m.n_lobes == 1 else "s"))
        return m

    def save(self, path) -> None:
        with open(path, "w") as f:
            json.dump(self.to_dict(), f, indent=1)

    @classmethod
    def load(cls, path):
        path = os.fspath(path)
        try:
            with open(path) as f:
                d = json.load(f)
        except FileNotFoundError:
            raise MaterialError("material file %s does not exist" % path) from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise MaterialError("material file %s is unreadable: %s" % (path, e)) from None
        return cls.from_dict(d, source=path)

    def __repr__(self):
        return "Material(name=%r, lobes=%d)" % (self.name, self.n_lobes)


def check_chromaticity(c, tol=1e-4) -> np.ndarray:
    """Raise MaterialError unless every row is >= 0 and sums to one (within tol)."""
    c = np.asarray(c, dtype=np.float64)
    if np.any(c < 0):
        raise MaterialError("chromaticity must be non-negative, got %s" % np.round(c, 6).tolist())
    sums = c.sum(axis=-1)
    if np.any(np.abs(sums - 1.0) > tol):
        raise MaterialError("each lobe's chromaticity must sum to 1, got sums %s" % np.round(sums, 6).tolist())
    return c


def _exp_text(log_value) -> str:
    """exp(``log_value``) as text, also where it overflows a float (``exp(1e+06)``)."""
    return "%g" % math.exp(log_value) if log_value < 700 else "exp(%g)" % log_value


def _as_lobe_array(values, width, what) -> np.ndarray:
    try:
        a = np.array(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise MaterialError("%s must be numbers, got %r" % (what, values)) from None
    if a.ndim == 1 and a.size == width:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != width:
        raise MaterialError("%s must have %d values per lobe, got shape %s" % (what, width, a.shape))
    if not np.all(np.isfinite(a)):
        raise MaterialError("%s must be finite" % what)
    return a
