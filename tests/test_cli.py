"""The command line: the demo (the README's main job) and output-directory safety."""
import subprocess
import sys

import numpy as np

from mi_dsbrdf.cli import main
from mi_dsbrdf.scenes import SCENES


def test_demo_writes_exr_and_png_and_never_overwrites(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--spp", "4"]) == 0
    for name in SCENES:
        assert (out / (name + ".exr")).stat().st_size > 0
        assert (out / (name + ".png")).stat().st_size > 0
    import mitsuba as mi
    img = np.array(mi.Bitmap(str(out / "sphere_envmap.exr")))
    assert img.shape == (128, 128, 3) and np.isfinite(img).all() and img.max() > 0
    before = (out / "sphere_envmap.exr").stat().st_mtime_ns
    r = subprocess.run([sys.executable, "-m", "mi_dsbrdf.cli", "demo", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "--force" in r.stderr
    assert (out / "sphere_envmap.exr").stat().st_mtime_ns == before


def test_render_missing_scene_is_a_clear_error(tmp_path, capsys):
    assert main(["render", str(tmp_path / "nope.xml"), "--out", str(tmp_path / "o")]) == 1
    assert "no scene" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_build_model_refuses_to_overwrite_and_names_bad_sources(tmp_path, capsys):
    existing = tmp_path / "model.npz"
    existing.write_bytes(b"keep me")
    r = subprocess.run([sys.executable, "-m", "mi_dsbrdf.cli", "build-model", "--merl", str(tmp_path),
                        "--out", str(existing)], capture_output=True, text=True)
    assert r.returncode != 0 and "--force" in r.stderr
    assert existing.read_bytes() == b"keep me"
    assert main(["build-model", "--merl", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "m.npz")]) == 1
    assert "does not exist" in capsys.readouterr().err
    assert main(["build-model", "--merl", str(tmp_path), "--out", str(tmp_path / "m.npz")]) == 1
    assert "no MERL .binary files" in capsys.readouterr().err
    assert not (tmp_path / "m.npz").exists()
