"""Reflectance priors (paper §4), as negative log densities with gradients, and their learning.

  * :class:`GaussianMixture` — Eq. 6, a Gaussian mixture on the basis
    coefficients psi, fitted by EM (:func:`fit_gmm`), the number of components
    and covariance type chosen by BIC (:func:`select_gmm`).
  * :class:`HuePrior` — Eq. 7-12, a von Mises prior on the angle between the hue
    vectors of every pair of lobes; the concentration kappa_h is fitted by
    maximum likelihood (:func:`fit_hue_concentration`).
  * :class:`ChromaticityPrior` — not in the paper: a kernel density of each
    lobe's log chromaticity over the library, the material's side of the split
    of colour between material and light (its light's side:
    :class:`~mi_dsbrdf.inference.illumination_priors.LightColourPrior`).

All functions take float64 numpy arrays and return float64; ``nll`` methods
return -log p up to the constants stated, ``grad`` methods its gradient.
The illumination priors are in :mod:`mi_dsbrdf.inference.illumination_priors`.
"""
from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
from scipy.optimize import brentq
from scipy.special import i0e, i1e, logsumexp

# --- Gaussian mixture on psi (Eq. 6) -----------------------------------------------


class GaussianMixture:
    """p(psi) = sum_c w_c N(psi; mu_c, Sigma_c).

    weights (C,), means (C, k), covariances (C, k, k): float64 arrays;
    covariances symmetric positive definite.

    Every method takes ``volume``, the fraction of each component's volume term
    -1/2 log det Sigma_c kept: 1 (the default) is the normalised mixture density;
    0 ranks the components by weight and Mahalanobis distance alone (as a MAP
    prior the density rewards tight clusters, which pulls diffuse images to
    glossy materials). Below 1 not a normalised density.
    """

    def __init__(self, weights, means, covariances):
        self.weights = np.asarray(weights, dtype=np.float64).reshape(-1)
        self.means = np.asarray(means, dtype=np.float64)
        self.covariances = np.asarray(covariances, dtype=np.float64)
        C = self.weights.size
        if self.means.ndim != 2 or self.means.shape[0] != C:
            raise ValueError("GMM means must be (%d, k), got %s" % (C, self.means.shape))
        k = self.means.shape[1]
        if self.covariances.shape != (C, k, k):
            raise ValueError("GMM covariances must be (%d, %d, %d), got %s" % (C, k, k, self.covariances.shape))
        if not (np.all(np.isfinite(self.weights)) and np.all(self.weights >= 0)
                and abs(self.weights.sum() - 1) < 1e-6):
            raise ValueError("GMM weights must be non-negative and sum to 1")
        try:
            self._chol = np.linalg.cholesky(self.covariances)
        except np.linalg.LinAlgError:
            raise ValueError("GMM covariances must be positive definite") from None
        self._prec = np.linalg.inv(self.covariances)
        logdet = 2 * np.log(np.diagonal(self._chol, axis1=1, axis2=2)).sum(axis=1)
        self._log_norm = np.log(np.maximum(self.weights, 1e-300)) - 0.5 * (logdet + k * math.log(2 * math.pi))

    @property
    def n_components(self) -> int:
        return self.weights.size

    @property
    def dim(self) -> int:
        return self.means.shape[1]

    def _offsets(self, x):
        """(M, C, k) x - mu_c and Sigma_c^-1 (x - mu_c) for x of shape (k,) or (M, k)."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        diff = x[:, None, :] - self.means[None]                              # (M, C, k)
        return diff, np.einsum("cij,mcj->mci", self._prec, diff)

    def _component_logs(self, x, volume=1.0):
        diff, sol = self._offsets(x)
        log_w = np.log(np.maximum(self.weights, 1e-300))
        norm = log_w + float(volume) * (self._log_norm - log_w)
        return norm[None] - 0.5 * np.einsum("mci,mci->mc", diff, sol), sol

    def mahalanobis(self, psi) -> np.ndarray:
        """(C,) Mahalanobis distance of ``psi`` (k,) to each component's mean, in its
        own standard deviations."""
        diff, sol = self._offsets(np.asarray(psi, dtype=np.float64).reshape(1, -1))
        return np.sqrt(np.einsum("mci,mci->mc", diff, sol)[0])

    def dominant_precision(self, psi, volume=1.0) -> np.ndarray:
        """(k, k) inverse covariance of the component most responsible for ``psi``:
        the Gauss-Newton Hessian of -log p near psi (the reflectance block adds it)."""
        lc, _ = self._component_logs(np.asarray(psi, dtype=np.float64).reshape(1, -1), volume)
        return self._prec[int(np.argmax(lc[0]))]

    def log_density(self, x, volume=1.0) -> np.ndarray:
        """log p(psi) for psi of shape (k,) (returns a float) or (M, k) (returns (M,))."""
        lc, _ = self._component_logs(x, volume)
        out = logsumexp(lc, axis=1)
        return float(out[0]) if np.ndim(x) == 1 else out

    def nll(self, psi, volume=1.0) -> float:
        """-log p(psi) (Eq. 6), exact with its normalisation at ``volume`` 1."""
        return -self.log_density(np.asarray(psi, dtype=np.float64).reshape(-1), volume)

    def grad(self, psi, volume=1.0) -> np.ndarray:
        """d(-log p)/d psi = sum_c resp_c Sigma_c^-1 (psi - mu_c), shape (k,)."""
        lc, sol = self._component_logs(np.asarray(psi, dtype=np.float64).reshape(1, -1), volume)
        resp = np.exp(lc - logsumexp(lc, axis=1, keepdims=True))
        return (resp[:, :, None] * sol).sum(axis=1)[0]

    def n_parameters(self, covariance_type="full") -> int:
        C, k = self.n_components, self.dim
        if covariance_type == "tied":
            return (C - 1) + C * k + k * (k + 1) // 2
        cov = k * (k + 1) // 2 if covariance_type == "full" else k
        return (C - 1) + C * k + C * cov


def fit_gmm(X, n_components, covariance_type="full", seed=0, n_init=5, max_iter=500, reg=1e-3):
    """Fit a Gaussian mixture to rows of ``X`` (M, k) by EM.

    ``covariance_type``: "full", "diag" or "tied" (one full covariance shared by
    every component: the components differ in weight and mean, not in volume).
    k-means++ starts from ``np.random.default_rng(seed)``; the best of
    ``n_init`` runs by log likelihood is returned as (GaussianMixture, loglik).
    ``reg`` times the mean per-dimension variance is added to each covariance
    diagonal, which keeps components of few points well conditioned.
    """
    X = np.asarray(X, dtype=np.float64)
    M, k = X.shape
    if n_components > M:
        raise ValueError("cannot fit %d components to %d points" % (n_components, M))
    rng = np.random.default_rng(seed)
    floor = reg * max(float(X.var(axis=0).mean()), 1e-12)
    best = None
    for _ in range(n_init):
        centres = [X[rng.integers(M)]]
        for _ in range(1, n_components):
            d2 = np.min([((X - c) ** 2).sum(axis=1) for c in centres], axis=0)
            p = d2 / d2.sum() if d2.sum() > 0 else np.full(M, 1 / M)
            centres.append(X[rng.choice(M, p=p)])
        labels = np.argmin([((X - c) ** 2).sum(axis=1) for c in centres], axis=0)
        resp = np.eye(n_components)[labels]
        prev = -np.inf
        for _ in range(max_iter):
            gmm = _m_step(X, resp, covariance_type, floor)
            lc, _ = gmm._component_logs(X)
            ll = float(logsumexp(lc, axis=1).sum())
            resp = np.exp(lc - logsumexp(lc, axis=1, keepdims=True))
            if ll - prev < 1e-8 * abs(ll):
                break
            prev = ll
        if best is None or ll > best[1]:
            best = (gmm, ll)
    return best


def _m_step(X, resp, covariance_type, floor):
    nk = resp.sum(axis=0) + 1e-12
    weights = nk / nk.sum()
    means = (resp.T @ X) / nk[:, None]
    covs = []
    for c in range(resp.shape[1]):
        d = X - means[c]
        cov = (resp[:, c, None] * d).T @ d / nk[c]
        if covariance_type == "diag":
            cov = np.diag(np.diag(cov))
        covs.append(cov + floor * np.eye(X.shape[1]))
    if covariance_type == "tied":                  # the responsibility-weighted pool of the components'
        covs = [sum(n * c for n, c in zip(nk, covs)) / nk.sum()] * resp.shape[1]
    return GaussianMixture(weights, means, np.array(covs))


@dataclasses.dataclass
class GMMSelection:
    gmm: GaussianMixture
    covariance_type: str
    table: list     # [(covariance_type, n_components, loglik, bic), ...]


def select_gmm(X, max_components=5, covariance_types=("full", "diag"), seed=0) -> GMMSelection:
    """Fit 1..max_components components of each covariance type; keep the lowest
    BIC = -2 log L + n_parameters log M."""
    X = np.asarray(X, dtype=np.float64)
    M = X.shape[0]
    table, best = [], None
    for ct in covariance_types:
        for C in range(1, min(max_components, M) + 1):
            gmm, ll = fit_gmm(X, C, ct, seed=seed)
            bic = -2 * ll + gmm.n_parameters(ct) * math.log(M)
            table.append((ct, C, ll, bic))
            if best is None or bic < best[2]:
                best = (gmm, ct, bic)
    return GMMSelection(best[0], best[1], table)


def held_out_nll(X, n_components, covariance_type="full", reg=1e-3, seed=0, n_init=5) -> np.ndarray:
    """(M,) -log p of each row of ``X`` under the mixture fitted to the other rows
    (leave-one-out): how well a structure (components, covariance type, ``reg``)
    predicts a material it has not seen, which is what the prior does at
    inference."""
    X = np.asarray(X, dtype=np.float64)
    return np.array([fit_gmm(np.delete(X, i, axis=0), n_components, covariance_type, seed=seed, n_init=n_init,
                             reg=reg)[0].nll(X[i]) for i in range(X.shape[0])])


# --- von Mises hue prior (Eq. 7-12) ---------------------------------------------------

#: Saturation |c - 1/3| below which a hue vector is treated as undefined (grey).
HUE_EPS = 1e-3


def hue_vectors(chromaticity) -> np.ndarray:
    """(R, 3) hue vectors: chromaticity minus grey, i.e. projected onto the plane
    orthogonal to (1, 1, 1) (chromaticities sum to one)."""
    return np.asarray(chromaticity, dtype=np.float64) - 1.0 / 3.0


def hue_cosines(chromaticity) -> np.ndarray:
    """cos of the angle between the hue vectors of every pair of lobes (r < s),
    softened by HUE_EPS so that a grey lobe gives 0 (no preference) and a finite gradient."""
    h = hue_vectors(chromaticity)
    n = np.sqrt((h * h).sum(axis=1) + HUE_EPS ** 2)
    return np.array([h[r] @ h[s] / (n[r] * n[s]) for r, s in itertools.combinations(range(len(h)), 2)])


class HuePrior:
    """p(c) prop. to prod_{r<s} exp(kappa_h cos(angle(h_r, h_s))) / (2 pi I0(kappa_h))."""

    def __init__(self, kappa_h):
        self.kappa_h = float(kappa_h)
        if not (math.isfinite(self.kappa_h) and self.kappa_h >= 0):
            raise ValueError("hue concentration kappa_h must be finite and >= 0, got %r" % kappa_h)

    def nll(self, chromaticity) -> float:
        cos = hue_cosines(chromaticity)
        log_norm = math.log(2 * math.pi) + math.log(i0e(self.kappa_h)) + self.kappa_h
        return float(-self.kappa_h * cos.sum() + cos.size * log_norm)

    def grad(self, chromaticity) -> np.ndarray:
        """d(-log p)/d chromaticity, shape (R, 3)."""
        h = hue_vectors(chromaticity)
        R = h.shape[0]
        n = np.sqrt((h * h).sum(axis=1) + HUE_EPS ** 2)
        g = np.zeros_like(h)
        for r, s in itertools.combinations(range(R), 2):
            dot = h[r] @ h[s]
            # d cos / d h_r = h_s/(n_r n_s) - dot h_r / (n_r^3 n_s)
            g[r] += h[s] / (n[r] * n[s]) - dot * h[r] / (n[r] ** 3 * n[s])
            g[s] += h[r] / (n[r] * n[s]) - dot * h[s] / (n[s] ** 3 * n[r])
        return -self.kappa_h * g


def fit_hue_concentration(chromaticities, min_saturation=0.02) -> tuple:
    """Maximum-likelihood kappa_h from (M, R, 3) lobe chromaticities.

    Pairs of lobes that are both saturated (|c - 1/3| >= ``min_saturation``)
    give angles theta_i; the ML estimate solves A(kappa) = I1/I0(kappa) =
    mean cos theta_i. Returns (kappa_h, number of pairs used).
    """
    cos = []
    for c in np.asarray(chromaticities, dtype=np.float64):
        h = hue_vectors(c)
        n = np.linalg.norm(h, axis=1)
        for r, s in itertools.combinations(range(len(h)), 2):
            if n[r] >= min_saturation and n[s] >= min_saturation:
                cos.append(h[r] @ h[s] / (n[r] * n[s]))
    if not cos:
        return 0.0, 0
    rbar = float(np.mean(cos))
    if rbar <= 0:
        return 0.0, len(cos)
    rbar = min(rbar, 1 - 1e-9)
    kappa = brentq(lambda k: i1e(k) / i0e(k) - rbar, 1e-9, 1e9)
    return float(kappa), len(cos)


# --- chromaticity prior: how coloured each lobe of a real material is ---------------

#: (3, 2) orthonormal basis of the plane orthogonal to (1, 1, 1): the log
#: chromaticity's coordinates there ignore its (arbitrary) overall level
LOG_CHROMA_BASIS = np.array([[1.0, -1.0, 0.0], [1.0, 1.0, -2.0]]).T / np.array([math.sqrt(2.0), math.sqrt(6.0)])
#: a library lobe with a channel below this carries no colour worth learning (a
#: lobe its fit left without energy, e.g. pink-fabric's second at (0, 1, 0))
CHROMA_DEGENERATE = 0.01
#: spread (log chromaticity) of the chromaticity prior's broad kernel: at a distance
#: of 1 from grey lie chromaticities such as (0.18, 0.18, 0.63) and (0.58, 0.14, 0.28)
BROAD = 1.0


def log_chroma_coords(chromaticity) -> np.ndarray:
    """(..., 2) coordinates of log c in the plane orthogonal to (1, 1, 1), from
    chromaticities (..., 3) (floored at 1e-6)."""
    return np.log(np.maximum(np.asarray(chromaticity, dtype=np.float64), 1e-6)) @ LOG_CHROMA_BASIS


class ChromaticityPrior:
    """p(c) = prod_r p_r(y_r), y_r = :func:`log_chroma_coords` (c_r): a kernel
    density of each lobe's log chromaticity over the library's materials, plus
    one broad kernel for materials unlike any of them.

    Under unknown light only the product of the light's colour and the
    material's is observed; this prior is what the model knows about the
    material's part. Learned per lobe because lobes differ (shipped library:
    the broad lobe's median distance from grey is 0.54 in log chromaticity, the
    sharper lobes' 0.13 and 0.11 — dielectric highlights are the light's
    colour), with scipy's Gaussian kernel density and its bandwidth (Scott's
    rule); the gradient is written here. The broad kernel, N(0, BROAD^2 I) with
    the weight of one library material, keeps the tails heavy: with Gaussian
    kernels alone a lobe far from every library one costs tens of nats and
    drags the whole split with it. ``library_chroma`` (M, R, 3); lobes with a channel below
    CHROMA_DEGENERATE are left out of their lobe's density.
    """

    def __init__(self, library_chroma):
        from scipy.stats import gaussian_kde     # scipy.stats is slow to import; only a model needs it
        c = np.asarray(library_chroma, dtype=np.float64)
        if c.ndim != 3 or c.shape[2] != 3:
            raise ValueError("library chromaticities must be (M, R, 3), got %s" % (c.shape,))
        self.lobes = []
        for r in range(c.shape[1]):
            y = log_chroma_coords(c[c[:, r].min(axis=1) >= CHROMA_DEGENERATE, r])
            if len(y) < 3:
                raise ValueError("lobe %d has %d usable library chromaticities; at least 3 are needed" % (r, len(y)))
            cov = gaussian_kde(y.T).covariance
            # kernels: (centres (n, 2), precision (2, 2), log weight + log normaliser)
            log_w = -math.log(len(y) + 1)
            self.lobes.append([(y, np.linalg.inv(cov), log_w - 0.5 * math.log(np.linalg.det(2 * math.pi * cov))),
                               (np.zeros((1, 2)), np.eye(2) / BROAD ** 2, log_w - math.log(2 * math.pi * BROAD ** 2))])

    def _per_lobe(self, chromaticity):
        y = log_chroma_coords(chromaticity)                            # (R, 2)
        if y.shape[0] != len(self.lobes):
            raise ValueError("the prior has %d lobes, got %d chromaticities" % (len(self.lobes), y.shape[0]))
        out = []
        for r, kernels in enumerate(self.lobes):
            d = [y[r] - centres for centres, _, _ in kernels]
            e = np.concatenate([ln - 0.5 * np.einsum("mi,ij,mj->m", dk, P, dk)
                                for dk, (_, P, ln) in zip(d, kernels)])
            resp = np.exp(e - logsumexp(e))
            g = np.concatenate([dk @ P for dk, (_, P, _) in zip(d, kernels)])
            out.append((-float(logsumexp(e)), resp @ g))               # -log p_r, d(-log p_r)/dy_r
        return out

    def nll(self, chromaticity) -> float:
        """-log p(c) of (R, 3) chromaticities (normalised density in y)."""
        return float(sum(v for v, _ in self._per_lobe(chromaticity)))

    def grad(self, chromaticity) -> np.ndarray:
        """d(-log p)/d chromaticity, shape (R, 3)."""
        c = np.maximum(np.asarray(chromaticity, dtype=np.float64), 1e-6)
        gy = np.stack([g for _, g in self._per_lobe(c)])              # (R, 2)
        return (gy @ LOG_CHROMA_BASIS.T) / c
