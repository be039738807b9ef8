"""Hostile inputs, as a user meets them: each is one line on stderr (or an exception of
mi_dsbrdf.errors from the API), a nonzero exit, and nothing written."""
import json
import math
import os
import signal
import subprocess
import sys
import time

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import mi_dsbrdf
import mi_dsbrdf.app.recover as recover_module
from mi_dsbrdf import InputError, MaterialError, SceneError
from mi_dsbrdf.app.cli import main
from mi_dsbrdf.app.io import check_out, staged_file, staged_output, write_exr
from mi_dsbrdf.app.photo import sphere_scene
from mi_dsbrdf.app.render import check_envmap
from mi_dsbrdf.app.result import RESULT_FILES, Result
from mi_dsbrdf.app.scenes import SCENE_DIR, scene_path

RES = 32
SKY = os.path.join(SCENE_DIR, "textures", "sky.exr")
#: a process id no process has (above Linux's largest, 2^22)
DEAD_PID = 999_999_999


def one_line(capsys, *words) -> str:
    """The one line a command printed on stderr (progress bars aside), checked for ``words``."""
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("mi-dsbrdf: ")]
    assert len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def listing(folder) -> list:
    """Every name in ``folder``, hidden ones too."""
    return sorted(os.listdir(folder))


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """The shipped directional-light scene at RES pixels and its image (gold-metallic-paint),
    a sphere on black with its mask, and a few bad files."""
    d = tmp_path_factory.mktemp("case")
    xml = open(scene_path("sphere_directional")).read().replace('name="res" value="128"', 'name="res" value="%d"' % RES)
    (d / "scene.xml").write_text(xml)
    truth = xml.replace('<bsdf type="dsbrdf" id="material"/>', '<bsdf type="dsbrdf" id="material">'
                        '<string name="material" value="gold-metallic-paint"/></bsdf>')
    (d / "truth.xml").write_text(truth)
    write_exr(d / "image.exr", np.array(mi.render(mi.load_file(str(d / "truth.xml")), spp=16, seed=0)))
    (d / "no_sensor.xml").write_text('<scene version="3.0.0"><shape type="sphere"><bsdf type="dsbrdf"/></shape>'
                                     '<emitter type="directional"/></scene>')
    yy, xx = np.mgrid[0:RES, 0:RES]
    disc = (xx + 0.5 - 16) ** 2 + (yy + 0.5 - 16) ** 2 <= 10 ** 2
    write_exr(d / "disc.exr", np.where(disc[..., None], 0.5 + 0.3 * xx[..., None] / RES, 0.0) * np.ones(3))
    mi.Bitmap((disc * 255).astype(np.uint8)).write(str(d / "disc_mask.png"))
    return d


@pytest.fixture(scope="module")
def result(case):
    """A quick recovery of the case (the API), to save and to interrupt."""
    return mi_dsbrdf.recover(str(case / "scene.xml"), str(case / "image.exr"),
                             config=mi_dsbrdf.Config(max_rounds=1, block_iters=3))


def recover_args(case, out, *more):
    return ["recover", "--scene", str(case / "scene.xml"), "--image", str(case / "image.exr"),
            "--out", str(out)] + list(more)


@pytest.fixture
def quick(monkeypatch, result):
    """``recover`` of the command line returns the module's result at once (the
    tests here are about everything around inference)."""
    monkeypatch.setattr(recover_module, "recover", lambda *a, **k: result)


# --- scenes, cameras, materials, maps ----------------------------------------------

def test_a_scene_without_a_sensor(case, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(recover_args(case, out)[:2] + [str(case / "no_sensor.xml")] + recover_args(case, out)[3:]) == 1
    one_line(capsys, "no sensor")
    with pytest.raises(SceneError, match="no sensor"):
        mi_dsbrdf.recover(scene={"type": "scene"}, image=str(case / "image.exr"))
    assert listing(tmp_path) == []


@pytest.mark.parametrize("fov,words", [("1e-9", ("1e-09 degrees", "leave out --fov")),
                                        ("0", ("(0, 180)",)), ("180", ("(0, 180)",)), ("-5", ("(0, 180)",)),
                                        ("nan", ("(0, 180)",)), ("inf", ("(0, 180)",))])
def test_a_field_of_view_out_of_range(case, tmp_path, capsys, fov, words):
    assert main(["recover", "--sphere", "--image", str(case / "disc.exr"), "--mask", str(case / "disc_mask.png"),
                 "--fov=" + fov, "--out", str(tmp_path / "out")]) == 1
    one_line(capsys, *words)
    assert listing(tmp_path) == []


def test_the_narrowest_field_of_view_still_sees_the_sphere():
    """At the narrowest field of view taken, the camera's rays still hit the sphere
    where the outline says (float32 rays miss it about 10x farther away)."""
    scene = sphere_scene((RES, RES), (16, 16, 10), fov=0.2)
    scene["object"] = {"type": "sphere", "emitter": {"type": "area", "radiance": 1.0}}
    del scene["light"]
    seen = np.array(mi.render(mi.load_dict(scene), spp=4))[..., 0] > 0.5
    assert abs(seen.sum() - math.pi * 100) < 10
    with pytest.raises(InputError, match="leave out --fov"):
        sphere_scene((RES, RES), (16, 16, 10), fov=0.1)


def material_file(folder, **change):
    d = mi_dsbrdf.load_material("gold-metallic-paint").to_dict()
    for key, value in change.items():
        if key == "log_kappa_00":
            d["log_kappa"][0][0] = value
        else:
            d[key] = value
    path = folder / "material.json"
    path.write_text(json.dumps(d))
    return path


@pytest.mark.parametrize("change,words", [({"log_kappa_00": 1e6}, ("kappa must be <= 60", "exp(1e+06)")),
                                          ({"lobes": 7}, ('"lobes": 7', "3 rows"))])
def test_a_bad_material_file(tmp_path, capsys, change, words):
    path = material_file(tmp_path, **change)
    with pytest.raises(MaterialError):
        mi_dsbrdf.load_material(str(path))
    assert main(["relight", str(path), "--envmap", SKY, "--out", str(tmp_path / "relit.exr"), "--res", "8",
                 "--spp", "1"]) == 1
    one_line(capsys, *words)
    assert listing(tmp_path) == ["material.json"]


@pytest.mark.parametrize("name", ["relit.png", "relit", "relit.partial"])
def test_a_relight_output_that_is_not_an_exr(tmp_path, capsys, name):
    assert main(["relight", "gold-metallic-paint", "--envmap", SKY, "--out", str(tmp_path / name), "--res", "8",
                 "--spp", "1"]) == 1
    one_line(capsys, "ending in .exr")
    assert listing(tmp_path) == []


@pytest.mark.parametrize("size", [(1, 1), (3, 7), (4, 64), (8, 15)])
def test_a_relight_map_that_is_not_two_to_one(tmp_path, capsys, size):
    write_exr(tmp_path / "map.exr", np.ones(size + (3,)))
    assert main(["relight", "gold-metallic-paint", "--envmap", str(tmp_path / "map.exr"),
                 "--out", str(tmp_path / "relit.exr"), "--res", "8", "--spp", "1"]) == 1
    one_line(capsys, "twice as wide as high", "%dx%d" % size[::-1])
    assert listing(tmp_path) == ["map.exr"]


def test_two_to_one_maps_are_taken(tmp_path):
    for size in ((2, 4), (8, 16), (100, 201)):
        write_exr(tmp_path / "map.exr", np.ones(size + (3,)))
        check_envmap(tmp_path / "map.exr")


def test_srgb_on_an_hdr_image_is_refused(case, tmp_path, capsys):
    assert main(recover_args(case, tmp_path / "out", "--srgb")) == 1
    one_line(capsys, "--srgb", "linear radiance already")
    with pytest.raises(InputError, match="srgb"):
        mi_dsbrdf.recover(str(case / "scene.xml"), np.ones((RES, RES, 3)), srgb=True)
    assert listing(tmp_path) == []


def test_a_nan_parameter_set_through_traverse_is_refused():
    """The evaluation clamps log kappa (fmin, which drops a NaN): a NaN set through
    mi.traverse is refused when the parameters update, never rendered as kappa 60."""
    for bsdf, key in ((mi.load_dict({"type": "dsbrdf", "kappa_0": "2", "gamma_0": "10"}), "log_kappa"),
                      (mi.load_dict({"type": "dsbrdf", "kappa_0": "2", "gamma_0": "10"}), "log_gamma"),
                      (mi.load_dict({"type": "dsbrdf", "kappa_0": "2", "gamma_0": "10"}), "chromaticity"),
                      (mi.load_dict({"type": "dsbrdf", "psi": " ".join(["0"] * 10)}), "psi")):
        params = mi.traverse(bsdf)
        good = np.array(params[key])
        bad = good.copy()
        bad[0] = np.nan
        params[key] = mi.Float(bad)
        with pytest.raises(MaterialError, match="%s has 1 NaN" % key):
            params.update()
        params[key] = mi.Float(good[:-1])
        with pytest.raises(MaterialError, match="%s needs %d values" % (key, good.size)):
            params.update()
        params[key] = mi.Float(good)
        params.update()                                 # a good value again: evaluates
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi, si.sh_frame = mi.Vector3f(0, 0, 1), mi.Frame3f(mi.Vector3f(0, 0, 1))
    value = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(0, 0.1, 0.995)))
    assert np.isfinite(value).all() and value.max() > 0


# --- interruptions --------------------------------------------------------------

def test_ctrl_c_is_one_line_and_writes_nothing(case, tmp_path, capsys, monkeypatch):
    def interrupted(*a, **k):
        os.kill(os.getpid(), signal.SIGINT)           # Ctrl-C during the work
        time.sleep(5)
    monkeypatch.setattr(recover_module, "recover", interrupted)
    assert main(recover_args(case, tmp_path / "out")) == 130
    one_line(capsys, "interrupted; nothing written")
    assert listing(tmp_path) == []


@pytest.mark.parametrize("earlier,out", [(False, "out"), (True, "out"), (False, "new/folders/out")])
def test_sigterm_during_the_save_leaves_no_staging_folder(case, tmp_path, capsys, monkeypatch, quick, earlier, out):
    """SIGTERM stops the command as Ctrl-C does: the staging folder goes (and the
    folders made for it), an earlier result (--force) stays whole."""
    out = tmp_path / out
    if earlier:
        assert main(recover_args(case, out)) == 0
        before = {p.name: p.read_bytes() for p in out.iterdir()}
    write = Result._write

    def terminated(self, tmp, final):
        write(self, tmp, final)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
    monkeypatch.setattr(Result, "_write", terminated)
    capsys.readouterr()
    assert main(recover_args(case, out, *(["--force"] if earlier else []))) == 128 + signal.SIGTERM
    one_line(capsys, "interrupted; nothing written")
    assert listing(tmp_path) == (["out"] if earlier else [])
    if earlier:
        assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL       # the handler is the command's only


def test_an_interruption_between_the_two_renames_puts_the_earlier_result_back(tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    (out / "material.json").write_text("earlier")
    import mi_dsbrdf.app.io as io
    rename = os.rename

    def rename_then_stop(src, dst):
        if os.path.basename(src).startswith(".out.partial-"):
            raise KeyboardInterrupt
        rename(src, dst)
    monkeypatch.setattr(io.os, "rename", rename_then_stop)
    with pytest.raises(KeyboardInterrupt):
        with staged_output(out, True, RESULT_FILES) as tmp:
            open(os.path.join(tmp, "material.json"), "w").write("new")
    monkeypatch.undo()
    assert listing(tmp_path) == ["out"] and (out / "material.json").read_text() == "earlier"


def test_sigterm_from_outside_is_one_line(case, tmp_path):
    """The installed command, stopped by SIGTERM once it has printed what the scene
    needs (the work under way)."""
    out = tmp_path / "out"
    p = subprocess.Popen([os.path.join(os.path.dirname(sys.executable), "mi-dsbrdf")] + recover_args(case, out),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().startswith("  light:")
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=60)
    finally:
        p.kill()
    assert p.returncode == 128 + signal.SIGTERM, err
    assert err.strip().splitlines()[-1] == "mi-dsbrdf: interrupted; nothing written" and "Traceback" not in err
    assert listing(tmp_path) == []


# --- the output folder --------------------------------------------------------------

def test_leftover_staging_folders_are_cleaned_or_named(case, tmp_path, capsys, quick):
    out = tmp_path / "out"
    day_old = time.time() - 2 * 24 * 3600
    for name in (".out.partial-%d-abc" % DEAD_PID, ".out.old-%d-abc" % DEAD_PID, ".out.partial-k2j3x9"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "material.json").write_text("half")
    os.utime(tmp_path / ".out.partial-k2j3x9", (day_old, day_old))     # an older version's, no pid: by its age
    (tmp_path / (".other.partial-%d-abc" % DEAD_PID)).mkdir()               # another output's: not ours to clean
    assert main(recover_args(case, out)) == 0
    assert listing(tmp_path) == [".other.partial-%d-abc" % DEAD_PID, "out"]
    # a staging folder of a live process (the test's parent), made now: named, nothing done
    live = tmp_path / (".out.partial-%d-abc" % os.getppid())
    live.mkdir()
    capsys.readouterr()
    assert main(recover_args(case, out, "--force")) == 1
    one_line(capsys, str(live), "pid %d" % os.getppid())
    live.rmdir()
    # a run stopped between its two renames: the earlier result is the user's, named
    import shutil
    stopped = tmp_path / (".out.old-%d-abc" % DEAD_PID)
    stopped.mkdir()
    shutil.move(str(out), str(stopped / "result"))
    assert main(recover_args(case, out)) == 1
    one_line(capsys, str(stopped / "result"), "move it back")
    assert (stopped / "result" / "material.json").exists() and not out.exists()


def test_leftover_staging_files_are_cleaned_or_named(tmp_path):
    """A file's staging name carries the writer's pid, as a folder's does: a dead
    writer's file goes, a live one's is named."""
    out = tmp_path / "relit.exr"
    dead = tmp_path / (".relit.exr.partial-%d-file.exr" % DEAD_PID)
    dead.write_text("half")
    tmp = staged_file(out)
    assert os.path.basename(tmp) == ".relit.exr.partial-%d-file.exr" % os.getpid()
    assert listing(tmp_path) == []
    live = tmp_path / (".relit.exr.partial-%d-file.exr" % os.getppid())
    live.write_text("half")
    with pytest.raises(InputError, match="pid %d.*remove that file" % os.getppid()):
        staged_file(out)
    assert listing(tmp_path) == [live.name]


def test_a_mount_point_is_refused_before_the_work(case, tmp_path, capsys, monkeypatch):
    def no_work(*a, **k):
        raise AssertionError("the work started")
    monkeypatch.setattr(recover_module, "recover", no_work)
    assert main(recover_args(case, "/", "--force")) == 1
    one_line(capsys, "/ is a mount point")
    mount = tmp_path / "usb"
    mount.mkdir()
    real = os.path.ismount
    monkeypatch.setattr(os.path, "ismount", lambda p: os.fspath(p) == str(mount) or real(p))
    assert main(recover_args(case, mount)) == 1
    one_line(capsys, "mount point", os.path.join(str(mount), "result"))
    assert main(recover_args(case, "/proc/mi-dsbrdf-out")) == 1
    one_line(capsys, "cannot write into /proc")
    assert listing(tmp_path) == ["usb"] and listing(mount) == []


@pytest.mark.parametrize("mask", [0o022, 0o027, 0o077])
def test_the_result_folder_has_the_users_umask(tmp_path, result, mask):
    previous = os.umask(mask)
    try:
        result.save(tmp_path / "out")
        os.mkdir(tmp_path / "mine")
    finally:
        os.umask(previous)
    assert os.stat(tmp_path / "out").st_mode & 0o777 == 0o777 & ~mask == os.stat(tmp_path / "mine").st_mode & 0o777


def test_the_results_scene_keeps_the_shapes_ids(case, tmp_path, capsys, result):
    result.save(tmp_path / "out")
    text = (tmp_path / "out" / "scene.xml").read_text()
    assert 'id="object"' in text and 'id="light"' in text
    assert main(["relight", str(tmp_path / "out" / "material.json"), "--scene", str(tmp_path / "out" / "scene.xml"),
                 "--shape-id", "object", "--out", str(tmp_path / "relit.exr"), "--spp", "1"]) == 0
    assert np.array(mi.Bitmap(str(tmp_path / "relit.exr"))).shape == (RES, RES, 3)
    # a photograph's scene (a dict): the ids of its entries, not of nested objects
    from mi_dsbrdf.app.outputs import write_scene_xml
    scene = sphere_scene((RES, RES), (16, 16, 10), light="point")
    scene["floor"] = {"type": "rectangle", "bsdf": {"type": "diffuse"}}
    photo = tmp_path / "out" / "photo.xml"
    write_scene_xml(scene, photo, {"type": "point", "position": [0, 0, 5], "intensity": 1.0},
                    tmp_path / "out" / "material.json")
    text = photo.read_text()
    assert 'id="object"' in text and 'id="floor"' in text and 'id="bsdf"' not in text
    mi.load_file(str(photo))


def test_check_out_of_a_clean_destination_changes_nothing(tmp_path):
    (tmp_path / ".mine").mkdir()
    check_out(tmp_path / "out")
    assert listing(tmp_path) == [".mine"]


@pytest.mark.parametrize("args", [["--spp", "0"], ["--spp", "-1"], ["--spp", "100000000000"],
                                  ["--param", "res=0"]])
def test_render_refuses_bad_samples_and_film_sizes_in_one_line(args, tmp_path, capsys):
    assert main(["render", "sphere_envmap", "--out", str(tmp_path / "r")] + args) == 1
    one_line(capsys, "mi-dsbrdf:")
    assert not (tmp_path / "r").exists()
