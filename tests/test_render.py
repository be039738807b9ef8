"""Rendering with the plugins: scenes, gradients, sampling strategies agree, model files."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_dsbrdf import ModelError
from mi_dsbrdf.model.model_file import load_model
from mi_dsbrdf.app.scenes import SCENES, scene_path


def write_model(path, k=3, lobes=2, **override):
    rng = np.random.default_rng(0)
    arrays = dict(knots=np.array([0, 0, 0, np.pi / 8, np.pi / 4, 3 * np.pi / 8, np.pi / 2, np.pi / 2, np.pi / 2]),
                  mean=np.stack([np.stack([np.full(6, np.log(0.5)), np.zeros(6)]),
                                 np.stack([np.full(6, np.log(3.0)), np.full(6, np.log(100.0))])])[:lobes],
                  bases=rng.normal(0, 0.2, (k, lobes, 2, 6)),
                  library_names=np.array(["test-paint"]), library_psi=np.zeros((1, k)),
                  library_chroma=np.full((1, lobes, 3), 1 / 3))
    arrays.update(override)
    np.savez(path, **arrays)
    return path


def small_scene(bsdf, integrator="prb"):
    return mi.load_dict({
        "type": "scene", "integrator": {"type": integrator, **({"max_depth": 2} if integrator == "prb" else {})},
        "sensor": {"type": "perspective", "fov": 32,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 24, "height": 24, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 8}},
        "object": {"type": "sphere", "bsdf": bsdf},
        "emitter": {"type": "envmap", "bitmap": mi.Bitmap(np.full((8, 16, 3), 0.5, np.float32)
                                                          + np.linspace(0, 1, 16, dtype=np.float32)[None, :, None])},
    })


@pytest.mark.parametrize("kind", ["explicit", "basis"])
def test_gradients_of_every_parameter_finite_and_nonzero(kind, tmp_path):
    if kind == "basis":
        bsdf = {"type": "dsbrdf", "model": str(write_model(tmp_path / "model.npz")), "psi": "0.1 -0.2 0.3",
                "chromaticity_0": "0.5 0.3 0.2", "chromaticity_1": "0.2 0.3 0.5"}
    else:
        bsdf = {"type": "dsbrdf", "lobes": 2, "kappa_0": "0.5", "gamma_0": "1", "kappa_1": "1 2 3 4 5 6",
                "gamma_1": "80", "chromaticity_0": "0.5 0.3 0.2"}
    scene = small_scene(bsdf)
    params = mi.traverse(scene)
    keys = [k for k in params.keys() if k.startswith("object.bsdf.")] + ["emitter.data"]
    assert len(keys) == (3 if kind == "basis" else 4)
    opt = mi.ad.Adam(lr=0.01)
    for k in keys:
        opt[k] = params[k]
    params.update(opt)
    img = mi.render(scene, params, spp=8, seed=1)
    dr.backward(dr.mean(img))
    for k in keys:
        g = np.array(dr.grad(opt[k]))
        assert np.all(np.isfinite(g)), k
        assert np.any(g != 0), "zero gradient for %s" % k


def test_bsdf_sampling_and_emitter_sampling_agree():
    """Two unbiased estimators of the same image: BSDF sampling only vs emitter sampling only."""
    bsdf = {"type": "dsbrdf", "lobes": 2, "kappa_0": "0.6", "gamma_0": "1", "kappa_1": "3", "gamma_1": "40",
            "chromaticity_0": "0.5 0.3 0.2"}
    means = []
    for strategy in ({"bsdf_samples": 1, "emitter_samples": 0}, {"bsdf_samples": 0, "emitter_samples": 1}):
        scene = small_scene(bsdf, integrator="direct")
        integrator = mi.load_dict(dict(type="direct", **strategy))
        img = np.array(mi.render(scene, integrator=integrator, spp=512, seed=3))
        means.append(img.mean(axis=(0, 1)))
    np.testing.assert_allclose(means[0], means[1], rtol=0.01)


@pytest.mark.parametrize("name", list(SCENES))
def test_shipped_scenes_render(name):
    scene = mi.load_file(scene_path(name), res="32", spp="4")
    img = np.array(mi.render(scene))
    assert img.shape == (32, 32, 3) and np.all(np.isfinite(img)) and img.max() > 0
    assert type(scene.shapes()[0].bsdf()).__name__ == "DSBRDF"


def test_scene_with_merl_material_renders(tmp_path):
    from mi_dsbrdf.brdf.measured import MeasuredBRDF
    from tests_support import glossy_function
    path = tmp_path / "m.binary"
    MeasuredBRDF.from_function(glossy_function, name="m").to_binary(path)
    img = np.array(mi.render(small_scene({"type": "merl", "filename": str(path)}, "direct")))
    assert np.all(np.isfinite(img)) and img.max() > 0


def test_model_file_library_and_errors(tmp_path):
    model = load_model(write_model(tmp_path / "m.npz"))
    assert model.basis.n_bases == 3 and "test-paint" in model.library
    m = model.library_material("test-paint")
    np.testing.assert_allclose(m.log_kappa, model.basis.mean[:, 0])
    with pytest.raises(ModelError, match="lacks the arrays bases"):
        p = tmp_path / "a.npz"
        np.savez(p, knots=np.zeros(9), mean=np.zeros((2, 2, 6)))
        load_model(p)
    with pytest.raises(ModelError, match="bases must have shape"):
        load_model(write_model(tmp_path / "b.npz", bases=np.zeros((3, 2, 2, 5))))
    with pytest.raises(ModelError, match="library_psi must be"):
        load_model(write_model(tmp_path / "c.npz", library_psi=np.zeros((1, 2))))
    (tmp_path / "d.npz").write_bytes(b"not an npz")
    with pytest.raises(ModelError, match="unreadable"):
        load_model(tmp_path / "d.npz")
    with pytest.raises(RuntimeError, match="psi needs 3 values"):
        mi.load_dict({"type": "dsbrdf", "model": str(tmp_path / "m.npz"), "psi": "0.1"})
