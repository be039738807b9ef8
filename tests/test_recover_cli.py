"""`mi-dsbrdf recover`: the result directory, and clear errors on bad input (nothing written)."""
import json
import math
import os

import mitsuba as mi
import numpy as np
import pytest

from mi_dsbrdf.app.cli import main
from mi_dsbrdf.app.io import write_exr
from mi_dsbrdf.inference.latlong import TEXEL_BLOCK
from mi_dsbrdf.app.scenes import scene_path

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
                        '<bsdf type="dsbrdf" id="material">'
                        '<string name="material" value="gold-metallic-paint"/></bsdf>')
    (d / "truth.xml").write_text(truth)
    img = np.array(mi.render(mi.load_file(str(d / "truth.xml"), spp="64"), seed=0))
    write_exr(d / "image.exr", img)
    return d, img


def test_recover_writes_the_result_directory(case, tmp_path, capsys):
    d, img = case
    out = tmp_path / "out"
    assert main(["recover", "--scene", str(d / "scene.xml"), "--image", str(d / "image.exr"), "--out", str(out),
                 "--max-rounds", "2", "--block-iters", "20"]) == 0
    # progress: what the scene needs first, then one bar per pass with its total, the re-render announced
    printed = capsys.readouterr()
    lines = printed.out.splitlines()
    assert lines[0].startswith("  light: directional") and lines[-1].startswith("recovered in")
    assert any(line.startswith("  re-rendering ") and " pixels" in line for line in lines)
    bars = printed.err.replace("\r", "\n")
    assert "recover: light search" in bars and "/8 [" in bars
    assert "recover: light pass" in bars and "/2 [" in bars and "<" in bars.split("recover: light pass")[-1]
    for f in ("material.json", "light.json", "log.json", "scene.xml", "input.png", "rerender.png", "residual.png",
              "material.png"):
        assert (out / f).stat().st_size > 0, f
    light = json.loads((out / "light.json").read_text())
    truth = -np.array([-0.5, -0.5, -0.7071])
    truth /= np.linalg.norm(truth)
    assert math.degrees(math.acos(min(1.0, float(np.dot(light["direction"], truth))))) < 2.0
    log = json.loads((out / "log.json").read_text())
    assert any("Powell" in n for n in log["needs"])
    assert all(math.isfinite(r["neg_log_posterior"]) for r in log["rounds"])
    import dataclasses

    import mi_dsbrdf
    assert log["version"] == mi_dsbrdf.__version__
    assert mi_dsbrdf.Config(**dict(log["config"], map_size=tuple(log["config"]["map_size"]))) \
        == mi_dsbrdf.Config(max_rounds=2, block_iters=20)
    assert set(log["config"]) == {f.name for f in dataclasses.fields(mi_dsbrdf.Config)}
    assert log["image_size"] == [RES, RES] and log["map_size"] is None        # a directional light: no map
    assert log["image_size"] == log["working_grid"]["image"]                    # [H, W] both
    assert list(log["stages"]) == ["checks", "inference", "re-render", "observed directions", "save"]
    assert 0 < log["residual"] < 0.3              # relative L1, led by the highlight
    # gold's highlight is the photograph's: the posterior does not doubt it, nothing is flagged
    from mi_dsbrdf.inference.uncertainty import HIGHLIGHT_DOUBT
    assert 0 <= log["highlight_doubt"] < HIGHLIGHT_DOUBT and log["flags"] == []
    for stage in log["stages"].values():
        assert stage["seconds"] >= 0 and 50 < stage["peak_memory_mb"] < 1e5
    # scene.xml re-renders the input with the recovered material and light, from any working directory
    rerender = np.array(mi.render(mi.load_file(str(out / "scene.xml")), spp=64, seed=1))
    # (log with the likelihood's offset: at 64 spp a dark channel of a lit pixel can render as 0)
    lit, e = img.mean(axis=2) > 1e-2 * img.mean(), 1e-3 * img.mean()
    assert np.median(np.abs(np.log(rerender[lit] + e) - np.log(img[lit] + e))) < 0.05
    # rerender.png is scene.xml as Mitsuba renders it, within a few per cent of the forward model's
    from mi_dsbrdf.app.io import srgb_bitmap
    preview = log["rerender_png"]
    assert preview["renderer"] == "mitsuba" and preview["size"] == [RES, RES] and preview["spp"] >= 4
    assert preview["mitsuba_vs_rerender"] < 0.03
    ours = np.array(srgb_bitmap(mi.render(mi.load_file(str(out / "scene.xml")), spp=preview["spp"], seed=0)),
                    dtype=np.int16)
    assert np.abs(np.array(mi.Bitmap(str(out / "rerender.png")), dtype=np.int16) - ours).max() <= 1
    # the material loads into the plugin and evaluates
    from mi_dsbrdf import load_material
    found = load_material(str(out / "material.json"))
    v = found.eval([0.1], [0.2])
    assert v.shape == (1, 3) and np.all(np.isfinite(v)) and np.all(v > 0)
    # it records where the image looked: a lit sphere shows the highlight's theta_h, not grazing theta_h
    seen = found.observed(np.radians([1.0, 89.0]), np.radians([30.0, 30.0]))
    assert seen is not None and np.all(seen >= 0) and seen[1] == 0.0


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


@pytest.mark.slow
def test_point_light_and_envmap_scenes(tmp_path):
    """A point-light scene gets a position; an envmap scene an illumination map, its
    preview and a scene.xml with the map, from a mesh scene given by a relative path."""
    xml = open(scene_path("sphere_point")).read().replace('name="res" value="128"', 'name="res" value="24"')
    (tmp_path / "point.xml").write_text(xml)
    truth = xml.replace('<bsdf type="dsbrdf" id="material"/>',
                        '<bsdf type="dsbrdf" id="material"><string name="material" value="blue-acrylic"/></bsdf>')
    (tmp_path / "truth.xml").write_text(truth)
    write_exr(tmp_path / "point.exr", np.array(mi.render(mi.load_file(str(tmp_path / "truth.xml")), spp=64, seed=0)))
    out = tmp_path / "out_point"
    assert main(["recover", "--scene", str(tmp_path / "point.xml"), "--image", str(tmp_path / "point.exr"),
                 "--out", str(out), "--max-rounds", "2", "--block-iters", "15"]) == 0
    light = json.loads((out / "light.json").read_text())
    truth_dir = np.array([2.5, 2.0, 3.0]) / np.linalg.norm([2.5, 2.0, 3.0])
    assert light["type"] == "point" and math.degrees(math.acos(min(1.0, np.dot(light["direction"], truth_dir)))) < 3
    np.testing.assert_allclose(np.linalg.norm(light["position"]), np.linalg.norm([2.5, 2.0, 3.0]), rtol=1e-6)
    assert "point" in (out / "scene.xml").read_text()

    from mi_dsbrdf.app.scenes import SCENE_DIR
    torus = open(scene_path("torus_envmap")).read().replace('name="res" value="128"', 'name="res" value="24"')
    (tmp_path / "meshes").mkdir()
    import shutil
    shutil.copy(os.path.join(SCENE_DIR, "meshes", "torus.ply"), tmp_path / "meshes" / "torus.ply")
    torus = torus.replace('value="textures/sky.exr"', 'value="%s"' % os.path.join(SCENE_DIR, "textures", "sky.exr"))
    (tmp_path / "torus.xml").write_text(torus)
    img = np.array(mi.render(mi.load_file(str(tmp_path / "torus.xml")), spp=16, seed=0))
    write_exr(tmp_path / "torus.exr", img)
    out = tmp_path / "out_torus"
    assert main(["recover", "--scene", str(tmp_path / "torus.xml"), "--image", str(tmp_path / "torus.exr"),
                 "--out", str(out), "--map-size", "4x8", "--max-rounds", "1", "--block-iters", "3"]) == 0
    for f in ("illumination.exr", "illumination.png", "scene.xml", "material.png"):
        assert (out / f).stat().st_size > 0, f
    log = json.loads((out / "log.json").read_text())
    assert any("visibility rays: yes" in n for n in log["needs"])
    assert log["map_size"] == [4, 8] and log["image_size"] == [24, 24]
    env = np.array(mi.Bitmap(str(out / "illumination.exr")))
    k = TEXEL_BLOCK
    assert env.shape == (4 * k, 8 * k, 3) and np.isfinite(env).all() and np.all(env >= 0)
    assert np.array_equal(np.repeat(np.repeat(env[::k, ::k], k, 0), k, 1), env)          # constant blocks
    # the map's posterior spread, laid out alike: positive where a texel is seen, 0 where not
    std = np.array(mi.Bitmap(str(out / "illumination_std.exr")))
    assert std.shape == env.shape and np.all((std > 0) == (env > 0))
    saved = json.loads((out / "material.json").read_text())
    from mi_dsbrdf.brdf.dsbrdf import LOBE_PARAMETERS
    assert len(saved["covariance_factor"]) == LOBE_PARAMETERS * saved["lobes"]
    # the written scene loads (mesh path made absolute, the map beside it) and renders finite pixels
    assert str(tmp_path / "meshes" / "torus.ply") in (out / "scene.xml").read_text()
    rerender = np.array(mi.render(mi.load_file(str(out / "scene.xml")), spp=4))
    assert np.isfinite(rerender).all() and rerender.max() > 0


def test_progress_shows_one_bar_per_pass_with_its_total(capsys):
    """Rows as recover_envmap logs them (a grey pass that converges after 2 rounds, a
    colour pass, a second route, the answer): one bar per pass, each with its total."""
    import types

    from mi_dsbrdf import Config
    from mi_dsbrdf.app.recover import _progress
    from mi_dsbrdf.inference.reflectance import reflectance_starts
    from mi_dsbrdf.model.model_file import shipped_model
    model = shipped_model()
    starts = len(reflectance_starts(model))
    report, close = _progress(True, Config(max_rounds=3), types.SimpleNamespace(reasons=("light: envmap",)), model)
    rows = ([{"pass": "start", "round": i} for i in range(starts)] + [{"pass": "grey", "round": i} for i in range(2)]
            + [{"pass": "colour", "round": i} for i in range(3)]
            + [{"pass": "start", "round": i, "route": 1} for i in range(starts)]
            + [{"pass": "colour", "round": i, "route": 1} for i in range(3)] + [{"pass": "answer", "round": 2}])
    for row in rows:
        report(dict(row, neg_log_posterior=1.0, seconds=0.0))
    close()
    printed = capsys.readouterr()
    assert printed.out == "  light: envmap\n"
    import re
    ends = {}                       # each bar's last frame: {description: "n/total"}
    for frame in printed.err.replace("\r", "\n").splitlines():
        m = re.match(r"(.*): +\d+%\|.*\| (\d+/\d+) \[", frame)
        if m:
            ends[m.group(1)] = m.group(2)
    assert ends == {"recover: starts": "%d/%d" % (starts, starts), "recover: grey pass": "2/3",
                    "recover: colour pass": "3/3", "recover: second route, starts": "%d/%d" % (starts, starts),
                    "recover: second route, colour pass": "3/3"}


def test_a_flagged_highlight_names_where_it_lights_the_object(case, monkeypatch, tmp_path, capsys):
    """With the flag's threshold at 0, gold's highlight is flagged: log.json and the
    command line name the sphere's upper right, where the light (travelling along
    -0.5, -0.5, -0.71: from the upper right, in the camera's frame) mirrors towards
    the camera; the extra re-render is its own stage."""
    from mi_dsbrdf.inference import uncertainty
    d, _ = case
    monkeypatch.setattr(uncertainty, "HIGHLIGHT_DOUBT", 0.0)
    assert main(["recover", "--scene", str(d / "scene.xml"), "--image", str(d / "image.exr"),
                 "--out", str(tmp_path / "out"), "--max-rounds", "2", "--block-iters", "20"]) == 0
    log = json.loads((tmp_path / "out" / "log.json").read_text())
    (flag,) = log["flags"]
    assert "on the object's upper right" in flag and "\n" not in flag
    assert list(log["stages"])[-2:] == ["highlight place", "save"]
    assert "  warning: " + flag in capsys.readouterr().out.splitlines()
