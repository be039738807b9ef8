"""Natural light: recovery beats doing nothing on a small held-out synthetic case.

The fast slice of ``benchmarks/natural_light.py``: a library material rendered
by the deterministic forward model under a procedural sky, recovered with a
model rebuilt without that material (bases, GMM and hue prior from the other
99 fits), from the pixels the app uses (the silhouette ring dropped). The
recovered map must beat a constant map and the recovered BRDF the model's mean
material; a near-Lambertian material must come back without a highlight. Each
also with shot noise (a photograph's: 200 photons at the mean pixel,
:func:`~mi_dsbrdf.evaluation.experiment.shot_noise`).
"""
import numpy as np
import pytest

from mi_dsbrdf.app.demo import brdf_errors
from mi_dsbrdf.app.scenes import sphere_scene
from mi_dsbrdf.config import Config
from mi_dsbrdf.evaluation.experiment import downsample, shot_noise
from mi_dsbrdf.model.build import loo_model
from mi_dsbrdf.evaluation.metrics import highlight_ratio, scale_invariant_log_error
from mi_dsbrdf.inference import recover_envmap
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.inference.latlong import procedural_sky
from mi_dsbrdf.inference.pixels import usable_pixels
from mi_dsbrdf.model import model_file as model_data
from mi_dsbrdf.model.samples import samples_from_function

RES, MAP = 32, (16, 32)
#: shot noise of the noisy variants: photons at the image's mean pixel
PHOTONS = 200


def recover(name, cache, photons=None):
    """(recovery, truth material, truth map at the recovered size, model) of ``name``
    under a sky, recovered with the leave-one-out model (built into ``cache``),
    from an image with ``photons`` shot noise (None: noise-free)."""
    sky = procedural_sky(2 * MAP[0], 2 * MAP[1], sun_direction=(0.4, 0.6, 0.7)).astype(np.float64)
    s = sphere_scene({"type": "dsbrdf", "material": name}, RES)
    ts = TexelSum(s, s.shapes()[0], sky.shape[:2])
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(sky.reshape(-1, 3))
    if photons:
        img = shot_noise(img, ts.mask.reshape(-1), photons, seed=name)
    s2 = sphere_scene({"type": "dsbrdf"}, RES)
    ts2 = TexelSum(s2, s2.shapes()[0], MAP)
    model = loo_model(name, str(cache))
    assert name not in model.library
    img = img.reshape(RES, RES, 3)
    res = recover_envmap(ts2, img, usable_pixels(ts2.mask, img), model, Config(map_size=MAP, max_rounds=2))
    return res, model_data.shipped_model().library_material(name), downsample(sky, *MAP), model


@pytest.mark.slow
@pytest.mark.parametrize("photons", [None, pytest.param(PHOTONS, marks=pytest.mark.xfail(
    strict=False, reason="known bug: under 200 photons a mean pixel green-plastic can come back near-diffuse, "
    "its map no better than a constant one (depends on the BLAS build)"))])
@pytest.mark.parametrize("name", ["green-plastic"])
def test_recovery_beats_a_constant_map_and_the_mean_material(name, photons, tmp_path):
    res, truth, sky, model = recover(name, tmp_path, photons)
    assert np.all(np.isfinite(res.illumination)) and np.all(np.isfinite(res.psi))
    seen = res.seen
    for convention in ("cosine", "paper"):
        found = scale_invariant_log_error(res.illumination, sky, seen, convention)
        constant = scale_invariant_log_error(np.ones_like(sky), sky, seen, convention)
        assert found < constant, (convention, found, constant)
    assert brdf_errors(res.material, truth)["paper"] < brdf_errors(model.mean_material(), truth)["paper"]


@pytest.mark.slow
@pytest.mark.parametrize("photons", [None, PHOTONS])
def test_a_near_lambertian_material_comes_back_without_a_highlight(photons, tmp_path):
    res, truth, _, model = recover("pink-felt", tmp_path, photons)
    s = samples_from_function(lambda th, td, pd: truth.eval(th, td))
    ratio = [highlight_ratio(m.eval(s.theta_h, s.theta_d), s.theta_h, s.theta_d)
             for m in (res.material, truth, model.mean_material())]
    assert ratio[1] < 1.2 and ratio[2] > 3            # the truth has none, the mean material has one
    assert ratio[0] < 1.5 * ratio[1], ratio              # benchmarks/natural_light.py: HIGHLIGHT_LIMIT
