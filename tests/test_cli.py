"""The command line: the demo (the main job), recover's settings, relight, build-model and output safety."""
import json
import math
import subprocess
import sys

import mitsuba as mi
import numpy as np

from mi_dsbrdf.app.cli import main
from mi_dsbrdf.app.scenes import SCENE_DIR


def test_demo_recovers_and_reports_and_never_overwrites(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--res", "24", "--map-size", "4x8", "--max-rounds", "1",
                 "--block-iters", "3", "--spp", "16"]) == 0
    report = json.loads((out / "report.json").read_text())
    # log.json's flags: in the report, its table, and each as a warning line
    log = json.loads((out / "recovered" / "log.json").read_text())
    assert report["flags"] == log["flags"] and "what the photograph may not support" in (out / "report.md").read_text()
    printed = capsys.readouterr().out.splitlines()
    assert [line for line in printed if line.startswith("  warning: ")] == ["  warning: " + f for f in log["flags"]]
    for key in ("brdf_eq20_paper", "brdf_eq20_cosine", "mean_material_eq20_paper", "illumination_cosine_after_scale",
                "illumination_paper_after_scale", "constant_map_cosine_after_scale", "constant_map_paper_after_scale",
                "relit_log_rmse_after_scale", "mean_material_relit_log_rmse_after_scale"):
        assert math.isfinite(report[key]) and report[key] >= 0, key
    # the posterior band: a share of the cells, and a width
    assert 0 <= report["band_coverage_observed"] <= 1 and report["band_width_observed"] > 0
    assert "posterior band holds the truth" in (out / "report.md").read_text()
    for f in ("report.md", "comparison.png", "observed.exr", "recovered/material.json",
              "recovered/illumination.exr", "recovered/scene.xml"):
        assert (out / f).stat().st_size > 0, f
    before = (out / "report.json").stat().st_mtime_ns
    r = subprocess.run([sys.executable, "-m", "mi_dsbrdf.app.cli", "demo", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "--force" in r.stderr
    assert (out / "report.json").stat().st_mtime_ns == before


def test_relight_renders_the_posteriors_spread(tmp_path, capsys):
    """--samples N renders N posterior materials with the MAP's seed: their per-pixel
    standard deviation is ~0 for a material without spread and grows with it; a
    library material has no posterior and is refused in one line."""
    from mi_dsbrdf.brdf.dsbrdf import LOBE_PARAMETERS
    from mi_dsbrdf.model.model_file import shipped_model
    sky = "%s/textures/sky.exr" % SCENE_DIR
    base = shipped_model().library_material("gold-metallic-paint")
    spreads = []
    for name, f in (("none", 0.0), ("some", 0.1)):
        path = tmp_path / ("%s.json" % name)
        base.with_covariance(np.full((LOBE_PARAMETERS * base.n_lobes, 1), f)).save(path)
        out = tmp_path / ("%s.exr" % name)
        assert main(["relight", str(path), "--envmap", sky, "--out", str(out), "--res", "16", "--spp", "4",
                     "--samples", "3"]) == 0
        img, std = (np.array(mi.Bitmap(str(p))) for p in (out, tmp_path / ("%s_std.exr" % name)))
        assert std.shape == img.shape and (tmp_path / ("%s_std.png" % name)).stat().st_size > 0
        spreads.append(std.max() / img.max())
    assert spreads[0] < 1e-4 < 1e-2 < spreads[1]
    assert main(["relight", "gold-metallic-paint", "--envmap", sky, "--out", str(tmp_path / "lib.exr"),
                 "--samples", "2"]) == 1
    assert "carries its posterior" in capsys.readouterr().err


def test_relight_renders_a_material_and_refuses_bad_input(tmp_path, capsys):
    sky = "%s/textures/sky.exr" % SCENE_DIR
    out = tmp_path / "relit.exr"
    assert main(["relight", "gold-metallic-paint", "--envmap", sky, "--out", str(out), "--res", "24",
                 "--spp", "8"]) == 0
    img = np.array(mi.Bitmap(str(out)))
    assert img.shape == (24, 24, 3) and np.isfinite(img).all() and img[12, 12].max() > 0
    assert (tmp_path / "relit.png").stat().st_size > 0
    assert main(["relight", "gold-metallic-paint", "--envmap", sky, "--out", str(out)]) == 1
    assert "--force" in capsys.readouterr().err
    for args, message in ((["nope-material", "--envmap", sky], "neither a file nor a library material"),
                          (["gold-metallic-paint", "--envmap", str(tmp_path / "none.exr")], "does not exist"),
                          (["gold-metallic-paint", "--envmap", sky, "--shape", "cube"], "shape 'cube'")):
        assert main(["relight"] + args + ["--out", str(tmp_path / "x.exr")]) == 1
        assert message in capsys.readouterr().err
        assert not (tmp_path / "x.exr").exists()


def test_render_missing_scene_is_a_clear_error(tmp_path, capsys):
    assert main(["render", str(tmp_path / "nope.xml"), "--out", str(tmp_path / "o")]) == 1
    assert "no scene" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def recover_args(*options):
    """The parsed arguments of ``recover`` with these options (the default preset
    and no override without any)."""
    from mi_dsbrdf.app.cli import parser
    return parser().parse_args(["recover", "--image", "i.exr", "--out", "o"] + list(options))


def test_bad_map_size_is_a_usage_error(tmp_path, capsys):
    import pytest
    with pytest.raises(SystemExit):
        main(["recover", "--scene", "s.xml", "--image", "i.exr", "--out", str(tmp_path / "o"), "--map-size", "16by32"])
    assert "HxW" in capsys.readouterr().err


def test_the_colour_split_is_on_by_default_and_an_option_of_recover(capsys):
    import pytest
    from mi_dsbrdf.app.cli import _config
    on = _config(recover_args())
    off = _config(recover_args("--no-colour-split"))
    assert (on.w_chromaticity, on.w_light_colour) == (1.0 / 3.0, 1.0) and on.colour_split
    assert (off.w_chromaticity, off.w_light_colour) == (0, 0) and not off.colour_split
    with pytest.raises(SystemExit):
        main(["recover", "--help"])
    assert "--no-colour-split" in capsys.readouterr().out


def test_recover_s_options_are_the_config_fields_and_its_presets_are_default_and_fast(capsys):
    """Every Config field is an option of recover and demo, named as the field with
    dashes; --rounds and --iters are aliases of --max-rounds and --block-iters;
    unset options keep the preset's values."""
    import dataclasses

    import pytest

    from mi_dsbrdf import PRESETS, Config
    from mi_dsbrdf.app.cli import _config
    assert _config(recover_args()) == Config() == PRESETS["default"]
    assert _config(recover_args("--preset", "fast")) == PRESETS["fast"] == Config(map_size=(16, 32))
    given = {"map_size": (8, 16), "max_rounds": 2, "tol": 0.01, "block_iters": 4, "w_gmm": 2.5,
             "second_route_highlight": None, "grey_texel_samples": None, "map_pairs": 1 << 20}
    argv = []
    for name, value in given.items():
        text = "x".join(map(str, value)) if isinstance(value, tuple) else "none" if value is None else str(value)
        argv += ["--" + name.replace("_", "-"), text]
    assert _config(recover_args(*argv)) == dataclasses.replace(Config(), **given)
    assert _config(recover_args("--rounds", "5", "--iters", "7")) == Config(max_rounds=5, block_iters=7)
    for command in ("recover", "demo"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        out = capsys.readouterr().out
        for f in dataclasses.fields(Config):
            assert "--" + f.name.replace("_", "-") in out, f.name
        assert "--rounds" in out and "--iters" in out
    for gone in ("--start-candidates", "--grey-rounds"):
        with pytest.raises(SystemExit):
            main(["recover", "--image", "i.exr", "--out", "o", gone, "1"])
        assert "unrecognized arguments" in capsys.readouterr().err


def test_a_bad_setting_is_a_one_line_error_naming_the_option_as_typed(tmp_path, capsys):
    base = ["recover", "--sphere", "--image", str(tmp_path / "i.exr"), "--out", str(tmp_path / "o")]
    for option, value in (("--max-rounds", "0"), ("--rounds", "0"), ("--iters", "0"), ("--map-size", "1x8"),
                          ("--texel-samples", "0"), ("--w-gmm", "-1"), ("--second-route-highlight", "0")):
        assert main(base + [option, value]) == 1
        err = capsys.readouterr().err
        assert err.startswith("mi-dsbrdf: %s " % option), err
        assert "_" not in err.split(" ")[1] and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_the_second_route_is_on_by_default_and_no_second_route_turns_it_off(capsys):
    import pytest
    from mi_dsbrdf.app.cli import _config
    assert _config(recover_args()).second_route_highlight == 2.0
    assert _config(recover_args("--no-second-route")).second_route_highlight is None
    with pytest.raises(SystemExit):
        main(["recover", "--help"])
    assert "--no-second-route" in capsys.readouterr().out


def test_build_model_refuses_to_overwrite_and_names_bad_sources(tmp_path, capsys):
    existing = tmp_path / "model.npz"
    existing.write_bytes(b"keep me")
    r = subprocess.run([sys.executable, "-m", "mi_dsbrdf.app.cli", "build-model", "--merl", str(tmp_path),
                        "--out", str(existing)], capture_output=True, text=True)
    assert r.returncode != 0 and "--force" in r.stderr
    assert existing.read_bytes() == b"keep me"
    assert main(["build-model", "--merl", str(tmp_path / "missing.npz"), "--out", str(tmp_path / "m.npz")]) == 1
    assert "does not exist" in capsys.readouterr().err
    assert main(["build-model", "--merl", str(tmp_path), "--out", str(tmp_path / "m.npz")]) == 1
    assert "no MERL .binary files" in capsys.readouterr().err
    assert not (tmp_path / "m.npz").exists()


def test_a_builds_recorded_command_repeats_the_build(tmp_path, monkeypatch):
    """build_info's command, run, asks build_model for the same build: every
    non-default option is in it (--fits-from, --k and --gmm)."""
    import shlex

    import pytest

    from mi_dsbrdf.app import cli
    from mi_dsbrdf.model.build import GMM, build_command
    calls = []

    class Called(Exception):
        pass

    def build_model(source, out, **kwargs):
        calls.append(dict(kwargs, source=source, out=out))
        raise Called

    monkeypatch.setattr(cli, "build_model", build_model)
    monkeypatch.chdir(tmp_path)
    builds = [dict(k=7, exclude=("pvc", "teflon"), fits_from="old.npz", gmm="diag:5:0.01"),
              dict(k=10, exclude=(), fits_from=None, gmm=GMM)]
    for build in builds:
        command = build_command("merl.npz", "m.npz", **build)
        with pytest.raises(Called):
            cli.main(shlex.split(command)[1:])
        got = calls.pop()
        assert (got["source"], got["out"]) == ("merl.npz", "m.npz")
        assert got["k"] == build["k"] and tuple(got["exclude"]) == build["exclude"]
        assert got["fits_from"] == build["fits_from"] and got["gmm"] == build["gmm"]
