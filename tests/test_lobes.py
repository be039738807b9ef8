"""The fast DSBRDF forward model (inference/lobes.py) against the plain reference:
the plugin evaluated through TexelSum, differentiated by Dr.Jit's forward-mode AD."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_dsbrdf.app.scenes import sphere_scene
from mi_dsbrdf.brdf.dsbrdf import KAPPA_MAX, Material
from mi_dsbrdf.evaluation.experiment import dsbrdf_bsdf, texels
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.inference.latlong import procedural_sky
from mi_dsbrdf.inference.lobes import LobeSum
from mi_dsbrdf.inference.reflectance import psi_jacobian
from mi_dsbrdf.model import model_file as model_data


def relative(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.parametrize("name", ["gold-metallic-paint", "chrome", "pink-felt"])
def test_transport_matches_the_plugin(name):
    material = model_data.shipped_model().library_material(name)
    ts = texels(dsbrdf_bsdf(material), 24, (8, 16))
    fast = LobeSum(ts)
    T = ts.transport()
    assert T.max() > 0 and relative(fast.transport(material), T) < 1e-5
    L = procedural_sky(8, 16).reshape(-1, 3)
    assert relative(fast.render(material, L), ts.render(L)) < 1e-5
    # a subset of the pixels, and the same view under a point light
    rows = np.arange(0, ts.n_pixels, 7)
    assert relative(fast.subset(rows).transport(material), T[:, rows]) < 1e-5
    pos = [1.5, 2.0, 3.0]
    ref = ts.with_point(pos).render(np.ones((1, 3)))
    assert ref.max() > 0 and relative(fast.with_point(pos).render(material, np.ones((1, 3))), ref) < 1e-5


def test_transport_with_visibility_matches_the_plugin():
    material = model_data.shipped_model().library_material("blue-acrylic")
    ts = texels(dsbrdf_bsdf(material), 24, (8, 16), shape="torus")
    assert ts.visibility is not None and not ts.visibility.all()
    assert relative(LobeSum(ts).transport(material), ts.transport()) < 1e-5


def test_jacobian_matches_forward_mode_ad():
    model = model_data.shipped_model()
    psi = np.linspace(-0.6, 0.6, model.basis.n_bases)
    psi[2] = 5.0                       # far out: a control value clamps, its columns must vanish
    chroma = np.array([[0.5, 0.3, 0.2], [0.2, 0.3, 0.5], [0.3, 0.4, 0.3]])
    props = {"type": "dsbrdf", "psi": " ".join(map(str, psi))}
    props.update({"chromaticity_%d" % r: " ".join(map(str, chroma[r])) for r in range(3)})
    ts = texels(props, 16, (8, 16))
    params = mi.traverse(ts.bsdf)
    dr.enable_grad(params["psi"])
    dr.enable_grad(params["chromaticity"])
    params.update()
    L = procedural_sky(8, 16).reshape(-1, 3)
    image, J = ts.reflectance_jacobian(L, params, ["psi", "chromaticity"])
    material = Material.from_basis(model.basis, psi, chroma)
    ctrl = model.basis.control_values(psi)
    assert (ctrl[:, 0] > np.log(KAPPA_MAX)).any() or (ctrl[:, 1] > np.log(1e6)).any() or \
        (ctrl[:, 1] < np.log(1e-4)).any()
    jac = LobeSum(ts).jacobian(material, L)
    assert relative(jac.image, image) < 1e-5
    k = model.basis.n_bases
    assert relative(psi_jacobian(model.basis, psi, jac.controls).transpose(2, 1, 0), J[:, :, :k]) < 1e-4
    ref_chroma = J[:, :, k:].reshape(-1, 3, 3, 3)           # (P, channel, lobe, chromaticity channel)
    assert relative(jac.chromaticity, np.stack([ref_chroma[:, c, :, c].T for c in range(3)], axis=1)) < 1e-5
    off_diagonal = [ref_chroma[:, c, :, k] for c in range(3) for k in range(3) if c != k]
    assert np.abs(off_diagonal).max() == 0


@pytest.mark.parametrize("light", ["point", "directional"])
def test_pixel_rays_match_the_plugin(light):
    """3 x 3 rays a pixel under a point or a directional light: the fast path's
    values and Jacobian against the plugin's, on all pixels and on a subset."""
    model = model_data.shipped_model()
    psi = np.linspace(-0.4, 0.4, model.basis.n_bases)
    chroma = np.array([[0.5, 0.3, 0.2], [0.2, 0.3, 0.5], [0.3, 0.4, 0.3]])
    props = {"type": "dsbrdf", "psi": " ".join(map(str, psi))}
    props.update({"chromaticity_%d" % r: " ".join(map(str, chroma[r])) for r in range(3)})
    base = texels(props, 16, pixel_rays=3)
    ts = base.with_point([1.5, 2.0, 3.0]) if light == "point" else base.with_directions([[0.6, 0.3, 0.74]], [1.0])
    assert ts.n_directions == 9 and ts.n_texels == 1 and ts.footprint_rays.share.size == 9 * ts.n_pixels
    material = Material.from_basis(model.basis, psi, chroma)
    L = np.full((1, 3), 7.0)
    fast = LobeSum(ts)
    ref = ts.render(L)
    assert ref.max() > 0 and relative(fast.render(material, L), ref) < 1e-5
    rows = np.arange(0, ts.n_pixels, 5)
    assert relative(fast.subset(rows).render(material, L), ref[rows]) < 1e-5
    params = mi.traverse(ts.bsdf)
    dr.enable_grad(params["psi"])
    params.update()
    image, J = ts.reflectance_jacobian(L, params, ["psi"])
    jac = fast.jacobian(material, L)
    assert relative(jac.image, image) < 1e-5
    assert relative(psi_jacobian(model.basis, psi, jac.controls).transpose(2, 1, 0), J) < 1e-4
    # the centre ray alone is another image (the rays are not a copy of it)
    centre = texels(props, 16)
    centre = centre.with_point([1.5, 2.0, 3.0]) if light == "point" else centre.with_directions([[0.6, 0.3, 0.74]],
                                                                                               [1.0])
    assert relative(centre.render(L), ref) > 1e-3


def test_jacobian_stays_finite_for_the_sharpest_lobe_under_a_sun():
    """kappa at its bound (e^{60} at the peak) under a 1e5 sun: float32 products
    would overflow without the scaling of the light and the order of the factors."""
    log_kappa = np.full((1, 6), np.log(KAPPA_MAX))
    material = Material(log_kappa, np.full((1, 6), np.log(1e4)), [[1 / 3, 1 / 3, 1 / 3]])
    s = sphere_scene({"type": "dsbrdf"}, 16)
    ts = TexelSum(s, s.shapes()[0], (16, 32))
    L = np.full((16 * 32, 3), 1e-2)
    L[100] = 1e5
    jac = LobeSum(ts).jacobian(material, L)
    for a in (jac.image, jac.controls, jac.chromaticity):
        assert np.all(np.isfinite(a))
    assert jac.image.max() > 1e3


def test_unseen_texels_come_from_geometry_not_from_the_material():
    """Texels straight behind the sphere are unseen, none in front is; a lobe of
    kappa e^60 (whose peak dwarfs every other entry of the transport) hides none."""
    from mi_dsbrdf.inference.latlong import latlong_directions
    s = sphere_scene({"type": "dsbrdf"}, 16)
    view = LobeSum(TexelSum(s, s.shapes()[0], (16, 32)))
    d = latlong_directions(16, 32).reshape(-1, 3)
    assert view.unseen.any() and np.all(d[view.unseen, 2] < 0) and not view.unseen[d[:, 2] > 0].any()
    sharp = Material(np.full((1, 6), np.log(KAPPA_MAX)), np.full((1, 6), np.log(1e5)), [[1 / 3, 1 / 3, 1 / 3]])
    peak = view.transport(sharp).max(axis=(0, 1))          # the old test: relative to the largest entry
    assert (peak <= 1e-6 * peak.max()).sum() > 2 * view.unseen.sum()


def test_texel_samples_integrate_each_texel_over_its_footprint(monkeypatch):
    """samples=s lights each texel from the s x s directions of the (sH x sW) grid
    inside it: the same image as that finer map with the radiance repeated, by the
    plugin (TexelSum) and by the fast path (LobeSum, value and Jacobian); a texel
    is unseen only when all its directions are."""
    material = model_data.shipped_model().library_material("chrome")
    ts = texels(dsbrdf_bsdf(material), 24, (8, 16))
    coarse, fine = ts.with_map_size((4, 8), samples=2), ts.with_map_size((8, 16))
    assert (coarse.n_texels, coarse.n_directions, fine.n_texels) == (32, 128, 128)
    L = procedural_sky(4, 8)
    L_fine = np.repeat(np.repeat(L, 2, axis=0), 2, axis=1)
    ref = fine.render(L_fine)
    assert ref.max() > 0 and relative(coarse.render(L), ref) < 1e-5
    import mi_dsbrdf.inference.forward as forward
    monkeypatch.setattr(forward, "CHUNK", 10 * coarse.n_pixels)       # several chunks of whole texels
    assert relative(coarse.render(L), ref) < 1e-5
    monkeypatch.undo()
    assert relative(LobeSum(coarse).render(material, L.reshape(-1, 3)), ref) < 1e-5
    a = LobeSum(coarse).jacobian(material, L.reshape(-1, 3))
    b = LobeSum(fine).jacobian(material, L_fine.reshape(-1, 3))
    assert relative(a.image, b.image) < 1e-5 and relative(a.controls, b.controls) < 1e-5
    assert relative(a.chromaticity, b.chromaticity) < 1e-5
    unseen_fine = LobeSum(fine).unseen.reshape(4, 2, 8, 2).transpose(0, 2, 1, 3).reshape(32, 4)
    assert np.array_equal(LobeSum(coarse).unseen, unseen_fine.all(axis=1))
    # the centres of a chrome sphere's coarse texels miss what the integral sees
    assert relative(ts.with_map_size((4, 8)).render(L), ref) > 0.05
    with pytest.raises(ValueError, match="samples"):
        ts.with_map_size((4, 8), samples=0)


@pytest.mark.slow
def test_transport_shadowed_by_another_shape_matches_the_plugin():
    """A card shadows the sphere: the fast path weighs each pair with the plain
    reference's visibility, under a map, a point and a directional light."""
    from test_scene_needs import LIGHT, TOWARDS, blocked_scene
    material = model_data.shipped_model().library_material("blue-acrylic")
    d = blocked_scene("point", res=24)
    d["object"]["bsdf"] = dsbrdf_bsdf(material)
    del d["light"]
    scene = mi.load_dict(d)
    ts = TexelSum(scene, [s for s in scene.shapes() if s.id() == "object"][0], (8, 16), visibility=True)
    fast = LobeSum(ts)
    assert not ts.visibility.all() and relative(fast.transport(material), ts.transport()) < 1e-5
    for view, lobes in ((ts.with_point(LIGHT), fast.with_point(LIGHT)),
                        (ts.with_directions(TOWARDS[None], [1.0]), fast.with_directions(TOWARDS[None], [1.0]))):
        ref = view.render(np.ones((1, 3)))
        assert not view.visibility.all() and relative(lobes.render(material, np.ones((1, 3))), ref) < 1e-5
