"""Where an image looks in (theta_h, theta_d): ``DirectionWeights``, ``observed_directions``
and ``Material.observed``, and Eq. 20 restricted to it."""
import math

import numpy as np
import pytest

from mi_dsbrdf.brdf.dsbrdf import Material
from mi_dsbrdf.brdf.log_error import material_errors, observed_errors
from mi_dsbrdf.brdf.observed import N_CELLS, DirectionWeights, cell_indices
from mi_dsbrdf.errors import MaterialError
from mi_dsbrdf.evaluation.experiment import texels
from mi_dsbrdf.inference.lobes import observed_directions
from mi_dsbrdf.model import model_file
from mi_dsbrdf.model.samples import samples_from_function


def test_direction_weights_bin_normalise_and_look_up():
    th, td = np.array([0.01, 0.011, 1.2]), np.array([0.3, 0.3, 1.0])
    w = DirectionWeights.from_pairs(th, td, [1.0, 1.0, 2.0])
    np.testing.assert_allclose(w(th, td), [0.5, 0.5, 0.5])          # two pairs share a cell
    assert w.weights.sum() == pytest.approx(1.0)
    assert w(np.array([0.5]), np.array([0.5]))[0] == 0.0           # a cell no pair fell in
    # the theta_h cells are finer near the highlight: 0.5 deg and 5 deg fall in different cells
    i, _ = cell_indices(np.radians([0.5, 5.0]), np.zeros(2))
    assert i[0] < i[1] and cell_indices(math.pi / 2, math.pi / 2) == (N_CELLS - 1, N_CELLS - 1)
    again = DirectionWeights.from_dict(w.to_dict())
    np.testing.assert_allclose(again.weights, w.weights, atol=1e-8)
    with pytest.raises(MaterialError, match="finite and >= 0"):
        DirectionWeights(-np.ones((3, 3)))


def test_a_material_keeps_where_it_was_seen_through_its_file(tmp_path):
    base = model_file.shipped_model().mean_material()
    assert base.observed(np.zeros(1), np.zeros(1)) is None           # not recovered from an image
    seen = DirectionWeights.from_pairs([0.05], [0.4], [1.0])
    m = base.with_observed(seen)
    assert base.observed(np.zeros(1), np.zeros(1)) is None           # the original is unchanged
    m.save(tmp_path / "m.json")
    back = Material.load(tmp_path / "m.json")
    assert back.observed(np.array([0.05, 0.05]), np.array([0.4, 1.2])).tolist() == [1.0, 0.0]
    np.testing.assert_allclose(back.log_kappa, m.log_kappa)


@pytest.mark.parametrize("apart_deg", [0.0, 60.0])
def test_a_directional_light_is_seen_at_half_its_angle_to_each_view_direction(apart_deg):
    """theta_d is half the angle between the light and the direction to the camera:
    a light at ``apart_deg`` from the camera's axis puts all the weight between
    the smallest and largest half-angle over the sphere's pixels, and none elsewhere."""
    a = math.radians(apart_deg)
    light = np.array([math.sin(a), 0.0, math.cos(a)])
    view = texels({"type": "dsbrdf"}, 32).with_directions(light[None], [1.0])
    weights = observed_directions(view, np.ones((1, 3)), np.arange(view.n_pixels))
    to_camera = np.array([0.0, 0.0, 4.0])[:, None] - view.positions             # (3, P)
    to_camera /= np.linalg.norm(to_camera, axis=0)
    lit = (view.frames[2].T * light).sum(axis=1) > 0                           # n . light > 0
    half = np.degrees(np.arccos(np.clip(light @ to_camera, -1, 1)))[lit] / 2
    theta_d = (np.arange(N_CELLS) + 0.5) * 90.0 / N_CELLS                      # degrees, cell centres
    by_theta_d = weights.weights.sum(axis=0)
    cell = 90.0 / N_CELLS
    assert by_theta_d[(theta_d < half.min() - cell) | (theta_d > half.max() + cell)].sum() < 1e-6
    assert half.min() - cell <= float((by_theta_d * theta_d).sum()) <= half.max() + cell
    # a light behind the sphere lights none of the pixels the camera sees
    behind = texels({"type": "dsbrdf"}, 16).with_directions(np.array([[0.0, 0.0, -1.0]]), [1.0])
    assert observed_directions(behind, np.ones((1, 3)), np.arange(behind.n_pixels)).weights.sum() == 0.0


def test_eq20_on_observed_directions_scores_only_them():
    truth = model_file.shipped_model().library_material("gold-metallic-paint")
    samples = samples_from_function(lambda th, td, pd: truth.eval(th, td))
    mean = model_file.shipped_model().mean_material()
    near = samples.theta_d < math.radians(20)
    seen = mean.with_observed(DirectionWeights.from_pairs(samples.theta_h[near], samples.theta_d[near],
                                                         np.ones(near.sum())))
    got = observed_errors(seen, samples)
    where = seen.observed(samples.theta_h, samples.theta_d) > 0
    assert where.any() and not where.all()
    assert got["observed"] == material_errors(mean, samples, where=where)
    assert got["unobserved"] == material_errors(mean, samples, where=~where)
    assert got["observed"]["paper"] != pytest.approx(material_errors(mean, samples)["paper"], rel=1e-3)
    assert observed_errors(mean, samples) is None
