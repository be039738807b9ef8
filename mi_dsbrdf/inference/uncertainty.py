"""The posterior's uncertainty at the MAP (not in the paper): the material's
Laplace approximation (:func:`laplace`, :class:`Laplace`), the illumination
map's per-texel spread (:func:`illumination_spread`), each tempered by a
temperature chosen on validation, and the doubt on a recovered highlight
(:func:`highlight_doubt`).

The first two take the likelihood's curvature from Eq. 19's expected Hessian at the
residuals' own scale (:func:`fisher_scale`) and the priors' curvature from the
blocks that minimise them (:mod:`~mi_dsbrdf.inference.reflectance`,
:class:`~mi_dsbrdf.inference.illumination_priors.GradientPrior`).
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from mi_dsbrdf.brdf.curves import N_CONTROL
from mi_dsbrdf.brdf.dsbrdf import LOBE_PARAMETERS, NO_HIGHLIGHT, passed_through
from mi_dsbrdf.inference.transport import apply_transport
from mi_dsbrdf.inference.reflectance import (chroma_prior_hessian, log_residuals, material_columns,
                                             prior_derivatives)


def fisher_scale(post, d) -> float:
    """b b_hat: Eq. 19's expected Hessian in a log pixel value is 1 / (b b_hat), b
    the likelihood's scale (``post.scale``) and b_hat = mean |d| the residuals'
    own (the Laplacian's density at zero is 1 / (2 b_hat)), at least the kink."""
    return post.scale * max(float(np.mean(np.abs(d))), post.kink)


#: the temperature of the material's posterior covariance (:meth:`Laplace.factor`)
#: under an illumination map; chosen on validation for the 90 % band's coverage of the truth
POSTERIOR_TEMPERATURE = 4000.0
#: the same under a point or directional light (one direction a pixel shows less of
#: the BRDF, and the answer's error outweighs the curvature more); chosen alike, on
#: the validation materials under point lights
LIGHT_POSTERIOR_TEMPERATURE = 15000.0


@dataclasses.dataclass(frozen=True)
class Laplace:
    """The Laplace approximation of the posterior of the material at its MAP,
    with the light held at its MAP (paper §4's posterior, not in the paper).

    In the variables x = (psi (k,), chromaticity variables (R, 2) if they were
    fitted): the negative log posterior's Hessian is ``likelihood`` + ``prior``;
    ``to_parameters`` maps a change of x to the material's parameters
    theta = (log kappa controls (R, 6), log gamma controls (R, 6), chromaticity
    variables (R, 2)), flattened in that order (controls a clamp holds do not move).

    Attributes
    ----------
    likelihood : (n, n) expected Hessian of Eq. 19 at the MAP: the Laplacian's
        Fisher information with its scale from the residuals themselves
    prior : (n, n) Hessian of the reflectance priors (GMM, curve penalty, and
        the positive part of the hue and chromaticity priors')
    to_parameters : (LOBE_PARAMETERS R, n)
    seconds : the time it took
    alternatives : ((delta (LOBE_PARAMETERS R,), energy), ...): other modes the
        search found, as their parameters less the MAP's and their negative log
        posterior above the MAP's (>= 0)
    temperature : the shipped temperature :meth:`factor` tempers with
        (:data:`POSTERIOR_TEMPERATURE` under a map, :data:`LIGHT_POSTERIOR_TEMPERATURE`
        under a point or directional light)
    """
    likelihood: np.ndarray
    prior: np.ndarray
    to_parameters: np.ndarray
    seconds: float = 0.0
    alternatives: tuple = ()
    temperature: float = POSTERIOR_TEMPERATURE

    def factor(self, temperature=None) -> np.ndarray:
        """(LOBE_PARAMETERS R, n) F with the parameters' covariance F F^T =
        temperature x A (likelihood + prior)^-1 A^T, A = ``to_parameters``: the
        posterior tempered, p^(1 / temperature) (default :attr:`temperature`;
        neighbouring pixels' residuals are not
        independent, and the priors' weights grow with the pixels), plus one
        column a mode in ``alternatives`` (F has n + their number columns).
        Eigenvalues of the Hessian are floored at EIGEN_FLOOR times the largest."""
        t = self.temperature if temperature is None else float(temperature)
        w, V = np.linalg.eigh(self.likelihood + self.prior)
        w = np.maximum(w, EIGEN_FLOOR * max(float(w.max()), 1e-300))
        F = self.to_parameters @ (V * np.sqrt(t / w))
        if not self.alternatives:
            return F
        # other modes: a mixture of the MAP's Gaussian moved to each mode, weighted by the
        # tempered posterior exp(-energy / t), matched in its second moment about the MAP
        # (the MAP's covariance plus each offset's outer product times its weight)
        weights = mode_weights([e for _, e in self.alternatives], t)
        return np.concatenate([F] + [np.sqrt(wt) * np.asarray(d, dtype=np.float64)[:, None]
                                     for wt, (d, _) in zip(weights, self.alternatives)], axis=1)


def mode_weights(gaps, temperature) -> np.ndarray:
    """The posterior's weight at ``temperature`` t of each other mode, exp(-gap / t)
    / (1 + sum exp(-gap / t)), ``gaps`` their negative log posterior above the
    MAP's (>= 0). The MAP's own weight is 1 less their sum."""
    p = np.array([math.exp(-max(float(g), 0.0) / temperature) for g in gaps])
    return p / (1.0 + p.sum())


#: the smallest eigenvalue of the Hessian the covariance keeps, relative to the largest
EIGEN_FLOOR = 1e-9


def laplace(post, psi, logits, L, fit_chroma=True, temperature=POSTERIOR_TEMPERATURE) -> Laplace:
    """The :class:`Laplace` approximation at the MAP (psi (k,), chromaticity
    variables (R, 2)) under the light L (T, 3) (the posterior's light direction
    as set), over the reflectance block's pixels scaled to stand for all usable
    ones. One Jacobian of the image (the cost of one Levenberg-Marquardt step).

    Its likelihood part is sum_i J_i J_i^T / :func:`fisher_scale`, J the
    Jacobian of the log pixel values; ``temperature``: the shipped one it keeps
    (:attr:`Laplace.temperature`)."""
    t0 = time.perf_counter()
    k, R = psi.size, logits.shape[0]
    jac = post.refl.lobes.jacobian(post.material(psi, logits), L)
    Jd, d = log_residuals(post, np.concatenate(material_columns(post, jac, psi, logits, fit_chroma), axis=0),
                          jac.image)
    likelihood = post.refl.weight * (Jd @ Jd.T) / fisher_scale(post, d)
    prior = sum(h for _, h in prior_derivatives(post, psi, logits, fit_chroma))
    if fit_chroma:
        # the hue prior is not convex: its curvature enters where it is positive
        w, V = np.linalg.eigh(chroma_prior_hessian(post, logits))
        prior[k:, k:] += (V * np.maximum(w, 0.0)) @ V.T
    basis = post.model.basis
    ctrl = basis.control_values(psi)
    free = np.stack(passed_through(ctrl[:, 0], ctrl[:, 1]), axis=1)             # (R, 2, 6)
    moves = (basis.bases * free)                                                 # (k, R, 2, 6)
    to_controls = np.concatenate([moves[:, :, 0].reshape(k, -1), moves[:, :, 1].reshape(k, -1)], axis=1).T
    n = prior.shape[0]
    to_parameters = np.zeros((LOBE_PARAMETERS * R, n))
    to_parameters[:2 * N_CONTROL * R, :k] = to_controls
    if fit_chroma:
        to_parameters[2 * N_CONTROL * R:, k:] = np.eye(2 * R)
    return Laplace(likelihood, prior, to_parameters, time.perf_counter() - t0, temperature=temperature)


#: the posterior probability of no highlight (:func:`highlight_doubt`) from which a
#: recovered highlight is flagged (``Recovery.flags``); chosen on validation: the
#: middle of the probabilities that flag at least 80 % of the near-Lambertian
#: materials recovered glossy and at most 10 % of the rest
HIGHLIGHT_DOUBT = 0.22


def highlight_doubt(material) -> float | None:
    """For a recovered ``material`` (with its covariance) whose MAP has a highlight
    (:meth:`~mi_dsbrdf.brdf.dsbrdf.Material.highlight_ratio` at least
    ``NO_HIGHLIGHT``): the posterior's probability that it has none
    (:meth:`~mi_dsbrdf.brdf.dsbrdf.Material.no_highlight_probability`, at the
    shipped temperature). None for a MAP without a highlight."""
    if material.highlight_ratio() < NO_HIGHLIGHT:
        return None
    return material.no_highlight_probability()


#: the temperature of the map's spread (:func:`illumination_spread`), chosen on
#: validation for the 90 % band's coverage of the truth map
MAP_TEMPERATURE = 300.0


def illumination_spread(post, log_map, T, seen, temperature=None) -> np.ndarray:
    """(H, W, 3) the posterior's standard deviation of the log map (natural log
    units) per texel and channel, from the diagonal of the illumination block's
    Hessian at the MAP with the material held: the likelihood's expected Hessian
    (:func:`fisher_scale`, as the material's :func:`laplace`) plus the gradient prior's
    (Eq. 16, its majoriser's diagonal); the entropy prior (Eq. 13-15), not convex,
    is left out. Tempered: the variance times ``temperature`` (default
    :data:`MAP_TEMPERATURE`). A diagonal
    ignores the texels' correlations: it understates the spread where neighbours
    trade light. Texels no pixel sees are 0 (no estimate, as in the map)."""
    t = MAP_TEMPERATURE if temperature is None else float(temperature)
    H, W = seen.shape
    L = np.where(seen[..., None], np.exp(log_map), 0.0).reshape(-1, 3)
    image = apply_transport(T, L)
    keep = post.keep
    mp = np.maximum(image[keep], 0) + post.offset                              # (P, 3)
    d = np.log(mp) - np.log(np.maximum(post.observed[keep], 0) + post.offset)
    # d log(pixel) / d log(texel) = T L / pixel, per channel
    diag = np.stack([((np.asarray(T[c][keep], dtype=np.float64) * L[None, :, c] / mp[:, c:c + 1]) ** 2).sum(axis=0)
                     for c in range(3)], axis=1).reshape(H, W, 3) * post.weight / fisher_scale(post, d)
    diag = diag + post.gradient.majoriser_diagonal(log_map)[..., None]
    return np.where(seen[..., None], np.sqrt(t / np.maximum(diag, 1e-300)), 0.0)
