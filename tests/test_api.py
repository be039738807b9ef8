"""Issue 16: the Python API, the photograph workflow, and bad inputs as one-line errors
with nothing of the user's lost."""
import json
import math
import os

import mitsuba as mi
import numpy as np
import pytest

import mi_dsbrdf
from mi_dsbrdf.app.cli import main
from mi_dsbrdf.app.io import write_exr
from mi_dsbrdf.app.photo import fit_circle, sphere_scene
from mi_dsbrdf.app.scenes import SCENE_DIR, scene_path
from mi_dsbrdf.inference.images import read_image, srgb_to_linear

RES = 32
T = mi.ScalarTransform4f
#: the photograph's light, towards the light (world = the photo scene's frame: camera on +z)
SUN = np.array([0.5, 0.45, 0.74]) / np.linalg.norm([0.5, 0.45, 0.74])


def angle(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return math.degrees(math.acos(min(1.0, float(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))))


def one_line_error(capsys, *words):
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    for w in words:
        assert w in err, (w, err)
    return err


@pytest.fixture(scope="module")
def directional(tmp_path_factory):
    """The shipped directional-light scene at RES pixels and its image (gold-metallic-paint)."""
    d = tmp_path_factory.mktemp("directional")
    xml = open(scene_path("sphere_directional")).read().replace('name="res" value="128"', 'name="res" value="%d"' % RES)
    (d / "scene.xml").write_text(xml)
    truth = xml.replace('<bsdf type="dsbrdf" id="material"/>',
                        '<bsdf type="dsbrdf" id="material">'
                        '<string name="material" value="gold-metallic-paint"/></bsdf>')
    (d / "truth.xml").write_text(truth)
    img = np.array(mi.render(mi.load_file(str(d / "truth.xml")), spp=64, seed=0), dtype=np.float64)
    write_exr(d / "image.exr", img)
    return d, img


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    """A 'photograph': a sphere off the image's centre, seen by a distant camera,
    under a directional light, on black; its mask as an 8-bit PNG."""
    d = tmp_path_factory.mktemp("photo")
    W, H = 56, 48
    film = {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}}
    sensor = {"type": "orthographic", "film": film,
              "to_world": T().look_at(origin=[0.35, -0.2, 5], target=[0.35, -0.2, 0], up=[0, 1, 0])
              @ T().scale([1.6, 1.6, 1])}
    scene = {"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor,
             "object": {"type": "sphere", "bsdf": {"type": "dsbrdf", "material": "blue-acrylic"}},
             "light": {"type": "directional", "direction": [float(v) for v in -SUN],
                       "irradiance": {"type": "rgb", "value": 3.0}}}
    img = np.array(mi.render(mi.load_dict(scene), spp=64, seed=0), dtype=np.float64)
    coverage = np.array(mi.render(mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"}, "sensor": sensor,
        "object": {"type": "sphere", "emitter": {"type": "area", "radiance": 1.0}}}), spp=64))[..., 0]
    write_exr(d / "photo.exr", img)
    mi.Bitmap(((coverage > 0.5) * 255).astype(np.uint8)).write(str(d / "mask.png"))
    return d, img, coverage > 0.5, (W / 2 - 0.35 * W / 3.2, H / 2 - 0.2 * W / 3.2, W / 3.2)


# --- 1. the Python API ------------------------------------------------------------

@pytest.mark.slow
def test_api_recovers_from_arrays_and_saves_the_result_directory(directional, tmp_path):
    d, img = directional
    given = img.copy()
    rows = []
    cfg = mi_dsbrdf.Config(max_rounds=2, block_iters=15)
    r = mi_dsbrdf.recover(str(d / "scene.xml"), given, config=cfg, progress=rows.append)
    assert isinstance(r, mi_dsbrdf.Result) and isinstance(r.material, mi_dsbrdf.Material)
    np.testing.assert_array_equal(given, img)                # the caller's array is not touched
    truth = np.array([0.5, 0.5, 0.7071]) / np.linalg.norm([0.5, 0.5, 0.7071])
    assert r.light["type"] == "directional" and angle(r.light["direction"], truth) < 2.0
    assert r.illumination is None and rows and rows == r.log["rounds"]
    lit = r.used & (img.mean(axis=2) > 1e-2 * img.mean())
    assert np.median(np.abs(np.log(r.rerender[lit]) - np.log(img[lit]))) < 0.05
    out = r.save(tmp_path / "result")
    for f in ("material.json", "light.json", "log.json", "scene.xml", "rerender.png", "material.png"):
        assert (tmp_path / "result" / f).stat().st_size > 0, f
    assert json.loads((tmp_path / "result" / "light.json").read_text())["direction"] == r.light["direction"]
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".")]      # no staging folder left
    # an mi.Scene has no XML to rewrite: the directory has everything but scene.xml
    r2 = mi_dsbrdf.recover(mi.load_file(str(d / "scene.xml")), str(d / "image.exr"), config=cfg)
    r2.save(tmp_path / "from_scene")
    assert not (tmp_path / "from_scene" / "scene.xml").exists() and (tmp_path / "from_scene" / "material.json").exists()
    # ... and its rerender.png is the forward model's; a scene file's is Mitsuba's
    previews = [json.loads((tmp_path / f / "log.json").read_text())["rerender_png"] for f in ("from_scene", "result")]
    assert previews[0] == {"renderer": "forward model"} and previews[1]["renderer"] == "mitsuba"
    assert out == os.path.abspath(tmp_path / "result")


def test_api_bad_arguments_are_clear_errors(directional):
    d, img = directional
    with pytest.raises(mi_dsbrdf.InputError, match="scene must be"):
        mi_dsbrdf.recover(42, img)
    with pytest.raises(mi_dsbrdf.InputError, match="config must be"):
        mi_dsbrdf.recover(str(d / "scene.xml"), img, config={"max_rounds": 2})
    # a preset's name stands for its Config; an unknown name is a one-line error listing the names
    with pytest.raises(mi_dsbrdf.ConfigError, match="unknown preset 'quick': give one of default, fast$"):
        mi_dsbrdf.recover(str(d / "scene.xml"), img, config="quick")
    for name in ("default", "fast"):               # accepted: the film check comes next
        with pytest.raises(mi_dsbrdf.InputError, match="is 32x16 but the scene's film"):
            mi_dsbrdf.recover(str(d / "scene.xml"), img[:16], config=name)
    with pytest.raises(mi_dsbrdf.InputError, match="uint8 array"):
        mi_dsbrdf.recover(str(d / "scene.xml"), (np.clip(img, 0, 1) * 255).astype(np.uint8))
    with pytest.raises(mi_dsbrdf.InputError, match="is 32x16 but the scene's film is 32x32"):
        mi_dsbrdf.recover(str(d / "scene.xml"), img[:16])


def test_a_model_of_ones_own_is_the_one_inference_uses(directional):
    """recover(model=...) fits in that model's basis (here its first 4 of 10 bases)."""
    from mi_dsbrdf.model.model_file import ReflectanceModel, shipped_model
    d, img = directional
    arrays = dict(shipped_model().arrays)
    k = 4
    arrays.update(bases=arrays["bases"][:k], library_psi=arrays["library_psi"][:, :k],
                  prior_psi=arrays["prior_psi"][:, :k], gmm_means=arrays["gmm_means"][:, :k],
                  gmm_covariances=arrays["gmm_covariances"][:, :k, :k])
    cfg = mi_dsbrdf.Config(max_rounds=1, block_iters=5)
    r = mi_dsbrdf.recover(str(d / "scene.xml"), img, config=cfg, model=ReflectanceModel(arrays))
    assert r.material.psi.shape == (k,) and any("%d bases" % k in n for n in r.log["needs"])
    assert mi_dsbrdf.recover(str(d / "scene.xml"), img, config=cfg).material.psi.shape == (10,)


# --- 2. the photograph workflow ---------------------------------------------------

def test_sphere_outline_fit_and_scene_geometry(photo):
    d, img, mask, (cx, cy, r) = photo
    fx, fy, fr = fit_circle(mask)
    assert abs(fx - cx) < 0.3 and abs(fy - cy) < 0.3 and abs(fr - r) < 0.3
    # the built scene sees the sphere where the photograph has it, orthographic and perspective
    for fov in (None, 30.0):
        s = sphere_scene(img.shape[1::-1], (fx, fy, fr), fov=fov)
        s["object"] = {"type": "sphere", "emitter": {"type": "area", "radiance": 1.0}}
        del s["light"]
        seen = np.array(mi.render(mi.load_dict(s), spp=64))[..., 0] > 0.5
        assert (seen & mask).sum() / (seen | mask).sum() > 0.97, fov
    # a disc cut by the frame is fitted from its outline inside the frame
    yy, xx = np.mgrid[0:48, 0:48] + 0.5
    cut = (xx - 44.0) ** 2 + (yy - 20.0) ** 2 <= 15.0 ** 2
    np.testing.assert_allclose(fit_circle(cut), (44.0, 20.0, 15.0), atol=0.6)
    square = np.zeros((48, 48), bool)
    square[8:40, 8:40] = True
    with pytest.raises(mi_dsbrdf.InputError, match="mask's outline is not a circle"):
        fit_circle(square)


def test_photograph_of_a_sphere_recovered_end_to_end(photo, tmp_path, capsys):
    """An image and a mask, no scene XML: the light comes back within a few degrees,
    and the written scene.xml re-renders the photograph."""
    d, img, mask, _ = photo
    out = tmp_path / "out"
    assert main(["recover", "--sphere", "--image", str(d / "photo.exr"), "--mask", str(d / "mask.png"),
                 "--light", "directional", "--out", str(out), "--max-rounds", "2", "--block-iters", "15"]) == 0
    assert "orthographic camera" in capsys.readouterr().out
    light = json.loads((out / "light.json").read_text())
    assert angle(light["direction"], SUN) < 3.0
    rerender = np.array(mi.render(mi.load_file(str(out / "scene.xml")), spp=64, seed=1))
    lit = mask & (img.mean(axis=2) > 1e-2 * img[mask].mean())
    assert np.median(np.abs(np.log(rerender[lit] + 1e-6) - np.log(img[lit] + 1e-6))) < 0.1
    # without a mask the outline is where the image turns black: here that is the
    # terminator on one side, which is not a circle; refused, naming the fix
    assert main(["recover", "--sphere", "--image", str(d / "photo.exr"), "--out", str(tmp_path / "o")]) == 1
    one_line_error(capsys, "not a circle", "give a mask")
    # a sphere lit all around (a probe photograph) is fitted without one
    from mi_dsbrdf.app.photo import photo_scene
    lit_all_round = np.where(mask[..., None], img + 0.05, 0.0)
    _, circle = photo_scene(lit_all_round)
    np.testing.assert_allclose(circle, fit_circle(mask), atol=0.1)   # two fits: the outline and the mask
    # --sphere and --scene together, or neither, is a usage error in one line
    assert main(["recover", "--image", str(d / "photo.exr"), "--out", str(tmp_path / "o")]) == 1
    one_line_error(capsys, "--sphere")


def test_eight_bit_images_are_refused_or_linearised(tmp_path, directional, capsys):
    d, img = directional
    png = tmp_path / "photo.png"
    values = (np.linspace(0, 1, RES * RES * 3).reshape(RES, RES, 3) * 255).round().astype(np.uint8)
    mi.Bitmap(values).write(str(png))
    assert main(["recover", "--scene", str(d / "scene.xml"), "--image", str(png), "--out", str(tmp_path / "o")]) == 1
    one_line_error(capsys, "8-bit", "--srgb")
    assert not (tmp_path / "o").exists()
    np.testing.assert_allclose(read_image(png, srgb=True), srgb_to_linear(values / 255.0), atol=1e-6)
    np.testing.assert_allclose(srgb_to_linear([0.0, 0.5, 1.0]), [0.0, 0.21404, 1.0], atol=1e-5)


# --- 3. bad inputs ----------------------------------------------------------------

def test_spot_light_is_a_scene_error(directional, tmp_path, capsys):
    d, img = directional
    xml = (d / "scene.xml").read_text()
    start, end = xml.index("<emitter"), xml.index("</emitter>") + len("</emitter>")
    spot = xml[:start] + '<emitter type="spot"><transform name="to_world"><lookat origin="2, 2, 3" ' \
        'target="0, 0, 0" up="0, 1, 0"/></transform></emitter>' + xml[end:]
    (tmp_path / "spot.xml").write_text(spot)
    assert main(["recover", "--scene", str(tmp_path / "spot.xml"), "--image", str(d / "image.exr"),
                 "--out", str(tmp_path / "o")]) == 1
    one_line_error(capsys, "SpotLight", "point light")


@pytest.mark.slow
def test_output_folders_never_lose_anything(directional, tmp_path, capsys, monkeypatch):
    d, img = directional
    args = ["recover", "--scene", str(d / "scene.xml"), "--image", str(d / "image.exr"), "--max-rounds", "1",
            "--block-iters", "3"]
    # --out naming a file, or a folder that cannot be made
    (tmp_path / "file").write_text("mine")
    assert main(args + ["--out", str(tmp_path / "file")]) == 1
    one_line_error(capsys, "is a file")
    assert (tmp_path / "file").read_text() == "mine"
    assert main(args + ["--out", "/proc/mi-dsbrdf-out"]) == 1
    one_line_error(capsys, "cannot write")
    # --force into the scene's own folder would overwrite the user's scene.xml: refused
    before = (d / "scene.xml").read_bytes()
    assert main(args + ["--out", str(d), "--force"]) == 1
    one_line_error(capsys, "holds the input")
    assert (d / "scene.xml").read_bytes() == before
    # --force over an earlier result, interrupted: the earlier result stays whole
    out = tmp_path / "result"
    assert main(args + ["--out", str(out)]) == 0
    old = {p.name: p.read_bytes() for p in out.iterdir()}
    import mi_dsbrdf.app.result as result_module

    def interrupted(*a, **k):
        raise KeyboardInterrupt
    monkeypatch.setattr(result_module, "material_preview", interrupted)
    capsys.readouterr()
    assert main(args + ["--out", str(out), "--force"]) == 130
    assert capsys.readouterr().err.strip().splitlines()[-1] == "mi-dsbrdf: interrupted; nothing written"
    assert {p.name: p.read_bytes() for p in out.iterdir()} == old
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".")]
    monkeypatch.undo()
    # --force over a folder that holds something else than a result: refused
    (out / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main(args + ["--out", str(out), "--force"]) == 1
    one_line_error(capsys, "not a result", "notes.txt")


def test_bad_masks_and_too_few_pixels(directional, tmp_path, capsys):
    d, img = directional
    base = ["recover", "--scene", str(d / "scene.xml"), "--image", str(d / "image.exr")]
    nan = np.ones_like(img)
    nan[5, 7] = np.nan
    write_exr(tmp_path / "nan.exr", nan)
    assert main(base + ["--mask", str(tmp_path / "nan.exr"), "--out", str(tmp_path / "o")]) == 1
    one_line_error(capsys, "mask", "NaN/Inf", "(7, 5)")
    assert main(base + ["--mask", str(tmp_path / "missing.png"), "--out", str(tmp_path / "o")]) == 1
    one_line_error(capsys, "mask", "does not exist")
    # a 3-pixel mask gives a confident, wrong light: refused, and nothing is written
    three = np.zeros_like(img)
    three[15:16, 14:17] = 1.0
    write_exr(tmp_path / "three.exr", three)
    assert main(base + ["--mask", str(tmp_path / "three.exr"), "--out", str(tmp_path / "o")]) == 1
    one_line_error(capsys, "only 3 usable pixels", "at least 100")
    assert not (tmp_path / "o").exists()
    assert main(base + ["--max-rounds", "0", "--out", str(tmp_path / "o")]) == 1
    one_line_error(capsys, "--max-rounds must be")


def test_relight_in_the_users_own_scene_and_bad_relight_inputs(tmp_path, capsys):
    own = tmp_path / "room.xml"
    own.write_text("""<scene version="3.0.0">
    <integrator type="path"/>
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 1, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="16"/></film></sensor>
    <bsdf type="diffuse" id="grey"/>
    <shape type="sphere" id="ball"><ref id="grey"/></shape>
    <shape type="rectangle" id="floor"><ref id="grey"/>
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="5"/><translate y="-1"/></transform></shape>
    <emitter type="point"><point name="position" value="2, 3, 2"/><rgb name="intensity" value="20"/></emitter>
</scene>""")
    out = tmp_path / "relit.exr"
    assert main(["relight", "gold-metallic-paint", "--scene", str(own), "--shape-id", "ball", "--out", str(out),
                 "--spp", "16"]) == 0
    relit = np.array(mi.Bitmap(str(out)))
    assert relit.shape == (16, 24, 3) and np.isfinite(relit).all() and (tmp_path / "relit.png").exists()
    plain = np.array(mi.render(mi.load_file(str(own)), spp=16, seed=0))
    ball, floor = relit[8, 12], relit[15, 2]
    assert ball[0] > 1.3 * ball[2]                       # gold on the ball, not grey
    np.testing.assert_allclose(floor, plain[15, 2], rtol=0.5)   # the shared BSDF stays grey on the floor
    assert plain[8, 12, 0] < 1.1 * plain[8, 12, 2]
    sky = os.path.join(SCENE_DIR, "textures", "sky.exr")
    bad_json = tmp_path / "bad.json"
    bad_json.write_text('{"format": "mi-dsbrdf/material", "log_kappa": [[1, 2]]}')
    nan_map = tmp_path / "nan.exr"
    m = np.ones((8, 16, 3), np.float32)
    m[2, 3] = np.inf
    write_exr(nan_map, m)
    png_map = tmp_path / "sky.png"
    mi.Bitmap(np.full((8, 16, 3), 128, np.uint8)).write(str(png_map))
    for args, words in (
            ([str(bad_json), "--envmap", sky], ("bad.json",)),
            (["gold-metallic-paint", "--envmap", str(nan_map)], ("NaN/Inf", "(3, 2)")),
            (["gold-metallic-paint", "--envmap", sky, "--res", "0"], ("res must be",)),
            (["gold-metallic-paint", "--scene", str(own), "--shape-id", "table"], ("no shape with id", "'ball'")),
            (["gold-metallic-paint", "--scene", str(own)], ("--shape-id",)),
            (["gold-metallic-paint", "--envmap", sky, "--shape-id", "ball"], ("--shape-id names a shape of --scene",)),
            (["gold-metallic-paint", "--envmap", str(png_map)], ("8-bit display values", "(EXR/HDR)"))):
        assert main(["relight"] + args + ["--out", str(tmp_path / "x.exr")]) == 1
        one_line_error(capsys, *words)
        assert not (tmp_path / "x.exr").exists()
    assert main(["relight", "gold-metallic-paint", "--envmap", str(png_map), "--out", str(tmp_path / "x.exr")]) == 1
    assert "--srgb" not in capsys.readouterr().err          # relight has no --srgb: not offered


def test_all_unmeasured_merl_file_is_a_clear_error(tmp_path, capsys):
    n = 90 * 90 * 180
    with open(tmp_path / "empty.binary", "wb") as f:
        np.array([90, 90, 180], np.int32).tofile(f)
        np.full(3 * n, -1.0).tofile(f)
    from mi_dsbrdf.brdf.measured import MeasuredBRDF
    with pytest.raises(mi_dsbrdf.MeasuredFileError, match="no measured value"):
        MeasuredBRDF.from_binary(tmp_path / "empty.binary")


@pytest.mark.slow
def test_grey_image_with_clipped_highlights_comes_back_grey(directional):
    """A grey image with its highlight clipped: the plateau is left out and the
    lobes start (and stay) grey, not green."""
    d, img = directional
    grey = np.repeat(img.mean(axis=2, keepdims=True), 3, axis=2)
    grey = np.minimum(grey, 0.5 * grey.max())
    r = mi_dsbrdf.recover(str(d / "scene.xml"), grey, config=mi_dsbrdf.Config(max_rounds=2, block_iters=15))
    assert any("colour pass: no" in n for n in r.log["needs"])
    np.testing.assert_allclose(r.material.chromaticity, 1 / 3, atol=0.02)
    assert (~r.used & (grey[..., 0] >= grey.max())).any() and not (r.used & (grey[..., 0] >= grey.max())).any()


def test_render_and_demo_refuse_a_file_as_output_folder(tmp_path, capsys):
    (tmp_path / "file").write_text("mine")
    assert main(["render", "sphere_directional", "--out", str(tmp_path / "file")]) == 1
    one_line_error(capsys, "is a file")
    assert main(["demo", "--out", str(tmp_path / "file")]) == 1
    one_line_error(capsys, "is a file")
    assert (tmp_path / "file").read_text() == "mine"
