"""Functional PCA of the log curves (Eq. 2-3)."""
import numpy as np
import pytest

from mi_dsbrdf.brdf.curves import spline_matrix
from mi_dsbrdf.model.fpca import fpca, gram_matrix, l2_inner


def training_curves(M=30, seed=0):
    rng = np.random.default_rng(seed)
    latent = rng.normal(size=(M, 4))
    mix = rng.normal(size=(4, 3, 2, 6))
    return np.tensordot(latent, mix, axes=1) + rng.normal(0, 1e-3, (M, 3, 2, 6)) + 2.0


def test_gram_matrix_is_the_l2_inner_product():
    th = np.linspace(0, np.pi / 2, 200001)
    B = spline_matrix(th)
    dx = th[1] - th[0]
    w = np.full(th.size, dx)
    w[[0, -1]] = dx / 2                                            # trapezoid rule
    np.testing.assert_allclose(gram_matrix(), B.T @ (B * w[:, None]), atol=1e-8)


def test_fpca_reconstructs_training_curves_and_bases_are_orthonormal():
    X = training_curves()
    p = fpca(X)
    # all components: exact reconstruction of every training material
    rec = p.mean + np.tensordot(p.scores, p.bases, axes=1)
    np.testing.assert_allclose(rec, X, atol=1e-10)
    # the bases are orthonormal functions of theta_d
    K = p.bases.shape[0]
    gram = np.array([[l2_inner(p.bases[i], p.bases[j]) for j in range(K)] for i in range(K)])
    np.testing.assert_allclose(gram, np.eye(K), atol=1e-9)
    # four latent factors: four bases carry (almost) all the variance, in decreasing order
    assert np.all(np.diff(p.variance) <= 1e-12)
    assert p.explained[3] > 0.9999
    b = p.basis(4)
    rec4 = np.array([b.control_values(s) for s in p.scores[:, :4]])
    assert np.abs(rec4 - X).max() < 0.02
    with pytest.raises(ValueError, match="k must be"):
        p.basis(K + 1)


def test_fpca_is_deterministic_and_checks_shapes():
    X = training_curves()
    a, b = fpca(X), fpca(X.copy())
    np.testing.assert_array_equal(a.bases, b.bases)
    with pytest.raises(ValueError, match="shape"):
        fpca(np.zeros((5, 3, 6)))
    with pytest.raises(ValueError, match="at least 2"):
        fpca(X[:1])
