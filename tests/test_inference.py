"""End-to-end inference on small synthetic cases (data made by the deterministic forward model)."""
import dataclasses
import math

import numpy as np
import pytest

from mi_dsbrdf.config import Config
from mi_dsbrdf.errors import ConfigError, InputError
from mi_dsbrdf.inference import recover_envmap, recover_light
from mi_dsbrdf.inference.objective import direction_from_angles
from mi_dsbrdf.inference.reflectance import reflectance_starts
from mi_dsbrdf.model import model_file as model_data
from mi_dsbrdf.brdf.dsbrdf import Material
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.app.scenes import sphere_scene

TRUTH = "gold-metallic-paint"
RES = 24
LIGHT = direction_from_angles(1.1, 2.6)      # 40 deg from the viewer


def sphere(bsdf):
    return sphere_scene(bsdf, RES)


@pytest.fixture(scope="module")
def observed():
    s = sphere({"type": "dsbrdf", "material": TRUTH})
    ts = TexelSum(s, s.shapes()[0], (1, 1)).with_directions(LIGHT[None], [1.0])
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(np.full((1, 3), 3.0))
    return img.reshape(RES, RES, 3)


def pixel_angles(ts, light):
    """(theta_h, theta_d) of the pixels lit at more than 10 deg above their horizon."""
    n = np.array(ts.si.n).T.astype(np.float64)
    v = np.array(ts.si.to_world(ts.si.wi)).T.astype(np.float64)
    h = v + light
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    lit = n @ light > math.sin(math.radians(10))
    return np.arccos(np.clip((n * h).sum(1), -1, 1))[lit], np.arccos(np.clip(h @ light, -1, 1))[lit]


def brdf_error(res, model, ts, scale_invariant=False):
    """|log BRDF error| at the lit pixels' angles; scale-invariant (Eq. 20 style)
    when the light's intensity is unknown (only light x BRDF is observable)."""
    th, td = pixel_angles(ts, LIGHT)
    m = res.material
    d = np.log(m.eval(th, td)) - np.log(model.library_material(TRUTH).eval(th, td))
    return np.abs(d - np.median(d) if scale_invariant else d)


def test_known_directional_light_recovers_the_dsbrdf(observed):
    s = sphere({"type": "dsbrdf"})
    ts = TexelSum(s, s.shapes()[0], (1, 1))
    model = model_data.shipped_model()
    cfg = Config(max_rounds=1, block_iters=40)
    res = recover_light(ts, observed, ts.mask, model, cfg, known_light=(LIGHT, 3.0))
    assert all(np.isfinite(r["neg_log_posterior"]) for r in res.log)
    mean_log = res.log[-1]["likelihood"] * cfg.likelihood_scale / (3 * ts.mask.sum())
    assert mean_log < 0.005                                    # re-render: mean |log error| < 0.5 %
    err = brdf_error(res, model, ts)
    assert np.median(err) < 0.05, np.median(err)              # BRDF at the observed angles within 5 %


def test_a_light_takes_the_gmm_volume_of_lights_not_the_maps(observed):
    """Under a light the GMM prior keeps ``Config.light_gmm_volume`` of its volume
    terms (chosen under point lights), not ``gmm_volume`` (chosen under maps)."""
    s = sphere({"type": "dsbrdf"})
    ts = TexelSum(s, s.shapes()[0], (1, 1))
    model = model_data.shipped_model()
    base = Config(max_rounds=1, block_iters=8)
    psi = [recover_light(ts, observed, ts.mask, model, dataclasses.replace(base, **kw),
                         known_light=(LIGHT, 3.0)).psi
           for kw in ({"gmm_volume": 0.0, "light_gmm_volume": 1.0}, {"gmm_volume": 1.0, "light_gmm_volume": 1.0},
                      {"gmm_volume": 1.0, "light_gmm_volume": 0.0})]
    np.testing.assert_array_equal(psi[0], psi[1])
    assert not np.allclose(psi[1], psi[2])
    with pytest.raises(ConfigError, match="light_gmm_volume"):
        Config(light_gmm_volume=2.0)


def test_unknown_directional_light_within_a_degree(observed):
    s = sphere({"type": "dsbrdf"})
    ts = TexelSum(s, s.shapes()[0], (1, 1))
    model = model_data.shipped_model()
    res = recover_light(ts, observed, ts.mask, model,
                                              Config(max_rounds=4, block_iters=40))
    err = math.degrees(math.acos(min(1.0, float(res.light["direction"] @ LIGHT))))
    assert err < 1.0, err
    assert res.light["intensity"] > 0 and np.isfinite(res.light["intensity"])
    assert np.median(brdf_error(res, model, ts, scale_invariant=True)) < 0.05


def test_unknown_point_light_at_a_finite_distance_within_a_degree():
    pos = 5.0 * LIGHT
    s = sphere({"type": "dsbrdf", "material": TRUTH})
    ts = TexelSum(s, s.shapes()[0], (1, 1)).with_point(pos)
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(np.full((1, 3), 40.0))
    s2 = sphere({"type": "dsbrdf"})
    ts2 = TexelSum(s2, s2.shapes()[0], (1, 1))
    res = recover_light(ts2, img.reshape(RES, RES, 3), ts2.mask, model_data.shipped_model(),
                                        Config(max_rounds=3, block_iters=30), point=(np.zeros(3), 5.0))
    err = math.degrees(math.acos(min(1.0, float(res.light["direction"] @ LIGHT))))
    assert err < 1.0, err
    np.testing.assert_allclose(res.light["position"], 5.0 * res.light["direction"], rtol=1e-9)
    assert all(np.isfinite(r["neg_log_posterior"]) for r in res.log)


def test_envmap_inference_decreases_the_posterior_and_masks_unseen_texels():
    from mi_dsbrdf.inference.latlong import procedural_sky
    sky = procedural_sky(16, 32).astype(np.float64)
    s = sphere({"type": "dsbrdf", "material": TRUTH})
    ts = TexelSum(s, s.shapes()[0], (16, 32))
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(sky)
    s2 = sphere({"type": "dsbrdf"})
    ts2 = TexelSum(s2, s2.shapes()[0], (8, 16))
    # texel centres: at 8x16 with 2x2 directions a texel, every texel has one that a
    # silhouette pixel sees at grazing angles, and none would be unseen
    cfg = Config(map_size=(8, 16), max_rounds=2, block_iters=5, illumination_iters=20, texel_samples=1)
    res = recover_envmap(ts2, img.reshape(RES, RES, 3), ts2.mask, model_data.shipped_model(), cfg)
    passes = [r["pass"] for r in res.log]
    assert passes.count("start") == len(reflectance_starts(model_data.shipped_model()))
    assert "grey" in passes and "colour" in passes
    grey = [r["neg_log_posterior"] for r in res.log if r["pass"] == "grey"]
    colour = [r["neg_log_posterior"] for r in res.log if r["pass"] == "colour"]
    assert all(np.isfinite(grey + colour)) and colour[-1] < grey[0]
    # texels straight behind the sphere are seen by no pixel: black, and counted
    assert (~res.seen).sum() == res.log[-1]["unseen_texels"] > 0
    assert np.all(res.illumination[~res.seen] == 0) and np.all(res.illumination[res.seen] > 0)



def test_envmap_inference_runs_from_the_starts_it_is_given():
    """``starts`` replaces the mean material and the GMM means: one start, one
    start row, and two different starts give two different results."""
    from mi_dsbrdf.inference.latlong import procedural_sky
    model = model_data.shipped_model()
    s = sphere({"type": "dsbrdf", "material": TRUTH})
    ts = TexelSum(s, s.shapes()[0], (8, 16))
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(procedural_sky(8, 16).astype(np.float64))
    cfg = Config(map_size=(8, 16), max_rounds=1, block_iters=3, illumination_iters=10)
    found = []
    for psi in (np.zeros(model.basis.n_bases), model.library_material(TRUTH).psi):
        res = recover_envmap(ts, img.reshape(RES, RES, 3), ts.mask, model, cfg, colour=False, starts=[psi])
        assert [r["pass"] for r in res.log].count("start") == 1
        found.append((res.psi, res.log[0]["neg_log_posterior"]))
    assert not np.allclose(found[0][0], found[1][0]) and found[0][1] != found[1][1]
    with pytest.raises(InputError, match="starts must be"):
        recover_envmap(ts, img.reshape(RES, RES, 3), ts.mask, model, cfg, starts=[np.zeros(3)])

def test_coarse_to_fine_map_sizes_and_resampling():
    from mi_dsbrdf.inference.envmap import BLACK, map_sizes, resample
    assert map_sizes((32, 64), 3, 2) == [(8, 16), (32, 64), (32, 64)]
    assert map_sizes((32, 64), 3, 1) == [(8, 16), (32, 64)]
    assert map_sizes((32, 64), 1, 2) == [(32, 64)] * 3
    assert map_sizes((4, 8), 3, 2) == [(2, 4), (4, 8), (4, 8)]         # never below 2 x 4
    x = np.log(np.arange(1, 9, dtype=np.float64)).reshape(2, 4, 1).repeat(3, axis=2)
    x[0, 0] = BLACK                                                    # unseen
    up = resample(x, (4, 8))
    assert up.shape == (4, 8, 3)
    np.testing.assert_array_equal(up[2:, 6:], np.full((2, 2, 3), x[1, 3, 0]))    # each texel covers 2 x 2
    np.testing.assert_array_equal(up[:2, :2], np.full((2, 2, 3), x[0, 1, 0]))    # unseen: darkest seen value
    np.testing.assert_array_equal(resample(up, (2, 4))[1], x[1])


def test_a_grey_object_comes_back_grey():
    """A grey image (grey material, white light) gives grey lobes: the
    chromaticity starts at the image's colour (a random start came back with
    lobes of (0.29, 0.52, 0.19) and a green highlight)."""
    psi = model_data.shipped_model().library_material(TRUTH).psi
    props = {"type": "dsbrdf", "psi": " ".join(repr(float(v)) for v in psi)}
    props.update({"chromaticity_%d" % r: "0.3333333 0.3333333 0.3333334" for r in range(3)})
    s = sphere(props)
    ts = TexelSum(s, s.shapes()[0], (1, 1)).with_directions(LIGHT[None], [1.0])
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(np.full((1, 3), 3.0))
    s2 = sphere({"type": "dsbrdf"})
    ts2 = TexelSum(s2, s2.shapes()[0], (1, 1))
    res = recover_light(ts2, img.reshape(RES, RES, 3), ts2.mask, model_data.shipped_model(),
                        Config(max_rounds=2, block_iters=20))
    np.testing.assert_allclose(res.chromaticity, 1 / 3, atol=0.02)


def test_grey_texel_samples_runs_the_start_and_grey_pass_at_texel_centres():
    """``Config.grey_texel_samples`` 1 with ``texel_samples`` 2: the start and the
    grey pass are those of a texel-centre run, number for number; the colour pass
    lights each texel from 2 x 2 directions and ends elsewhere."""
    from mi_dsbrdf.inference.latlong import procedural_sky
    model = model_data.shipped_model()
    s = sphere({"type": "dsbrdf", "material": TRUTH})
    ts = TexelSum(s, s.shapes()[0], (8, 16))
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(procedural_sky(8, 16).astype(np.float64))
    base = Config(map_size=(8, 16), max_rounds=1, block_iters=3, illumination_iters=10)
    runs = [recover_envmap(ts, img.reshape(RES, RES, 3), ts.mask, model, cfg, starts=[np.zeros(model.basis.n_bases)])
            for cfg in (dataclasses.replace(base, texel_samples=1),
                        dataclasses.replace(base, texel_samples=2, grey_texel_samples=1))]
    value = [{r["pass"]: r["neg_log_posterior"] for r in res.log} for res in runs]
    assert value[0]["start"] == value[1]["start"] and value[0]["grey"] == value[1]["grey"]
    assert value[0]["colour"] != value[1]["colour"] and np.isfinite(value[1]["colour"])
    with pytest.raises(ConfigError, match="grey_texel_samples"):
        Config(grey_texel_samples=0)
