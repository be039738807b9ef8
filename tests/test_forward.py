"""The deterministic texel-sum forward model against Mitsuba's Monte Carlo render, and its gradients."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.inference.lobes import LobeSum
from mi_dsbrdf.inference.latlong import latlong_directions
from mi_dsbrdf.inference.pixels import interior
from mi_dsbrdf.inference.scene_dicts import camera

PSI = np.array([0.5, -0.3, 0.2, 0, 0, 0, 0, 0, 0, 0.1])


def smooth_map(H=16, W=32):
    d = latlong_directions(H, W)
    return np.stack([1 + 0.8 * d[..., 1], 1 + 0.5 * d[..., 0], 1 - 0.6 * d[..., 2]], -1)


def scene(bsdf, env=None, res=32, spp=256):
    d = {"type": "scene", "integrator": {"type": "direct", "emitter_samples": 2, "bsdf_samples": 2},
         "sensor": {"type": "perspective", "fov": 30,
                    "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent", "sample_count": spp}},
         "object": {"type": "sphere", "bsdf": bsdf}}
    if env is not None:
        d["emitter"] = {"type": "envmap", "bitmap": mi.Bitmap(env.astype(np.float32))}
    return mi.load_dict(d)


def test_texel_sum_matches_monte_carlo_render():
    env = smooth_map()
    # 1024 spp: at 256 the reference's own Monte Carlo noise is ~3 % per pixel (2 % at 2048)
    s = scene({"type": "dsbrdf", "material": "gold-metallic-paint"}, env, spp=1024)
    ref = np.array(mi.render(s, seed=3)).reshape(-1, 3)
    ts = TexelSum(s, s.shapes()[0], env.shape[:2])
    img = ts.render(env)
    sel = interior(ts.mask).reshape(-1)[ts.pixels]          # silhouette pixels also see the background
    ref = ref[ts.pixels][sel]
    err = np.abs(img[sel] - ref) / ref
    assert ts.n_pixels > 500 and np.mean(err) < 0.03 and np.percentile(err, 95) < 0.08, (np.mean(err), err.max())
    T = ts.transport()
    assert T.shape == (3, ts.n_pixels, 512) and np.all(T >= 0)
    # texels straight behind the sphere light no visible point: unseen; none in front is
    unseen = LobeSum(ts).unseen
    d = latlong_directions(16, 32).reshape(-1, 3)
    assert unseen.any() and np.all(d[unseen, 2] < 0) and not unseen[d[:, 2] > 0].any()


def psi_texels(psi, env, res):
    """A TexelSum over a sphere whose dsbrdf is the basis point ``psi``."""
    s = scene({"type": "dsbrdf", "psi": " ".join(map(str, psi)), "chromaticity_0": "0.5 0.3 0.2"}, res=res)
    return TexelSum(s, s.shapes()[0], env.shape[:2])


def psi_derivative(i, env, res, h=1e-2):
    """Central difference of the pixel radiance (P, 3) along psi_i, around PSI."""
    e = np.zeros(10)
    e[i] = h
    return (psi_texels(PSI + e, env, res).render(env) - psi_texels(PSI - e, env, res).render(env)) / (2 * h)


@pytest.mark.slow
def test_visibility_of_a_non_convex_object_matches_monte_carlo():
    from mi_dsbrdf.app.scenes import scene_path
    env = smooth_map()
    s = mi.load_file(scene_path("torus_envmap"), res="32", spp="256")
    obj = [sh for sh in s.shapes() if sh.is_mesh()][0]
    base = mi.load_dict({"type": "scene", "integrator": {"type": "direct", "emitter_samples": 2, "bsdf_samples": 2},
                         "sensor": s.sensors()[0], "object": obj,
                         "emitter": {"type": "envmap", "bitmap": mi.Bitmap(env.astype(np.float32))}})
    ref = np.array(mi.render(base, seed=1)).reshape(-1, 3)
    with_vis = TexelSum(base, obj, env.shape[:2], visibility=True)
    without = TexelSum(base, obj, env.shape[:2], visibility=False)
    sel = interior(with_vis.mask).reshape(-1)[with_vis.pixels]
    r = ref[with_vis.pixels][sel]
    err_vis = np.mean(np.abs(with_vis.render(env)[sel] - r) / r)
    err_none = np.mean(np.abs(without.render(env)[sel] - r) / r)
    assert with_vis.visibility is not None and not with_vis.visibility.all()
    assert err_vis < 0.06 and err_vis < 0.5 * err_none, (err_vis, err_none)


@pytest.mark.slow
def test_forward_mode_jacobian_matches_finite_differences():
    env = smooth_map(8, 16)
    ts = psi_texels(PSI, env, 16)
    params = mi.traverse(ts.bsdf)
    dr.enable_grad(params["psi"])
    dr.enable_grad(params["chromaticity"])
    params.update()
    image, J = ts.reflectance_jacobian(env, params, ["psi", "chromaticity"])
    assert J.shape == (ts.n_pixels, 3, 10 + 9)
    np.testing.assert_allclose(image, ts.render(env), rtol=1e-5, atol=1e-7)
    for i in (0, 4):
        fd = psi_derivative(i, env, 16)
        scale = np.abs(psi_texels(PSI, env, 16).render(env)).max()
        np.testing.assert_allclose(J[:, :, i], fd, rtol=2e-3, atol=1e-5 * scale)
    # chromaticity of lobe 0, red: the red channel is linear in it, the others do not depend on it
    assert np.abs(J[:, 1:, 10]).max() == 0 and np.abs(J[:, 0, 10]).max() > 0


def test_point_light_matches_monte_carlo_render():
    pos = [2.0, 1.5, 2.5]
    s = mi.load_dict({"type": "scene", "integrator": {"type": "direct"},
                      "sensor": {"type": "perspective", "fov": 30,
                                 "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0],
                                                                            up=[0, 1, 0]),
                                 "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}}},
                      "object": {"type": "sphere", "bsdf": {"type": "dsbrdf", "material": "gold-metallic-paint"}},
                      "light": {"type": "point", "position": pos, "intensity": {"type": "rgb", "value": 7.0}}})
    ref = np.array(mi.render(s, spp=256, seed=0)).reshape(-1, 3)
    ts = TexelSum(s, s.shapes()[0], (1, 1)).with_point(pos)
    img = ts.render(np.full((1, 3), 7.0))
    r = ref[ts.pixels]
    lit = r.mean(axis=1) > 1e-2 * r.mean()
    assert ts.n_texels == 1 and lit.sum() > 200
    assert np.median(np.abs(img[lit] - r[lit]) / r[lit]) < 0.02
    # per pixel: the unit direction to the light and 1/r^2 from the surface point
    x = np.array(ts.si.p, dtype=np.float64).T
    r = np.asarray(pos) - x
    np.testing.assert_allclose(ts.directions * np.linalg.norm(r, axis=1)[:, None], r, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(ts.solid_angles * (r * r).sum(axis=1), 1.0, rtol=1e-6)
    moved = ts.with_point(2 * np.array(pos))
    far = moved.render(np.full((1, 3), 7.0))
    # a new light is a new view: the first one is unchanged
    np.testing.assert_array_equal(ts.render(np.full((1, 3), 7.0)), img)
    assert np.median(far[lit] / img[lit]) < 0.5         # twice as far: about a quarter of the light
    ts = moved
    # a subset of pixels keeps its per-pixel light directions
    sub = ts.subset(np.arange(0, ts.n_pixels, 7))
    np.testing.assert_allclose(sub.render(np.full((1, 3), 7.0)), far[::7], rtol=1e-6)


@pytest.mark.parametrize("light", ["point", "directional"])
def test_pixel_rays_render_a_sharp_highlight_at_the_terminator_as_mitsuba_does(light):
    """blue-acrylic lit from 85 degrees: its highlight sits where pixels straddle the
    terminator. Mitsuba averages each pixel over its area (box filter); so do 4 x 4
    rays a pixel (within 4 %), while the centre ray alone is over 6 % off, more than
    twice as far (measured: 12.8 % and 2.0 % under the point light, 8.5 % and 3.1 %
    under the directional one)."""
    a = np.radians(85.0)
    towards = np.array([np.sin(a), 0.2, np.cos(a)]) / np.linalg.norm([np.sin(a), 0.2, np.cos(a)])
    emitter = ({"type": "point", "position": (4 * towards).tolist(), "intensity": {"type": "rgb", "value": 40.0}}
               if light == "point" else
               {"type": "directional", "direction": (-towards).tolist(), "irradiance": {"type": "rgb", "value": 3.0}})
    s = mi.load_dict({"type": "scene", "integrator": {"type": "direct", "hide_emitters": True},
                      "sensor": camera(64), "object": {"type": "sphere", "bsdf": {"type": "dsbrdf",
                                                                                  "material": "blue-acrylic"}},
                      "light": emitter})
    ref = np.array(mi.render(s, spp=1024, seed=1), dtype=np.float64).reshape(-1, 3)
    errors = []
    for rays in (1, 4):
        base = TexelSum(s, s.shapes()[0], (1, 1), pixel_rays=rays)
        ts = base.with_point(4 * towards) if light == "point" else base.with_directions(towards[None], [1.0])
        img = ts.render(np.full((1, 3), 40.0 if light == "point" else 3.0))
        sel = interior(ts.mask).reshape(-1)[ts.pixels]
        r = ref[ts.pixels][sel]
        errors.append(np.abs(img[sel] - r).sum() / r.sum())
    assert errors[0] > 0.06 and errors[1] < 0.04 and errors[0] > 2 * errors[1], errors


def test_other_shapes_shadow_the_texel_sum_as_in_monte_carlo():
    """A wall beside the sphere hides part of the map: with shadow rays through the
    whole scene the texel sum matches Mitsuba's render, without them it is far off."""
    env = smooth_map()
    s = scene({"type": "dsbrdf", "material": "gold-metallic-paint"}, env, spp=2048)
    wall = mi.load_dict({"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([1.4, 0, 0])
                         @ mi.ScalarTransform4f().rotate([0, 1, 0], -90) @ mi.ScalarTransform4f().scale(2.0)})
    s = mi.load_dict({"type": "scene", "integrator": {"type": "direct", "emitter_samples": 2, "bsdf_samples": 2},
                      "sensor": s.sensors()[0], "object": s.shapes()[0], "emitter": s.emitters()[0], "wall": wall})
    obj = [sh for sh in s.shapes() if sh.id() == "object"][0]
    ref = np.array(mi.render(s, seed=3)).reshape(-1, 3)
    # 4 x 4 directions per texel: the wall's edge crosses texels, whose centres alone
    # would shadow a pixel in steps of a whole texel
    shadowed = TexelSum(s, obj, env.shape[:2], visibility=True, samples=4)
    sel = interior(shadowed.mask).reshape(-1)[shadowed.pixels]
    r = ref[shadowed.pixels][sel]
    err = np.abs(shadowed.render(env)[sel] - r) / r
    assert not shadowed.visibility.all()
    assert np.mean(err) < 0.03 and np.percentile(err, 95) < 0.08, (np.mean(err), np.percentile(err, 95))
    unshadowed = TexelSum(s, obj, env.shape[:2], visibility=False, samples=4)
    assert np.mean(np.abs(unshadowed.render(env)[sel] - r) / r) > 1.0
    # the fast path weighs the pairs with the same visibility
    weights = [np.array(LobeSum(v).geometry[2]) for v in (shadowed, unshadowed)]
    np.testing.assert_array_equal(weights[0] > 0, (weights[1] > 0) & shadowed.visibility.reshape(-1))


@pytest.mark.parametrize("light", ["point", "directional"])
def test_other_shapes_shadow_a_point_or_directional_light_as_in_monte_carlo(light):
    from test_scene_needs import LIGHT, TOWARDS, blocked_scene
    s = mi.load_dict(blocked_scene(light, "gold-metallic-paint", res=32))
    ref = np.array(mi.render(s, spp=256, seed=0)).reshape(-1, 3)
    obj = [sh for sh in s.shapes() if sh.id() == "object"][0]
    base = TexelSum(s, obj, (1, 1), visibility=True)
    ts = base.with_point(LIGHT) if light == "point" else base.with_directions(TOWARDS[None], [1.0])
    img = ts.render(np.full((1, 3), 40.0 if light == "point" else 3.0))
    r = ref[ts.pixels]
    lit = r.mean(axis=1) > 1e-2 * r.mean()
    facing = (ts.directions * ts.frames[2].T).sum(axis=1) > 0 if light == "point" else ts.frames[2].T @ TOWARDS > 0
    assert (facing & ~ts.visibility[:, 0]).sum() > 0.2 * facing.sum()       # the card shadows a good part
    assert np.all(img[~ts.visibility[:, 0]] == 0)
    assert np.median(np.abs(img[lit] - r[lit]) / r[lit]) < 0.02
    # the pixels it shadows are dark in the render too, but for the shadow's edge
    # (the render integrates each pixel's footprint, the texel sum its centre)
    dark = r.mean(axis=1) < 1e-2 * r.mean()
    assert np.mean(dark[facing & ~ts.visibility[:, 0]]) > 0.8 and np.mean(dark[facing & ts.visibility[:, 0]]) < 0.1


@pytest.mark.parametrize("light", ["point", "directional"])
def test_a_lights_shadow_rays_are_the_plain_shadow_test(light):
    """FootprintRays.shadow_test (the rays uploaded once, one kernel for every light)
    gives what the plain shadow_test gives with one lane a ray, light after light."""
    from test_scene_needs import LIGHT, TOWARDS, blocked_scene

    from mi_dsbrdf.inference.rays import shadow_test
    s = mi.load_dict(blocked_scene(light, res=24))
    obj = [sh for sh in s.shapes() if sh.id() == "object"][0]
    rays = TexelSum(s, obj, (1, 1), visibility=True, pixel_rays=2).footprint_rays
    n = rays.share.size
    for shift in (np.zeros(3), np.array([0.3, -0.2, 0.1])):
        if light == "point":
            position, direction = LIGHT + shift, None
            to = position[None, :] - rays.positions.T
            dirs = to / np.linalg.norm(to, axis=1, keepdims=True)
        else:
            position = None
            direction = (TOWARDS + shift) / np.linalg.norm(TOWARDS + shift)
            dirs = np.repeat(direction[None], n, axis=0)
        fast = rays.shadow_test(s, position, direction)
        plain, _ = shadow_test(s, rays.positions, rays.normals, rays.frames, dirs, position, n // 4, 4, [(0, 4)],
                               True)
        assert not fast.all() and fast.any()
        np.testing.assert_array_equal(fast, plain.reshape(-1))


def test_a_lights_shadows_are_traced_when_its_view_is_first_rendered(monkeypatch):
    """A light search re-aims views it never renders: a light's shadow rays run when
    its visibility is first needed, once, and a subset of a traced view takes its rows."""
    from test_scene_needs import LIGHT, blocked_scene

    from mi_dsbrdf.inference.rays import FootprintRays
    s = mi.load_dict(blocked_scene("point", res=24))
    obj = [sh for sh in s.shapes() if sh.id() == "object"][0]
    base = TexelSum(s, obj, (1, 1), visibility=True, pixel_rays=2)
    calls = []
    traced = FootprintRays.shadow_test

    def counted(self, *a, **k):
        calls.append(1)
        return traced(self, *a, **k)
    monkeypatch.setattr(FootprintRays, "shadow_test", counted)
    views = [base.with_point(LIGHT + [0.0, 0.1 * i, 0.0]) for i in range(5)]
    assert calls == []
    img = views[-1].render(np.full((1, 3), 40.0))
    assert len(calls) == 1 and not views[-1].visibility.all() and np.all(img[~views[-1].visibility.any(axis=1)] == 0)
    rows = np.arange(0, views[-1].n_pixels, 3)
    sub = views[-1].subset(rows)
    np.testing.assert_array_equal(sub.visibility, views[-1].visibility[rows])
    assert len(calls) == 1
