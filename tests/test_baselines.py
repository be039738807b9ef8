"""Lambert + Cook-Torrance, the comparison model of the reports."""
import numpy as np
import pytest

from mi_dsbrdf.model import samples
from mi_dsbrdf.model.baselines import cook_torrance, fit_cook_torrance


@pytest.mark.slow
def test_cook_torrance_fit_recovers_a_known_one_lobe_model():
    truth = np.array([np.log(0.3), np.log(0.2), np.log(0.1),        # k_d
                      np.log(0.05), np.log(0.05), np.log(0.05),     # k_s
                      np.log(0.15), -1.0, -1.0, -1.0])              # m, logit F0
    s = samples.samples_from_function(lambda th, td, pd: cook_torrance(truth, th, td, pd, 1),
                                      samples.grid_subset(theta_d_step=6, phi_d_step=30))
    params, err = fit_cook_torrance(s, 1)
    assert err < 1e-4
    ref = cook_torrance(truth, s.theta_h, s.theta_d, s.phi_d, 1)
    got = cook_torrance(params, s.theta_h, s.theta_d, s.phi_d, 1)
    np.testing.assert_allclose(got, ref, rtol=1e-2, atol=1e-4)


def test_cook_torrance_is_finite_for_extreme_parameters():
    th, td, pd = np.array([0.0, 0.7, 1.5]), np.array([0.0, 0.5, 1.4]), np.array([0.0, 1.0, 3.0])
    for p in (np.full(10, 800.0), np.full(10, -800.0), np.zeros(24)):
        v = cook_torrance(p, th, td, pd, len(p) // 7)
        assert np.all(np.isfinite(v)) and np.all(v >= 0)
