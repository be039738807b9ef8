"""The one Levenberg-Marquardt core (mi_dsbrdf.lm) against scipy's least_squares."""
import numpy as np
import pytest
from scipy.optimize import least_squares

from mi_dsbrdf.brdf.measured import eval_nbrdf, load_nbrdf_weights
from mi_dsbrdf.lm import levenberg_marquardt
from mi_dsbrdf.model import fit_problem
from mi_dsbrdf.model.model_file import shipped_model
from mi_dsbrdf.model.samples import grid_subset, samples_from_function


def least_squares_pair(fun):
    """(linearise, cost) of 1/2 |r(x)|^2 for ``fun(x) -> (r, J)``."""
    def linearise(x):
        r, J = fun(x)
        return J.T @ r, J.T @ J
    return linearise, lambda x: 0.5 * float(fun(x)[0] @ fun(x)[0])


def rosenbrock(x):
    return np.array([10 * (x[1] - x[0] ** 2), 1 - x[0]]), np.array([[-20 * x[0], 10.0], [-1.0, 0.0]])


def test_reaches_the_minimum_of_rosenbrock_and_respects_bounds():
    res = levenberg_marquardt(*least_squares_pair(rosenbrock), np.array([-1.2, 1.0]), max_iter=200, tol=1e-14)
    assert res.cost < 1e-12
    np.testing.assert_allclose(res.x, [1.0, 1.0], atol=1e-5)
    # a box that excludes the minimum: the result stays inside and comes within 1e-4 of scipy's
    # cost in the box (projected steps crawl along an active bound, hence not to the last digit)
    box = lambda x, step: np.clip(x + step, -2.0, 0.5)   # noqa: E731
    res = levenberg_marquardt(*least_squares_pair(rosenbrock), np.array([-1.2, 0.0]), propose=box, max_iter=200,
                              tol=1e-14)
    ref = least_squares(lambda x: rosenbrock(x)[0], [-1.2, 0.0], jac=lambda x: rosenbrock(x)[1],
                        bounds=([-2, -2], [0.5, 0.5]))
    assert np.all(res.x <= 0.5) and res.cost <= ref.cost * (1 + 1e-4)


def test_a_singular_hessian_is_a_rejected_step_not_an_error():
    calls = []

    def linearise(x):
        calls.append(1)
        return np.ones(2), np.zeros((2, 2))     # with floor 0 every damped system is singular
    from mi_dsbrdf.lm import Damping
    res = levenberg_marquardt(linearise, lambda x: float(x @ x), np.ones(2), damping=Damping(floor=0.0))
    assert res.converged and res.iterations == 1 and np.array_equal(res.x, np.ones(2)) and len(calls) == 1


@pytest.mark.slow
def test_reaches_the_cost_of_scipy_least_squares_on_a_merl_fit(nbrdf_file):
    """The basis fit of a MERL material (16 variables): the same residuals minimised
    by this core and by scipy's trust-region least_squares end at the same cost."""
    basis = shipped_model().basis
    w = load_nbrdf_weights(nbrdf_file, "blue-acrylic")
    s = samples_from_function(lambda th, td, pd: eval_nbrdf(w, th, td, pd), grid_subset(theta_d_step=6, phi_d_step=30))
    problem = fit_problem.FitProblem(s, basis.n_lobes, basis.knots)
    k, R = basis.n_bases, basis.n_lobes
    A, b = basis.bases.reshape(k, -1).T, basis.mean.reshape(-1)

    def fun(x):
        r, Jc, Jz = problem.residuals((A @ x[:k] + b).reshape(R, 2, -1), x[k:].reshape(R, 2), jac=True)
        return r, np.hstack([Jc @ A, Jz])
    x0 = np.zeros(k + 2 * R)
    ours = levenberg_marquardt(*least_squares_pair(fun), x0, max_iter=300, tol=1e-12)
    ref = least_squares(lambda x: fun(x)[0], x0, jac=lambda x: fun(x)[1], xtol=1e-12, ftol=1e-12, gtol=1e-12)
    assert ref.cost < 0.5 * float(fun(x0)[0] @ fun(x0)[0])
    assert ours.cost == pytest.approx(ref.cost, rel=1e-3) or ours.cost < ref.cost
