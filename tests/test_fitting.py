"""Fitting DSBRDFs to measurements on the MERL grid (Eq. 5)."""
import math

import numpy as np
import pytest

from mi_dsbrdf import Material
from mi_dsbrdf.model import fitting, samples
from mi_dsbrdf.brdf.measured import MeasuredBRDF, eval_nbrdf, load_nbrdf_weights
from mi_dsbrdf.evaluation.metrics import log_rmse

# a coarse slice of the grid keeps each fit to a few seconds
SUBSET = dict(theta_d_step=6, phi_d_step=30)


def known_material():
    th = np.linspace(0, 1, 6)
    return Material(log_kappa=[np.log(0.2) - 0.3 * th, np.log(1.5) + 0.5 * th, np.log(6.0) + 0.2 * th],
                    log_gamma=[np.full(6, np.log(1.5)), np.log(40.0) - 0.4 * th, np.log(3000.0) - 1.0 * th],
                    chromaticity=[[0.5, 0.3, 0.2], [0.3, 0.35, 0.35], [1 / 3, 1 / 3, 1 / 3]], name="known")


def test_log_rmse_is_eq5():
    rng = np.random.default_rng(1)
    a, b, c = rng.uniform(0, 5, (50, 3)), rng.uniform(0, 5, (50, 3)), rng.uniform(0.1, 1, 50)
    expect = math.sqrt(np.mean((np.log(1 + a * c[:, None]) - np.log(1 + b * c[:, None])) ** 2))
    assert log_rmse(a, b, c) == pytest.approx(expect, rel=1e-12)
    assert log_rmse(a, a, c) == 0.0


def test_grid_subset_keeps_directions_above_horizon():
    ih, jd, kp = samples.grid_subset(**SUBSET)
    s = samples.samples_from_function(lambda th, td, pd: np.ones((th.size, 3)), (ih, jd, kp))
    assert np.all(s.cos_i > 0) and len(s) == ih.size
    assert s.theta_h.min() == 0.0 and s.theta_d.max() > math.radians(80)


def test_jacobian_matches_finite_differences():
    s = samples.samples_from_function(lambda th, td, pd: known_material().eval(th, td),
                                      samples.grid_subset(theta_d_step=15, phi_d_step=60))
    prob = fitting._Problem(s, 3)
    rng = np.random.default_rng(0)
    ctrl = np.stack([np.log([[0.3], [2.0], [5.0]]) + rng.normal(0, .1, (3, 6)),
                     np.log([[2.0], [30.0], [500.0]]) + rng.normal(0, .1, (3, 6))], axis=1)
    z = rng.normal(0, .5, (3, 2))
    _, Jc, Jz = prob.residuals(ctrl, z, jac=True)
    h = 1e-6
    for idx in [(0, 0, 0), (1, 1, 3), (2, 1, 5), (2, 0, 2)]:
        e = np.zeros_like(ctrl)
        e[idx] = h
        fd = (prob.residuals(ctrl + e, z)[0] - prob.residuals(ctrl - e, z)[0]) / (2 * h)
        np.testing.assert_allclose(Jc[:, np.ravel_multi_index(idx, ctrl.shape)], fd, rtol=1e-4, atol=1e-9)
    for idx in [(0, 0), (2, 1)]:
        e = np.zeros_like(z)
        e[idx] = h
        fd = (prob.residuals(ctrl, z + e)[0] - prob.residuals(ctrl, z - e)[0]) / (2 * h)
        np.testing.assert_allclose(Jz[:, np.ravel_multi_index(idx, z.shape)], fd, rtol=1e-4, atol=1e-9)


def test_fit_recovers_known_dsbrdf_on_merl_grid():
    truth = known_material()
    table = MeasuredBRDF.from_function(lambda th, td, pd: truth.eval(th, td), name="known")
    s = samples.samples_from_table(table, samples.grid_subset(**SUBSET))
    fit = fitting.fit_full(s)
    assert fit.error < 2e-3, fit.error
    # the lobes come back in specularity order and with the true parameters
    k_fit, g_fit = fit.material.curves(np.linspace(0, math.radians(75), 16))
    k_true, g_true = truth.curves(np.linspace(0, math.radians(75), 16))
    np.testing.assert_allclose(np.log(k_fit), np.log(k_true), atol=0.05)
    np.testing.assert_allclose(np.log(g_fit[:, 1:]), np.log(g_true[:, 1:]), atol=0.1)
    np.testing.assert_allclose(fit.material.chromaticity[:2], truth.chromaticity[:2], atol=0.01)
    # and the BRDF everywhere on held-out grid cells
    held = samples.samples_from_table(table, samples.grid_subset(theta_d_step=7, phi_d_step=17))
    assert log_rmse(fit.material.eval(held.theta_h, held.theta_d), held.values, held.cos_i) < 3e-3


def test_basis_fit_recovers_psi_and_chromaticity():
    from mi_dsbrdf.brdf.curves import CurveBasis
    rng = np.random.default_rng(3)
    mean = known_material()
    basis = CurveBasis(np.stack([mean.log_kappa, mean.log_gamma], axis=1), rng.normal(0, 0.15, (4, 3, 2, 6)))
    psi = np.array([0.8, -0.5, 0.3, 0.2])
    chroma = np.array([[0.6, 0.3, 0.1], [0.2, 0.3, 0.5], [0.3, 0.3, 0.4]])
    truth = Material.from_basis(basis, psi, chroma)
    s = samples.samples_from_function(lambda th, td, pd: truth.eval(th, td), samples.grid_subset(**SUBSET))
    fit = fitting.fit_basis(s, basis)
    assert fit.error < 1e-4
    np.testing.assert_allclose(fit.variables, psi, atol=0.02)
    np.testing.assert_allclose(fit.material.chromaticity, chroma, atol=0.01)


def test_fits_of_stiff_merl_materials_converge(nbrdf_file):
    """A near-mirror metal and a near-Lambertian fabric: finite, ordered, accurate."""
    for name, bound in (("chrome", 0.12), ("white-fabric", 0.02)):
        w = load_nbrdf_weights(nbrdf_file, name)
        s = samples.samples_from_function(lambda th, td, pd: eval_nbrdf(w, th, td, pd),
                                          samples.grid_subset(**SUBSET), name)
        fit = fitting.fit_full(s)
        m = fit.material
        assert np.isfinite(fit.error) and fit.error < bound, (name, fit.error)
        assert np.all(np.isfinite(m.log_kappa)) and np.all(np.isfinite(m.log_gamma))
        assert np.all(m.log_gamma >= fitting.LOG_GAMMA_BOUNDS[0] - 1e-9)     # no lobe collapses to gamma = 0
        assert np.all(np.diff(m.log_gamma.mean(axis=1)) >= 0)                 # specularity order


def test_scale_invariant_error_finds_the_scale_and_ignores_it():
    from mi_dsbrdf.evaluation.metrics import log_rmse, log_rmse_scale_invariant
    rng = np.random.default_rng(0)
    truth = np.exp(rng.normal(0, 1.5, (500, 3)))
    cos_i = rng.uniform(0.1, 1.0, 500)
    err, s = log_rmse_scale_invariant(truth / 7.0, truth, cos_i)
    assert err < 1e-6 and abs(s - 7.0) < 1e-4
    noisy = truth * np.exp(rng.normal(0, 0.2, truth.shape))
    err, s = log_rmse_scale_invariant(noisy * 0.01, truth, cos_i)
    assert err <= log_rmse(noisy, truth, cos_i) + 1e-9 and err < log_rmse(noisy * 0.01, truth, cos_i)
