"""Illumination priors (paper Eq. 13-16), as negative log densities with gradients.

The entropy and gradient priors act on the log radiance x = log L of an
(H, W, C) lat-long map (the illumination is optimised in log, which keeps it
positive), weight texels by their solid angle, and return (value, gradient
with respect to x) in float64.
:class:`LightColourPrior` (not in the paper) prices the colour of the light
the whole map sheds.
"""
from __future__ import annotations

import numpy as np

from mi_dsbrdf.inference.latlong import texel_solid_angles

#: (3, 2) the light-colour prior's axes in log RGB: colour temperature (R - B) and
#: tint (R + B - 2 G), orthonormal and orthogonal to (1, 1, 1)
LIGHT_AXES = np.array([[1.0, 0.0, -1.0], [1.0, -2.0, 1.0]]).T / np.array([np.sqrt(2.0), np.sqrt(6.0)])


def _texel_weights(height, width):
    """(H, W) solid angles normalised to sum to one."""
    w = texel_solid_angles(height, width)
    return w / w.sum()


class EntropyPrior:
    """Eq. 13-15: -log p(L) = weight * H(L), the entropy of the distribution of
    log luminance over the sphere, estimated by a kernel density (KDE) histogram.

    Natural illumination is dominated by few, bright sources; its log-radiance
    histogram is peaked (low entropy), while the blur that trades off against a
    glossy BRDF spreads it. With samples x_i (mean log channel of texel i,
    weight w_i = solid-angle fraction) and K bin centres b_k:

        h_k = sum_i w_i K((x_i - b_k) / sigma),   p_k = h_k / sum_k h_k,
        H = -sum_k p_k log p_k,

    K Gaussian, sigma = ``bandwidth_bins`` bin spacings.

    The bins are constants of the function: :meth:`bins_for` spans a map's
    range (inference fixes them at the start of each illumination block), and
    the entropy is then a smooth function of the map with an exact gradient.
    """

    def __init__(self, weight=1.0, n_bins=64, bandwidth_bins=1.5):
        self.weight = float(weight)
        self.n_bins = int(n_bins)
        self.bandwidth_bins = float(bandwidth_bins)

    def bins_for(self, log_map, seen=None):
        """(centres (K,), sigma) spanning the log luminance of ``log_map`` (H, W, C)
        with a 3-sigma margin; with ``seen`` (H, W) over those texels only: the
        unseen ones (held black, below every bin) count at the darkest seen value,
        so that they do not stretch the bins."""
        x = np.asarray(log_map, dtype=np.float64)
        if seen is not None:
            x = np.where(seen[..., None], x, x[seen].min())
        xl = x.mean(axis=2)
        lo, hi = float(xl.min()), float(xl.max())
        span = max(hi - lo, 1e-3)
        sigma = span / self.n_bins * self.bandwidth_bins
        return np.linspace(lo - 3 * sigma, hi + 3 * sigma, self.n_bins), sigma

    def __call__(self, log_map, bins=None):
        """(weight * H, gradient (H, W, C)) of an (H, W, C) log map; ``bins``
        from :meth:`bins_for` (default: those of this map)."""
        x = np.asarray(log_map, dtype=np.float64)
        H_, W_, C = x.shape
        lum_w = np.full(C, 1.0 / C)
        centres, sigma = self.bins_for(x) if bins is None else bins
        w = _texel_weights(H_, W_).reshape(-1)
        s = (x @ lum_w).reshape(-1)                                 # mean log channel
        z = (s[:, None] - centres[None]) / sigma                  # (N, K)
        k = np.exp(-0.5 * z * z)
        h = w @ k + 1e-300
        tot = h.sum()
        p = h / tot
        ent = float(-(p * np.log(p)).sum())
        # dH/dh_k = -(log p_k + 1)/tot + sum_j p_j (log p_j + 1)/tot
        dH_dp = -(np.log(p) + 1.0)
        dH_dh = (dH_dp - (p * dH_dp).sum()) / tot
        dh_ds = w[:, None] * k * (-z / sigma)                     # (N, K)
        g = (dh_ds @ dH_dh).reshape(H_, W_)
        return self.weight * ent, self.weight * g[..., None] * lum_w[None, None, :]


class GradientPrior:
    """Eq. 16: a hyper-Laplacian prior on the colour gradients of the log map,

        -log p(L) = weight * sum_i w_i (|grad x|_i^2 + eps^2)^(alpha / 2),

    alpha < 1 (heavy-tailed: sharp edges such as the sun's rim cost little,
    noise a lot). Lat-long aware: phi differences wrap around, are divided by
    sin theta (the angular distance between neighbouring texels of a row) and
    all differences are in units of the polar texel spacing; texels weigh by
    solid angle. eps keeps the gradient finite at the kink |grad x| = 0, and
    sets how stiff the prior is where the map is flat (its curvature there grows
    as eps^(alpha - 2)); inference takes it from ``Config.gradient_eps``.
    """

    def __init__(self, weight=1.0, alpha=0.5, eps=1e-2):
        if not 0 < alpha < 1:
            raise ValueError("the hyper-Laplacian exponent alpha must be in (0, 1), got %r" % alpha)
        self.weight, self.alpha, self.eps = float(weight), float(alpha), float(eps)

    @staticmethod
    def differences(log_map) -> tuple:
        """The prior's differences of an (H, W, C) log map, in polar texel spacings:
        (d_phi (H, W, C), d_theta (H, W, C), 1 / sin theta scaled (H, 1, 1)); the last
        row's d_theta is 0 (no neighbour past the pole)."""
        x = np.asarray(log_map, dtype=np.float64)
        H_, W_, _ = x.shape
        theta = (np.arange(H_) + 0.5) / H_ * np.pi
        inv_s = (1.0 / (np.sin(theta) * (2 * np.pi / W_) / (np.pi / H_)))[:, None, None]
        dphi = (np.roll(x, -1, axis=1) - x) * inv_s               # wraps in phi
        dth = np.zeros_like(x)
        dth[:-1] = x[1:] - x[:-1]                                  # no neighbour past the poles
        return dphi, dth, inv_s

    def _magnitude2(self, dphi, dth):
        """(H, W) |grad x|^2 + eps^2, summed over the channels."""
        return (dphi ** 2 + dth ** 2).sum(axis=2) + self.eps ** 2

    def _curvature(self, m2, w):
        """(H, W) w_i alpha m2_i^(alpha/2 - 1): d (w_i m2_i^(alpha/2)) / d m2_i, times 2."""
        return w * self.alpha * m2 ** (self.alpha / 2 - 1)

    def majoriser_weights(self, log_map) -> np.ndarray:
        """(H, W) c_i = weight w_i alpha m2_i^(alpha/2 - 1) at the (H, W, C) log map: the
        prior is bounded above, around that map, by its value plus its gradient step
        plus 1/2 sum_i c_i (|d grad x_i|^2) (alpha < 1 makes it concave in m2), the
        quadratic that iteratively reweighted least squares minimises."""
        dphi, dth, _ = self.differences(log_map)
        m2 = self._magnitude2(dphi, dth)
        return self.weight * self._curvature(m2, _texel_weights(*m2.shape))

    def majoriser_diagonal(self, log_map) -> np.ndarray:
        """(H, W) the diagonal of the majoriser's Hessian (:meth:`majoriser_weights`)
        in each channel of each texel: a texel's value enters its own two
        differences and its left and upper neighbours' ones."""
        c = self.majoriser_weights(log_map)
        _, _, inv_s = self.differences(log_map)
        s2 = inv_s[:, :, 0] ** 2                                        # (H, 1)
        below = np.ones((c.shape[0], 1))
        below[-1] = 0.0                                                 # no d_theta past the last row
        d = c * (s2 + below) + np.roll(c, 1, axis=1) * s2
        d[1:] += c[:-1]
        return d

    def __call__(self, log_map):
        dphi, dth, inv_s = self.differences(log_map)
        H_, W_, _ = dphi.shape
        m2 = self._magnitude2(dphi, dth)                           # (H, W)
        w = _texel_weights(H_, W_)
        val = float((w * m2 ** (self.alpha / 2)).sum())
        c = self._curvature(m2, w)[..., None]                      # d val / d (m2) * 2 / 2
        gphi = c * dphi * inv_s
        gth = c * dth
        g = -gphi + np.roll(gphi, 1, axis=1) - gth
        g[1:] += gth[:-1]
        return self.weight * val, self.weight * g


class LightColourPrior:
    """Not in the paper: a Gaussian on the colour of the light the map sheds,

        -log p(L) = weight * (y_T^2 / sigma_T^2 + y_G^2 / sigma_G^2) / 2,
        (y_T, y_G) = LIGHT_AXES^T log m,

    m (3,) the solid-angle-weighted mean radiance of the map's texels (its
    colour as a white sphere would see it). y_T is its colour temperature
    (log R - log B over sqrt 2: positive warm, negative blue) and y_G its tint
    (green negative, magenta positive), both 0 for white. Daylight, skies and
    incandescent light lie along the temperature axis, hardly ever off it.
    Only the product of the light's colour and the material's is observed;
    with :class:`~mi_dsbrdf.model.priors.ChromaticityPrior` (the material's
    side) this decides the split. ``temperature_sigma``, ``tint_sigma``: the
    spreads (the `grace` probe's orange: y_T 0.51).
    """

    def __init__(self, weight=1.0, temperature_sigma=0.26, tint_sigma=0.05):
        for name, v in (("temperature_sigma", temperature_sigma), ("tint_sigma", tint_sigma)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError("%s must be a finite number > 0, got %r" % (name, v))
        self.weight = float(weight)
        self.precision = 1.0 / np.array([temperature_sigma, tint_sigma], dtype=np.float64) ** 2

    @staticmethod
    def colour(log_map) -> np.ndarray:
        """(3,) log of the solid-angle-weighted mean radiance of an (H, W, 3) log map."""
        x = np.asarray(log_map, dtype=np.float64)
        w = _texel_weights(*x.shape[:2])
        return np.log(np.einsum("hw,hwc->c", w, np.exp(x)))

    def nll_of_colour(self, log_m) -> float:
        """The prior's value at the mean's log colour ``log_m`` (3,)."""
        y = np.asarray(log_m, dtype=np.float64) @ LIGHT_AXES
        return self.weight * float(y @ (self.precision * y)) / 2

    def __call__(self, log_map):
        """(value, gradient (H, W, 3)) of an (H, W, 3) log map."""
        x = np.asarray(log_map, dtype=np.float64)
        w = _texel_weights(*x.shape[:2])
        e = w[..., None] * np.exp(x)
        m = e.sum(axis=(0, 1))
        y = np.log(m) @ LIGHT_AXES
        g_log_m = self.weight * LIGHT_AXES @ (self.precision * y)
        return self.weight * float(y @ (self.precision * y)) / 2, e * (g_log_m / m)
