"""`mi-dsbrdf recover`: the result directory, and clear errors on bad input (nothing written)."""
import json
import math

import mitsuba as mi
import numpy as np
import pytest

from mi_dsbrdf.cli import main
from mi_dsbrdf.illumination import write_exr
from mi_dsbrdf.scenes import scene_path

RES = 32


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """A small directional-light scene and its image, rendered by Mitsuba with a library material."""
    d = tmp_path_factory.mktemp("case")
    xml = open(scene_path("sphere_directional")).read()
    xml = xml.replace('name="res" value="128"', 'name="res" value="%d"' % RES)
    scene_file = d / "scene.xml"
    scene_file.write_text(xml)
    truth = xml.replace('<bsdf type="dsbrdf" id="material"/>',
                        '<bsdf type="dsbrdf" id="material"><string name="material" value="gold-metallic-paint"/></bsdf>')
    (d / "truth.xml").write_text(truth)
    img = np.array(mi.render(mi.load_file(str(d / "truth.xml"), spp="64"), seed=0))
    write_exr(d / "image.exr", img)
    return d, img


def test_recover_writes_the_result_directory(case, tmp_path):
    d, _ = case
    out = tmp_path / "out"
    assert main(["recover", "--scene", str(d / "scene.xml"), "--image", str(d / "image.exr"), "--out", str(out),
                 "--rounds", "2", "--iters", "20"]) == 0
    for f in ("material.json", "light.json", "log.json", "input.png", "rerender.png", "residual.png"):
        assert (out / f).stat().st_size > 0, f
    light = json.loads((out / "light.json").read_text())
    truth = -np.array([-0.5, -0.5, -0.7071])
    truth /= np.linalg.norm(truth)
    assert math.degrees(math.acos(min(1.0, float(np.dot(light["direction"], truth))))) < 2.0
    log = json.loads((out / "log.json").read_text())
    assert any("Powell" in n for n in log["needs"]) and all(math.isfinite(r["neg_log_posterior"]) for r in log["rounds"])
    # the material loads into the plugin and evaluates
    from mi_dsbrdf import load_material
    v = load_material(str(out / "material.json")).eval([0.1], [0.2])
    assert v.shape == (1, 3) and np.all(np.isfinite(v)) and np.all(v > 0)


def _bad(tmp_path, img):
    p = tmp_path / "bad.exr"
    write_exr(p, img)
    return p


@pytest.mark.parametrize("make,message", [
    (lambda t, img: _bad(t, img[:16]), "is 32x16 but the scene's film is 32x32"),
    (lambda t, img: _bad(t, np.where(np.arange(RES)[:, None, None] == 3, np.nan, img)), "NaN/Inf"),
    (lambda t, img: _bad(t, img - 1.0), "negative"),
    (lambda t, img: _bad(t, np.zeros_like(img)), "black everywhere"),
    (lambda t, img: t / "missing.exr", "does not exist"),
    (lambda t, img: (t / "junk.exr").write_bytes(b"junk") and t / "junk.exr", "unreadable"),
])
def test_bad_images_are_clear_errors_and_write_nothing(case, tmp_path, capsys, make, message):
    d, img = case
    bad = make(tmp_path, img)
    out = tmp_path / "out"
    assert main(["recover", "--scene", str(d / "scene.xml"), "--image", str(bad), "--out", str(out)]) == 1
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_empty_mask_and_existing_output(case, tmp_path, capsys):
    d, img = case
    write_exr(tmp_path / "mask.exr", np.zeros_like(img))
    out = tmp_path / "out"
    assert main(["recover", "--scene", str(d / "scene.xml"), "--image", str(d / "image.exr"),
                 "--mask", str(tmp_path / "mask.exr"), "--out", str(out)]) == 1
    assert "is empty" in capsys.readouterr().err and not out.exists()
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert main(["recover", "--scene", str(d / "scene.xml"), "--image", str(d / "image.exr"), "--out", str(out)]) == 1
    assert "--force" in capsys.readouterr().err and (out / "keep.txt").read_text() == "mine"
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
