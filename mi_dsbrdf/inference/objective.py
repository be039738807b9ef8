"""The negative log posterior of paper §4 (Eq. 18) for one scene and image.

    -log p(psi, c, L | I) = likelihood (Eq. 19)
                            + reflectance priors: GMM (Eq. 6), hue (Eq. 12), curve penalty
                            + illumination priors: entropy (Eq. 13-15), gradient (Eq. 16)

:class:`Posterior` evaluates it term by term, each weighted by the
:class:`~mi_dsbrdf.config.Config` weights scaled to the observed pixel count.
It renders through :class:`~mi_dsbrdf.inference.lobes.LobeSum` views of the
caller's :class:`~mi_dsbrdf.inference.forward.TexelSum`, with the material
(psi, chromaticity variables) passed to each call: it holds no material state
and changes nothing it is given.
The blocks that minimise it are :mod:`~mi_dsbrdf.inference.envmap` (the
illumination map), :mod:`~mi_dsbrdf.inference.light` (a point or directional
light) and :mod:`~mi_dsbrdf.inference.reflectance` (psi and chromaticity).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from mi_dsbrdf.brdf.chromaticity import softmax_chroma
from mi_dsbrdf.brdf.dsbrdf import Material, log_lobe_energy
from mi_dsbrdf.config import Config
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.inference.transport import apply_transport, transport_adjoint
from mi_dsbrdf.inference.lobes import LobeSum
from mi_dsbrdf.inference.illumination_priors import EntropyPrior, GradientPrior, LightColourPrior
from mi_dsbrdf.inference.likelihood import KINK, log_likelihood_terms

#: how far (natural log) a recovered kappa/gamma control value may leave the range the
#: library's materials span at that control point before CURVE_PENALTY applies
CURVE_MARGIN = 1.0
#: how far (natural log) a recovered lobe's energy (:func:`~mi_dsbrdf.brdf.dsbrdf.log_lobe_energy`)
#: at a control point may exceed the brightest library lobe's there before CURVE_PENALTY applies
ENERGY_MARGIN = 0.5
#: weight of the squared excess (log units) of a control value or a lobe's energy beyond its range
CURVE_PENALTY = 100.0
#: the fewest and the most pixels the reflectance block works on (16 + 6 variables:
#: a few thousand pixels, evenly spread, constrain them as well as all of them do)
MIN_REFLECTANCE_PIXELS, MAX_REFLECTANCE_PIXELS = 64, 4096
#: the fraction (0 to 1) of its components' volume terms the GMM prior keeps under
#: an illumination map (:meth:`~mi_dsbrdf.model.priors.GaussianMixture.nll`): 0 ranks
#: psi by weight and Mahalanobis distance only, so that the GMM's narrow components
#: do not outweigh its broad ones (near-Lambertian materials)
GMM_VOLUME = 0.0


@dataclasses.dataclass(frozen=True)
class PixelView:
    """Pixels a block works on: their LobeSum, observed values (P, 3), usable
    flags (P,) and the factor that makes their likelihood stand for all usable pixels."""
    lobes: LobeSum
    observed: np.ndarray
    keep: np.ndarray
    weight: float


def spread(rows, n) -> np.ndarray:
    """At most ``n`` of the indices ``rows``, evenly spread over them (all if fewer)."""
    if rows.size <= n:
        return rows
    return rows[np.linspace(0, rows.size - 1, n).round().astype(np.int64)]


def direction_from_angles(theta, phi) -> np.ndarray:
    """World direction (y up, the lat-long convention of :mod:`mi_dsbrdf.inference.latlong`)."""
    st = np.sin(theta)
    return np.array([st * np.sin(phi), np.cos(theta), -st * np.cos(phi)])


def angles_from_direction(d) -> tuple:
    """(theta, phi) of a world direction, the inverse of :func:`direction_from_angles`."""
    d = np.asarray(d, dtype=np.float64) / np.linalg.norm(d)
    return float(np.arccos(np.clip(d[1], -1, 1))), float(np.arctan2(d[0], -d[2]))


class Posterior:
    """-log p(psi, c, L | I) for one view of one object and its observed image.

    Parameters
    ----------
    texels : the view (:class:`~mi_dsbrdf.inference.forward.TexelSum`) at the map's resolution
    observed : (H, W, >=3) float image (radiance)
    mask : (H, W) bool, the pixels the likelihood uses
    model : :class:`~mi_dsbrdf.model.model_file.ReflectanceModel`
    config : :class:`~mi_dsbrdf.config.Config`
    point : (centre, distance) of a point light (kept fixed), None for a
        directional light or a map
    max_pixels : the most pixels the posterior works on (default
        ``config.map_pairs`` / texels; see :class:`~mi_dsbrdf.config.Config`)
    gmm_volume : the fraction of the GMM's volume terms the prior keeps (default
        :data:`GMM_VOLUME`, a map's; a light's inference passes
        :data:`~mi_dsbrdf.inference.light.LIGHT_GMM_VOLUME`)
    """

    def __init__(self, texels: TexelSum, observed, mask, model, config: Config, point=None, max_pixels=None,
                 gmm_volume=None):
        self.model, self.cfg, self.point = model, config, point
        self.gmm_volume = GMM_VOLUME if gmm_volume is None else gmm_volume
        obs = np.asarray(observed, dtype=np.float64).reshape(-1, observed.shape[-1])[texels.pixels, :3]
        keep = np.asarray(mask, bool).reshape(-1)[texels.pixels]
        self.offset = config.log_offset * float(np.mean(obs[keep]))    # > 0 even when most pixels are unlit
        self.scale = config.likelihood_scale                  # Eq. 19: sum |log error| / b
        self.kink = KINK
        self.k, self.R = model.basis.n_bases, model.basis.n_lobes
        n_usable = int(keep.sum())
        # the posterior's pixels (Config.map_pairs): all usable ones, or an evenly
        # spread subset whose likelihood is scaled up (``weight``) to stand for all
        if max_pixels is None:
            max_pixels = config.map_pairs // max(texels.n_texels, 1)
        rows = spread(np.nonzero(keep)[0], max(int(max_pixels), MIN_REFLECTANCE_PIXELS))
        if rows.size < n_usable:
            texels, obs, keep = texels.subset(rows), obs[rows], np.ones(rows.size, bool)
        self.observed, self.keep, self.weight = obs, keep, n_usable / max(int(keep.sum()), 1)
        self.view = LobeSum(texels)
        # the reflectance block's pixels: an evenly spread subset of those
        n_sub = int(np.clip(config.reflectance_pairs // max(texels.n_texels, 1), MIN_REFLECTANCE_PIXELS,
                            MAX_REFLECTANCE_PIXELS))
        rows = spread(np.nonzero(keep)[0], n_sub)
        if rows.size < int(keep.sum()):
            self.refl = PixelView(self.view.subset(rows), obs[rows], np.ones(rows.size, bool),
                                  n_usable / rows.size)
        else:
            self.refl = PixelView(self.view, obs, keep, self.weight)
        # the range of the library's kappa/gamma control values (the priors' data,
        # model.prior_psi): a recovered curve stays within CURVE_MARGIN of it (one
        # image sees few theta_d; without this box the unobserved, grazing end of a
        # curve can run off to kappa = e^60)
        ctrl = np.stack([model.basis.control_values(p) for p in model.prior_psi])
        self.curve_range = (ctrl.min(axis=0).reshape(-1) - CURVE_MARGIN, ctrl.max(axis=0).reshape(-1) + CURVE_MARGIN)
        # a box per control value still lets a lobe combine a library's largest kappa
        # with its smallest gamma: a broad lobe e^20 times brighter than any measured
        # one at the unobserved theta_d (gold under a point light); each lobe's energy
        # at each control point stays within ENERGY_MARGIN of the library's brightest
        self.energy_max = log_lobe_energy(ctrl[:, :, 0], ctrl[:, :, 1])[0].max(axis=0) + ENERGY_MARGIN
        c0 = model.basis.control_values(np.zeros(self.k)).reshape(-1)      # control values are linear in psi
        self.curve_map = (c0, np.stack([model.basis.control_values(e).reshape(-1) - c0 for e in np.eye(self.k)],
                                       axis=1))
        self.w = config.prior_weights(n_usable)
        self.entropy = EntropyPrior(self.w["entropy"])
        self.gradient = GradientPrior(self.w["gradient"], alpha=config.gradient_alpha, eps=config.gradient_eps)
        self.light_colour = LightColourPrior(self.w["light_colour"], config.light_temperature_sigma,
                                             config.light_tint_sigma)

    def aim(self, theta, phi) -> None:
        """Light the pixels from the direction (theta, phi) (seen from the object):
        a directional light, or the point light at ``distance`` from ``centre``
        that way (its intensity then stands for W/sr, not irradiance)."""
        d = direction_from_angles(theta, phi)
        whole = self.refl.lobes is self.view

        def lit(view):
            if self.point is None:
                return view.with_directions(d[None], [1.0])
            return view.with_point(np.asarray(self.point[0]) + self.point[1] * d)
        self.view = lit(self.view)
        self.refl = dataclasses.replace(self.refl, lobes=self.view if whole else lit(self.refl.lobes))

    # --- reflectance -------------------------------------------------------------
    def material(self, psi, logits) -> Material:
        """The DSBRDF of psi (k,) and the chromaticity variables (R, 2)."""
        return Material.from_basis(self.model.basis, psi, softmax_chroma(logits))

    def transport(self, psi, logits) -> np.ndarray:
        """(3, P, T) transport of all pixels under the material (psi, logits)."""
        return self.view.transport(self.material(psi, logits))


    def prior_terms(self, psi, logits, log_map=None, bins=None) -> dict:
        """The weighted prior terms one by one, for the log: the curve penalty, GMM
        (Eq. 6), hue (Eq. 12), chromaticity (if weighted) and, given a map,
        entropy (Eq. 13-15), gradient (Eq. 16) and light colour (if weighted)."""
        terms = {"curve_penalty": self.curve_penalty(psi)[0]}
        if self.model.gmm is not None:
            terms["gmm"] = self.gmm_prior(psi)[0]
        chroma = softmax_chroma(logits)
        if self.model.hue_prior is not None:
            terms["hue"] = self.w["hue"] * self.model.hue_prior.nll(chroma)
        if self.w["chromaticity"] > 0:
            terms["chromaticity"] = self.w["chromaticity"] * self.model.chromaticity_prior.nll(chroma)
        if log_map is not None:
            terms["entropy"] = self.entropy(log_map, bins)[0]
            terms["gradient"] = self.gradient(log_map)[0]
            if self.w["light_colour"] > 0:
                terms["light_colour"] = self.light_colour(log_map)[0]
        return {k: float(v) for k, v in terms.items()}

    def chroma_prior_grad(self, chroma) -> np.ndarray:
        """d/d chromaticity (R, 3) of the weighted hue and chromaticity priors."""
        g = np.zeros_like(np.asarray(chroma, dtype=np.float64))
        if self.model.hue_prior is not None:
            g += self.w["hue"] * self.model.hue_prior.grad(chroma)
        if self.w["chromaticity"] > 0:
            g += self.w["chromaticity"] * self.model.chromaticity_prior.grad(chroma)
        return g

    def gmm_prior(self, psi) -> tuple:
        """(value, gradient, Gauss-Newton Hessian) of the weighted GMM prior (Eq. 6,
        with or without its components' volume terms: ``gmm_volume``).
        The model must have a GMM."""
        gmm, w, vol = self.model.gmm, self.w["gmm"], self.gmm_volume
        return w * gmm.nll(psi, vol), w * gmm.grad(psi, vol), w * gmm.dominant_precision(psi, vol)

    def curve_penalty(self, psi) -> tuple:
        """(value, gradient, Gauss-Newton Hessian) of CURVE_PENALTY * sum of the squared
        excess of the kappa/gamma control values beyond ``curve_range`` and of each
        lobe's log energy beyond ``energy_max``: ψ far from the data can put a curve's
        unobserved (grazing) end at kappa = e^60, or a bright lobe there."""
        c0, A = self.curve_map
        c = c0 + A @ psi
        excess = np.maximum(c - self.curve_range[1], 0) - np.maximum(self.curve_range[0] - c, 0)
        # the energy of each lobe at each control point, its Jacobian in psi (R x 6, k)
        ctrl, A_ctrl = c.reshape(self.R, 2, -1), A.reshape(self.R, 2, -1, self.k)
        log_e, d_kappa, d_gamma = log_lobe_energy(ctrl[:, 0], ctrl[:, 1])
        excess = np.concatenate([excess, np.maximum(log_e - self.energy_max, 0).reshape(-1)])
        J = np.concatenate([A, (d_kappa[..., None] * A_ctrl[:, 0] + d_gamma[..., None] * A_ctrl[:, 1])
                            .reshape(-1, self.k)])
        active = (excess != 0).astype(np.float64)
        return (CURVE_PENALTY * float(excess @ excess), 2 * CURVE_PENALTY * J.T @ excess,
                2 * CURVE_PENALTY * (J.T * active) @ J)

    def reflectance_terms(self, psi, logits, L) -> tuple:
        """(value, likelihood) of likelihood + GMM + hue priors + curve penalty at
        fixed L, the likelihood over the reflectance block's pixels (``self.refl``),
        no gradients (the block takes its derivatives from
        :meth:`~mi_dsbrdf.inference.lobes.LobeSum.jacobian`)."""
        lik = self.subset_likelihood(self.material(psi, logits), L)
        return lik + sum(self.prior_terms(psi, logits).values()), lik

    def subset_likelihood(self, material, L) -> float:
        """Eq. 19 over the reflectance block's pixels (``self.refl``) of ``material``
        under the light L (T, 3), scaled to stand for all usable pixels."""
        v = self.refl
        return self.likelihood(v.lobes.render(material, L), v.observed, v.keep) * v.weight

    def likelihood(self, image, observed, keep) -> float:
        """Eq. 19 of the pixel radiance ``image`` (P, 3) against ``observed`` (P, 3)
        at the pixels ``keep`` (P,), unweighted."""
        return log_likelihood_terms(image[:, None, :], observed[:, None, :], keep[:, None], self.offset,
                                    self.scale, grad=False, kink=self.kink)[0]

    # --- illumination ------------------------------------------------------------
    def map_likelihood(self, log_map, T, seen, grad=True) -> tuple:
        """(value, d/d log_map or None) of the likelihood (Eq. 19) of the map at fixed reflectance."""
        L = np.where(seen[..., None], np.exp(log_map), 0.0)
        image = apply_transport(T, L)
        lik, g_img = log_likelihood_terms(image[:, None, :], self.observed[:, None, :], self.keep[:, None],
                                          self.offset, self.scale, grad, kink=self.kink)
        if not grad:
            return lik * self.weight, None
        return lik * self.weight, transport_adjoint(T, g_img[:, 0, :]).reshape(log_map.shape) * (L * self.weight)

    def illumination_terms(self, log_map, T, seen, bins) -> tuple:
        """(value, d/d log_map, likelihood) of likelihood + entropy + gradient (+ light
        colour) priors at fixed reflectance."""
        lik, g = self.map_likelihood(log_map, T, seen)
        e, ge = self.entropy(log_map, bins)
        s, gs = self.gradient(log_map)
        value, grad = lik + e + s, g + ge + gs
        if self.w["light_colour"] > 0:
            c, gc = self.light_colour(log_map)
            value, grad = value + c, grad + gc
        return value, grad, lik
