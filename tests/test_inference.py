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
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.app.scenes import sphere_scene

TRUTH = "gold-metallic-paint"
RES = 24
LIGHT = direction_from_angles(1.1, 2.6)      # 40 deg from the viewer


def sphere(bsdf):
    return sphere_scene(bsdf, RES)


def image_under(props, sky):
    """(RES, RES, 3) image of a sphere of ``props`` under the map ``sky`` (H, W, 3)."""
    s = sphere(props)
    ts = TexelSum(s, s.shapes()[0], sky.shape[:2])
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(sky)
    return img.reshape(RES, RES, 3)


def dsbrdf_view(map_hw):
    """The view of a DSBRDF sphere that inference renders at ``map_hw`` texels."""
    s = sphere({"type": "dsbrdf"})
    return TexelSum(s, s.shapes()[0], map_hw)


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


def test_a_light_takes_the_gmm_volume_of_lights_not_the_maps(observed, monkeypatch):
    """Under a light the GMM prior keeps ``light.LIGHT_GMM_VOLUME`` of its volume
    terms, not a map's ``objective.GMM_VOLUME``."""
    from mi_dsbrdf.inference import light, objective
    s = sphere({"type": "dsbrdf"})
    ts = TexelSum(s, s.shapes()[0], (1, 1))
    model = model_data.shipped_model()
    cfg = Config(max_rounds=1, block_iters=8)
    assert (objective.GMM_VOLUME, light.LIGHT_GMM_VOLUME) == (0.0, 1.0)
    psi = []
    for map_volume, light_volume in ((0.0, 1.0), (1.0, 1.0), (1.0, 0.0)):
        monkeypatch.setattr(objective, "GMM_VOLUME", map_volume)
        monkeypatch.setattr(light, "LIGHT_GMM_VOLUME", light_volume)
        psi.append(recover_light(ts, observed, ts.mask, model, cfg, known_light=(LIGHT, 3.0)).psi)
    np.testing.assert_array_equal(psi[0], psi[1])
    assert not np.allclose(psi[1], psi[2])


@pytest.mark.slow
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


@pytest.mark.parametrize("rays", [1, 3])
def test_unknown_point_light_at_a_finite_distance_within_a_degree(rays):
    """From its own image formation: each pixel's centre ray, or 3 x 3 rays across it
    (the search then runs on centre rays, the later rounds on the rays)."""
    pos = 5.0 * LIGHT
    s = sphere({"type": "dsbrdf", "material": TRUTH})
    ts = TexelSum(s, s.shapes()[0], (1, 1), pixel_rays=rays).with_point(pos)
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(np.full((1, 3), 40.0))
    s2 = sphere({"type": "dsbrdf"})
    ts2 = TexelSum(s2, s2.shapes()[0], (1, 1), pixel_rays=rays)
    res = recover_light(ts2, img.reshape(RES, RES, 3), ts2.mask, model_data.shipped_model(),
                                        Config(max_rounds=3, block_iters=30), point=(np.zeros(3), 5.0))
    err = math.degrees(math.acos(min(1.0, float(res.light["direction"] @ LIGHT))))
    assert err < 1.0, err
    np.testing.assert_allclose(res.light["position"], 5.0 * res.light["direction"], rtol=1e-9)
    assert all(np.isfinite(r["neg_log_posterior"]) for r in res.log)


def test_envmap_inference_decreases_the_posterior_and_masks_unseen_texels():
    from mi_dsbrdf.inference.latlong import procedural_sky
    img = image_under({"type": "dsbrdf", "material": TRUTH}, procedural_sky(16, 32).astype(np.float64))
    ts2 = dsbrdf_view((8, 16))
    # texel centres: at 8x16 with 2x2 directions a texel, every texel has one that a
    # silhouette pixel sees at grazing angles, and none would be unseen
    cfg = Config(map_size=(8, 16), second_route_highlight=None,
                 max_rounds=2, block_iters=5, illumination_iters=20, texel_samples=1)
    res = recover_envmap(ts2, img, ts2.mask, model_data.shipped_model(), cfg)
    passes = [r["pass"] for r in res.log]
    assert passes.count("start") == len(reflectance_starts(model_data.shipped_model()))
    assert "grey" in passes and "colour" in passes
    grey = [r["neg_log_posterior"] for r in res.log if r["pass"] == "grey"]
    colour = [r["neg_log_posterior"] for r in res.log if r["pass"] == "colour"]
    assert all(np.isfinite(grey + colour)) and colour[-1] < grey[0]
    # texels straight behind the sphere are seen by no pixel: black, and counted
    assert (~res.seen).sum() == res.log[-1]["unseen_texels"] > 0
    assert np.all(res.illumination[~res.seen] == 0) and np.all(res.illumination[res.seen] > 0)



def sky_case():
    """(the shipped model, the 8x16 view of the TRUTH sphere, its (RES, RES, 3) image
    under the procedural sky): the small map case the driver's tests share."""
    from mi_dsbrdf.inference.latlong import procedural_sky
    s = sphere({"type": "dsbrdf", "material": TRUTH})
    ts = TexelSum(s, s.shapes()[0], (8, 16))
    img = np.zeros((RES * RES, 3))
    img[ts.pixels] = ts.render(procedural_sky(8, 16).astype(np.float64))
    return model_data.shipped_model(), ts, img.reshape(RES, RES, 3)


def test_envmap_inference_runs_from_the_starts_it_is_given():
    """``starts`` replaces the mean material and the GMM means: one start, one
    start row, and two different starts give two different results."""
    model, ts, img = sky_case()
    cfg = Config(map_size=(8, 16), max_rounds=1, block_iters=3, illumination_iters=10)
    found = []
    for psi in (np.zeros(model.basis.n_bases), model.library_material(TRUTH).psi):
        res = recover_envmap(ts, img, ts.mask, model, cfg, colour=False, starts=[psi])
        assert [r["pass"] for r in res.log].count("start") == 1
        found.append((res.psi, res.log[0]["neg_log_posterior"]))
    assert not np.allclose(found[0][0], found[1][0]) and found[0][1] != found[1][1]
    with pytest.raises(InputError, match="starts must be"):
        recover_envmap(ts, img, ts.mask, model, cfg, starts=[np.zeros(3)])


def test_coarse_to_fine_map_sizes_and_resampling():
    from mi_dsbrdf.inference.envmap import BLACK, map_sizes
    from mi_dsbrdf.inference.latlong import resample
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


@pytest.mark.slow
def test_a_grey_object_comes_back_grey():
    """A grey image (grey material, white light) gives grey lobes: the
    chromaticity starts at the image's colour (a random start gives coloured
    lobes and a green highlight)."""
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
    model, ts, img = sky_case()
    base = Config(map_size=(8, 16), second_route_highlight=None, max_rounds=1, block_iters=3, illumination_iters=10)
    runs = [recover_envmap(ts, img, ts.mask, model, cfg, starts=[np.zeros(model.basis.n_bases)])
            for cfg in (dataclasses.replace(base, texel_samples=1),
                        dataclasses.replace(base, texel_samples=2, grey_texel_samples=1))]
    value = [{r["pass"]: r["neg_log_posterior"] for r in res.log} for res in runs]
    assert value[0]["start"] == value[1]["start"] and value[0]["grey"] == value[1]["grey"]
    assert value[0]["colour"] != value[1]["colour"] and np.isfinite(value[1]["colour"])
    with pytest.raises(ConfigError, match="grey_texel_samples"):
        Config(grey_texel_samples=0)



def test_second_route_runs_only_above_its_highlight_and_the_lower_posterior_wins():
    """``Config.second_route_highlight``: above it (here any answer) a second
    inference (rows tagged ``route`` 1: its starts on the full map, no grey pass)
    runs after the first, and the answer is the end of the one whose last colour
    round is lower, repeated in a last "answer" row; far above any answer it never
    runs, and the run is the one without a second route (None), number for number."""
    model, ts, img = sky_case()
    base = Config(map_size=(8, 16), max_rounds=1, block_iters=3, illumination_iters=10, highlight_texels=0)
    off, never, always = (recover_envmap(ts, img, ts.mask, model, dataclasses.replace(base, second_route_highlight=h))
                          for h in (None, 1e9, 1e-9))
    assert [r["neg_log_posterior"] for r in never.log] == [r["neg_log_posterior"] for r in off.log]
    np.testing.assert_array_equal(never.psi, off.psi)
    first = [r for r in always.log if "route" not in r and r["pass"] != "answer"]
    second = [r for r in always.log if r.get("route") == 1]
    assert [r["neg_log_posterior"] for r in first] == [r["neg_log_posterior"] for r in off.log]
    assert [r["pass"] for r in second] == ["start"] * len(reflectance_starts(model)) + ["colour"]
    assert {tuple(r["map_size"]) for r in second} == {(8, 16)}
    ends = [first[-1]["neg_log_posterior"], second[-1]["neg_log_posterior"]]
    won = int(ends[1] < ends[0])
    if won:
        assert not np.array_equal(always.psi, off.psi)
    else:
        np.testing.assert_array_equal(always.psi, off.psi)
    # the last row is the answer's, whichever route won
    answer = always.log[-1]
    assert answer["pass"] == "answer" and answer["answer_route"] == won and "route" not in answer
    assert always.neg_log_posterior == min(ends)
    assert answer["likelihood"] == (first, second)[won][-1]["likelihood"]
    assert "answer" not in [r["pass"] for r in never.log]
    assert off.material.highlight_ratio() > 0
    with pytest.raises(ConfigError, match="second_route_highlight"):
        Config(second_route_highlight=0)


def test_envmap_recovery_does_not_depend_on_the_images_units():
    """The same image in other units (an exposure of 2^-40, or 3e9) gives the same
    material and the map in those units: the map's log bounds and the black of
    unseen texels are absolute constants, which an image far from unit level
    would otherwise cross."""
    model, ts, img = sky_case()
    cfg = Config(map_size=(8, 16), max_rounds=1, block_iters=3, illumination_iters=10, texel_samples=1)
    one = recover_envmap(ts, img, ts.mask, model, cfg)
    tiny = recover_envmap(ts, img * 2.0 ** -40, ts.mask, model, cfg)       # exact in binary: bit for bit
    np.testing.assert_array_equal(tiny.psi, one.psi)
    np.testing.assert_array_equal(tiny.illumination, one.illumination * 2.0 ** -40)
    big = recover_envmap(ts, img * 3e9, ts.mask, model, cfg)
    np.testing.assert_allclose(big.psi, one.psi, atol=1e-6)
    np.testing.assert_allclose(big.illumination[one.seen], one.illumination[one.seen] * 3e9, rtol=1e-6)
    with pytest.raises(InputError, match="mean"):
        recover_envmap(ts, np.zeros_like(img), ts.mask, model, cfg)


def grey_material_props(name):
    psi = model_data.shipped_model().library_material(name).psi
    props = {"type": "dsbrdf", "psi": " ".join(repr(float(v)) for v in psi)}
    props.update({"chromaticity_%d" % r: "0.3333333 0.3333333 0.3333334" for r in range(3)})
    return props


def test_colour_split_moves_the_colour_the_image_cannot_place():
    """Lobes tinted orange under a white map: the split step moves the tint into
    the map (the chromaticity prior knows most lobes are near grey) as far as the
    light-colour prior lets it, and leaves the broad lobe's light unchanged."""
    from mi_dsbrdf.brdf.chromaticity import chroma_logits, softmax_chroma
    from mi_dsbrdf.inference.envmap import colour_split
    from mi_dsbrdf.inference.objective import Posterior
    model = model_data.shipped_model()
    s = sphere(grey_material_props("pvc"))
    ts = TexelSum(s, s.shapes()[0], (4, 8))
    observed = np.ones((RES, RES, 3))
    orange = np.array([0.5, 0.3, 0.2])
    logits = chroma_logits(np.tile(orange, (3, 1)))
    x = np.random.default_rng(0).normal(0, 1, (4, 8, 1)).repeat(3, axis=2)       # a white map
    seen = np.ones((4, 8), bool)
    moved = []
    for sigma in (0.26, 0.02):
        post = Posterior(ts, observed, ts.mask, model, Config(map_size=(4, 8), w_chromaticity=1.0,
                                                              w_light_colour=1.0, light_temperature_sigma=sigma))
        new_logits, new_map = colour_split(post, logits, x, seen)
        c, m = softmax_chroma(new_logits), np.exp(post.light_colour.colour(new_map))
        # the broad lobe's colour times the light's is what it was, level included
        np.testing.assert_allclose(c[0] * m, orange * np.exp(post.light_colour.colour(x)), rtol=1e-9)
        moved.append(m / m.sum())
    assert moved[0][0] > moved[0][2] + 0.1              # the map took the tint...
    assert abs(moved[1][0] - moved[1][2]) < 0.03        # ... unless the light-colour prior is tight
    unchanged = colour_split(post, chroma_logits(np.full((3, 3), 1 / 3)), x, seen)
    assert np.abs(unchanged[1] - x).max() < 0.02       # grey lobes, white map: little to move


def test_an_orange_light_goes_into_the_map_not_the_material():
    """A grey material under an orange sky: with the colour-split priors the
    recovered map is orange and the lobes near grey; without them the image's
    colour stays in the material (its start)."""
    from mi_dsbrdf.inference.latlong import procedural_sky
    sky = procedural_sky(8, 16).astype(np.float64) * np.array([1.0, 0.6, 0.3])
    img = image_under(grey_material_props("pvc"), sky)
    ts2 = dsbrdf_view((8, 16))
    base = Config(map_size=(8, 16), second_route_highlight=None,
                  max_rounds=2, block_iters=5, illumination_iters=20, texel_samples=1)
    model = model_data.shipped_model()
    red_over_blue = {}
    for on in (0.0, 1.0):
        cfg = dataclasses.replace(base, w_chromaticity=on, w_light_colour=on)
        res = recover_envmap(ts2, img, ts2.mask, model, cfg)
        m = res.illumination[res.seen].mean(axis=0)
        red_over_blue[on] = (m[0] / m[2], res.chromaticity[0, 0] / res.chromaticity[0, 2])
        assert on == 0.0 or any(r.get("colour_split_kept") for r in res.log)
    truth = (sky.mean(axis=(0, 1))[0] / sky.mean(axis=(0, 1))[2], 1.0)
    assert red_over_blue[1.0][0] > red_over_blue[0.0][0] + 0.3        # the map is more orange
    assert red_over_blue[1.0][1] < red_over_blue[0.0][1] - 0.3        # the material greyer
    assert abs(np.log(red_over_blue[1.0][0] / truth[0])) < abs(np.log(red_over_blue[0.0][0] / truth[0]))


def test_the_highlight_pairs_refine_the_answer_only_where_they_change_its_image():
    """``Config.highlight_texels``, ``highlight_check``: the answer's image with and
    without the highlight pairs is compared (``Recovery.highlight_change``, the pairs'
    own re-render against the texel sum's); above the check a "highlights" pass goes on
    from the answer with them, and the Recovery says it was fitted with them; below it
    the run is the one without pairs, number for number."""
    from mi_dsbrdf.inference.lobes import LobeSum
    model, ts, img = sky_case()
    base = Config(map_size=(8, 16), max_rounds=1, block_iters=3, illumination_iters=10, second_route_highlight=None)
    none, never, always = (recover_envmap(ts, img, ts.mask, model, dataclasses.replace(base, **kw))
                           for kw in ({"highlight_texels": 0}, {"highlight_check": 1e9}, {"highlight_check": 0.0}))
    assert none.highlight_change is None and none.highlight_texels == 0
    assert [r["neg_log_posterior"] for r in never.log] == [r["neg_log_posterior"] for r in none.log]
    np.testing.assert_array_equal(never.psi, none.psi)
    assert never.highlight_texels == 0
    # the change is the pairs' re-render of the answer against the texel sum's
    L = np.asarray(never.illumination).reshape(-1, 3)
    plain = LobeSum(ts.with_map_size((8, 16), base.texel_samples)).render(never.material, L)
    pairs = LobeSum(ts.with_map_size((8, 16), base.texel_samples).with_highlights(25)).render(never.material, L)
    assert never.highlight_change > 0
    assert never.highlight_change == pytest.approx(np.abs(pairs - plain).sum() / np.abs(pairs).sum(), rel=0.05)
    passes = [r["pass"] for r in always.log]
    assert passes[:len(none.log)] == [r["pass"] for r in none.log] and passes[len(none.log):] == ["highlights"]
    assert always.highlight_texels == 25 and always.log[-1]["highlight_change"] == always.highlight_change
    with pytest.raises(ConfigError, match="highlight_check"):
        Config(highlight_check=-1.0)


def test_the_colour_split_priors_leave_the_start_and_the_grey_pass_alone(observed):
    """The chromaticity and light-colour priors act in the colour pass only: the
    start and the grey pass of a run with them are those of a run without, number
    for number, and a light's recovery ignores them (its colour is the material's)."""
    from mi_dsbrdf.inference.latlong import procedural_sky
    model = model_data.shipped_model()
    img = image_under({"type": "dsbrdf", "material": TRUTH}, procedural_sky(8, 16).astype(np.float64))
    ts = dsbrdf_view((8, 16))
    base = Config(map_size=(8, 16), second_route_highlight=None,
                  max_rounds=2, block_iters=3, illumination_iters=10, texel_samples=1)
    runs = [recover_envmap(ts, img, ts.mask, model, dataclasses.replace(base, **kw),
                           starts=[np.zeros(model.basis.n_bases)])
            for kw in ({"w_chromaticity": 0.0, "w_light_colour": 0.0}, {"w_chromaticity": 1.0, "w_light_colour": 1.0})]
    before = [[r["neg_log_posterior"] for r in res.log if r["pass"] in ("start", "grey")] for res in runs]
    assert before[0] == before[1]
    assert "chromaticity" in runs[1].log[-1] and "chromaticity" not in runs[0].log[-1]
    ts = dsbrdf_view((1, 1))
    light = [recover_light(ts, observed, ts.mask, model, Config(max_rounds=1, block_iters=8, w_chromaticity=w),
                           known_light=(LIGHT, 3.0)) for w in (0.0, 100.0)]
    np.testing.assert_array_equal(light[0].psi, light[1].psi)
    np.testing.assert_array_equal(light[0].chromaticity, light[1].chromaticity)
    with pytest.raises(ConfigError, match="light_tint_sigma"):
        Config(light_tint_sigma=0.0)
