"""Reflectance priors: Gaussian mixture on psi (Eq. 6), hue prior (Eq. 7-12) and
the chromaticity prior (ours: the material's side of the colour split)."""
import math

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from mi_dsbrdf.model.priors import (BROAD, ChromaticityPrior, GaussianMixture, HuePrior, fit_gmm,
                                    fit_hue_concentration, held_out_nll, hue_cosines, log_chroma_coords, select_gmm)


def three_clusters(seed=0):
    rng = np.random.default_rng(seed)
    centres = np.array([[-4.0, 0, 0], [0, 4.0, 0], [4.0, 0, 1.0]])
    return np.concatenate([c + rng.normal(0, 0.5, (60, 3)) for c in centres])


def random_gmm(k=4, C=3, seed=1):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(C, k, k))
    return GaussianMixture(rng.dirichlet(np.ones(C)), rng.normal(0, 2, (C, k)),
                           A @ A.transpose(0, 2, 1) + 0.5 * np.eye(k))


def test_gmm_density_matches_scipy():
    g = random_gmm()
    x = np.random.default_rng(2).normal(size=(20, 4))
    expect = np.log(sum(w * multivariate_normal(m, c).pdf(x) for w, m, c in zip(g.weights, g.means, g.covariances)))
    np.testing.assert_allclose(g.log_density(x), expect, rtol=1e-10)
    assert g.nll(x[0]) == pytest.approx(-expect[0])


def test_gmm_gradient_matches_finite_differences_and_is_finite_far_away():
    g = random_gmm()
    for x in (np.array([0.3, -0.2, 1.0, 0.5]), np.array([40.0, -30.0, 25.0, 60.0])):
        grad = g.grad(x)
        assert np.all(np.isfinite(grad)) and np.isfinite(g.nll(x))
        h = 1e-6 * max(1.0, np.abs(x).max())
        fd = np.array([(g.nll(x + h * e) - g.nll(x - h * e)) / (2 * h) for e in np.eye(4)])
        np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-6)



def test_gmm_without_volume_terms_does_not_favour_the_tight_component():
    """With its volume terms the density at a tight component's centre is far above
    a broad one's; without them equal-weight centres score alike, and the gradient
    and the dominant precision are those of the changed function."""
    g = GaussianMixture([0.5, 0.5], [[0.0, 0.0], [1.0, 0.0]], [np.eye(2) * 1e-6, np.eye(2)])
    tight, broad = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    assert g.nll(broad) - g.nll(tight) > 8
    assert abs(g.nll(broad, volume=False) - g.nll(tight, volume=False)) < 0.5
    x, h = np.array([0.3, 0.2]), 1e-7
    fd = np.array([(g.nll(x + h * e, False) - g.nll(x - h * e, False)) / (2 * h) for e in np.eye(2)])
    np.testing.assert_allclose(g.grad(x, volume=False), fd, rtol=1e-5)
    # just off the tight centre it still dominates the density, the broad one the ranking
    near = np.array([0.005, 0.0])
    np.testing.assert_allclose(g.dominant_precision(near), np.eye(2) * 1e6)
    np.testing.assert_allclose(g.dominant_precision(near, volume=False), np.eye(2))


def test_bic_finds_three_clusters_and_em_is_seeded():
    X = three_clusters()
    sel = select_gmm(X, max_components=5)
    assert sel.gmm.n_components == 3
    means = sel.gmm.means[np.argsort(sel.gmm.means[:, 0])]
    np.testing.assert_allclose(means[:, :2], [[-4, 0], [0, 4], [4, 0]], atol=0.2)
    a, _ = fit_gmm(X, 3, seed=7)
    b, _ = fit_gmm(X, 3, seed=7)
    np.testing.assert_array_equal(a.means, b.means)


def test_tied_covariance_is_shared_and_finds_the_clusters():
    """A tied mixture: one covariance for every component (so equal volumes),
    the pooled within-cluster spread, and fewer parameters than a full one."""
    rng = np.random.default_rng(3)
    X = np.concatenate([rng.normal(0, 0.2, (80, 2)), rng.normal(0, 2.0, (80, 2)) + [10, 0]])
    full, _ = fit_gmm(X, 2, "full", seed=0)
    tied, _ = fit_gmm(X, 2, "tied", seed=0)
    np.testing.assert_array_equal(tied.covariances[0], tied.covariances[1])
    np.testing.assert_allclose(np.sort(tied.means[:, 0]), [0, 10], atol=0.5)
    assert np.linalg.det(full.covariances).min() < 0.1 * np.linalg.det(full.covariances).max()
    assert tied.n_parameters("tied") == 1 + 2 * 2 + 3 < full.n_parameters("full")

def test_held_out_density_prefers_the_true_clusters():
    """Leave-one-out -log p (:func:`held_out_nll`) is lowest for
    the three clusters the data has."""
    X = three_clusters()[::3]                       # 60 points, 20 per cluster
    score = {c: held_out_nll(X, c, n_init=2).mean() for c in (1, 2, 3)}
    assert score[3] < score[2] < score[1]


def test_gmm_rejects_bad_parameters():
    with pytest.raises(ValueError, match="positive definite"):
        GaussianMixture([1.0], [[0.0, 0.0]], [[[1.0, 2.0], [2.0, 1.0]]])
    with pytest.raises(ValueError, match="sum to 1"):
        GaussianMixture([0.5], [[0.0]], [[[1.0]]])


def test_hue_prior_gradient_matches_finite_differences_including_grey_lobes():
    p = HuePrior(2.5)
    for c in (np.array([[0.5, 0.3, 0.2], [0.2, 0.5, 0.3], [0.34, 0.33, 0.33]]),
              np.full((3, 3), 1 / 3),
              np.array([[0.9, 0.05, 0.05], [0.6, 0.2, 0.2]])):
        g = p.grad(c)
        assert np.all(np.isfinite(g))
        h = 1e-7
        fd = np.zeros_like(c)
        for idx in np.ndindex(c.shape):
            e = np.zeros_like(c)
            e[idx] = h
            fd[idx] = (p.nll(c + e) - p.nll(c - e)) / (2 * h)
        np.testing.assert_allclose(g, fd, rtol=1e-4, atol=1e-5)


def test_hue_prior_prefers_aligned_hues_and_is_normalised():
    p = HuePrior(3.0)
    same = np.array([[0.5, 0.3, 0.2], [0.45, 0.32, 0.23]])
    opposite = np.array([[0.5, 0.3, 0.2], [0.2, 0.35, 0.45]])
    assert p.nll(same) < p.nll(opposite)
    # one pair: exp(-nll) integrates to one over the angle
    th = np.linspace(-np.pi, np.pi, 20001)
    dens = np.exp(3.0 * np.cos(th)) / (2 * np.pi * np.i0(3.0))
    assert np.trapezoid(dens, th) == pytest.approx(1.0, rel=1e-6)
    assert math.exp(-p.nll(same)) == pytest.approx(np.exp(3.0 * hue_cosines(same)[0]) / (2 * np.pi * np.i0(3.0)),
                                                   rel=1e-6)


def test_hue_concentration_maximum_likelihood():
    rng = np.random.default_rng(4)
    kappa = 4.0
    chroma = []
    for a in rng.vonmises(0, kappa, 4000):
        base = rng.uniform(0, 2 * np.pi)
        u, v = np.array([1, -1, 0]) / np.sqrt(2), np.array([1, 1, -2]) / np.sqrt(6)
        hue = [0.1 * (np.cos(t) * u + np.sin(t) * v) for t in (base, base + a)]
        chroma.append([1 / 3 + h for h in hue])
    k, n = fit_hue_concentration(np.array(chroma))
    assert n == 4000 and k == pytest.approx(kappa, rel=0.08)
    with pytest.raises(ValueError, match="kappa_h"):
        HuePrior(float("nan"))


def library_of_lobes(seed=5, m=80):
    """(m, 2, 3) chromaticities: a broad lobe of many colours, a sharp lobe near grey,
    and one degenerate sharp lobe (a lobe without energy, (0, 1, 0))."""
    rng = np.random.default_rng(seed)
    broad = rng.dirichlet([4, 4, 4], m)
    sharp = rng.dirichlet([300, 300, 300], m)
    sharp[0] = [0.0, 1.0, 0.0]
    return np.stack([broad, sharp], axis=1)


def test_chromaticity_prior_learns_each_lobe_and_its_gradient_is_exact():
    p = ChromaticityPrior(library_of_lobes())
    grey, tinted = np.full((2, 3), 1 / 3), np.tile([0.45, 0.32, 0.23], (2, 1))
    assert p.nll(grey) < p.nll(tinted)
    # a tint costs more on the sharp lobe (near grey in the library) than on the broad one
    per_lobe = [v for v, _ in p._per_lobe(tinted)]
    assert per_lobe[1] - p._per_lobe(grey)[1][0] > per_lobe[0] - p._per_lobe(grey)[0][0] + 1.0
    c = np.array([[0.5, 0.3, 0.2], [0.3, 0.33, 0.37]])
    g, h, fd = p.grad(c), 1e-7, np.zeros_like(c)
    for idx in np.ndindex(c.shape):
        e = np.zeros_like(c)
        e[idx] = h
        fd[idx] = (p.nll(c + e) - p.nll(c - e)) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=1e-4, atol=1e-5)
    # the degenerate lobe is left out: it would have widened the sharp lobe's kernels
    assert len(p.lobes[1][0][0]) == 79 and len(p.lobes[0][0][0]) == 80
    with pytest.raises(ValueError, match="lobes"):
        p.nll(np.full((3, 3), 1 / 3))
    with pytest.raises(ValueError, match="M, R, 3"):
        ChromaticityPrior(np.ones((5, 3)))


def test_chromaticity_prior_has_heavy_tails():
    """Far from every library lobe the broad kernel takes over: the cost grows like
    |y|^2 / (2 BROAD^2), not with the library kernels' curvature."""
    p = ChromaticityPrior(library_of_lobes())
    far = np.tile([0.02, 0.08, 0.9], (2, 1))
    y = log_chroma_coords(far)[1]
    v, gy = p._per_lobe(far)[1]
    assert np.isfinite(v) and v < float(y @ y) / (2 * BROAD ** 2) + np.log(81 * 2 * np.pi * BROAD ** 2) + 1e-9
    np.testing.assert_allclose(gy, y / BROAD ** 2, rtol=1e-3)


def test_mahalanobis_is_each_component_s_distance_in_its_own_sigmas():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(3, 3))
    full = A @ A.T + 0.5 * np.eye(3)                          # a full covariance beside a diagonal one
    gmm = GaussianMixture([0.4, 0.6], [[0.0, 0.0, 0.0], [1.0, -2.0, 0.5]], [np.diag([4.0, 1.0, 0.25]), full])
    psi = np.array([2.0, 1.0, -0.5])
    d = gmm.mahalanobis(psi)
    np.testing.assert_allclose(d[0], np.sqrt(1.0 + 1.0 + 1.0), rtol=1e-12)
    diff = psi - gmm.means[1]
    np.testing.assert_allclose(d[1], np.sqrt(diff @ np.linalg.solve(full, diff)), rtol=1e-12)
    # with no volume terms, the density ranks components by weight and this distance alone
    np.testing.assert_allclose(gmm.log_density(psi, volume=0.0),
                               np.log(np.sum(gmm.weights * np.exp(-0.5 * d ** 2))), rtol=1e-12)
