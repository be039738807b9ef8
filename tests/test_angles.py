import numpy as np
import mitsuba as mi

from mi_dsbrdf.brdf.angles import cos_half_diff, fold_phi_d, from_half_diff, half_diff, log_cos_h


def random_angles(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, np.pi / 2, n), rng.uniform(0, np.pi / 2, n), rng.uniform(-np.pi, np.pi, n)


def test_round_trip_and_definitions():
    th, td, pd = random_angles(2000)
    wi, wo = from_half_diff(th, td, pd)
    th2, ph2, td2, pd2 = half_diff(wi, wo)
    np.testing.assert_allclose(th2, th, atol=1e-7)
    np.testing.assert_allclose(td2, td, atol=1e-7)
    ok = td > 1e-3  # phi_d is undefined at theta_d = 0
    np.testing.assert_allclose(np.cos(pd2[ok] - pd[ok]), 1.0, atol=1e-9)
    cos_h, cos_d, sin2_h = cos_half_diff(wi, wo)
    np.testing.assert_allclose(cos_d, np.cos(td), atol=1e-12)   # theta_d = angle(wi, h)
    np.testing.assert_allclose(sin2_h, np.sin(th) ** 2, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(np.stack(wi), axis=0), 1, atol=1e-12)


def test_log_cos_theta_h_precise_near_peak_and_finite_at_90():
    th = np.array([0.0, 1e-6, 1e-3, 0.3, 1.2, np.pi / 2])
    wi, wo = from_half_diff(th, np.full(6, 0.2), np.zeros(6))
    cos_h, _, sin2_h = cos_half_diff(wi, wo)
    got = log_cos_h(cos_h, sin2_h)
    ref = np.where(th < 1, 0.5 * np.log1p(-np.sin(np.minimum(th, 1)) ** 2), np.log(np.maximum(np.cos(th), 1e-30)))
    np.testing.assert_allclose(got[:5], ref[:5], rtol=1e-9, atol=1e-18)
    assert np.isfinite(got[5]) and got[5] <= np.log(1e-15)


def test_drjit_matches_numpy():
    th, td, pd = random_angles(500, seed=1)
    wi, wo = from_half_diff(th, td, pd)
    ref = half_diff(wi, wo)
    got = half_diff(tuple(mi.Float(c) for c in wi), tuple(mi.Float(c) for c in wo))
    for r, g in zip(ref, got):
        d = np.angle(np.exp(1j * (np.array(g) - r)))  # wrap-safe difference
        assert np.max(np.abs(d[td > 1e-2])) < 1e-3


def test_fold_phi_d():
    p = np.array([-np.pi + 1e-9, -0.5, 0.0, 0.5, np.pi - 1e-9, np.pi])
    f = fold_phi_d(p)
    assert np.all((f >= 0) & (f < np.pi))
    np.testing.assert_allclose(np.sin(2 * f), np.sin(2 * p), atol=1e-8)
