"""One frozen, validated Config; the CLI prints its errors (and file errors) as one line."""
import dataclasses

import pytest

from mi_dsbrdf import PRESETS, Config, ConfigError
from mi_dsbrdf.app.cli import main
from mi_dsbrdf.config import PRIOR_PIXELS, field_docs, preset


def test_config_is_frozen_and_validated():
    cfg = Config()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.max_rounds = 5
    assert dataclasses.replace(cfg, map_size=[8, 16]).map_size == (8, 16)
    assert cfg.working_pixels == 128 * 128 and cfg.max_memory is None
    assert Config(max_memory=4).max_memory == 4 and Config(working_pixels=256).working_pixels == 256
    for bad in (dict(map_size=(1, 8)), dict(map_size="big"), dict(max_rounds=0), dict(block_iters=2.5),
                dict(tol=0.0), dict(likelihood_scale=float("nan")), dict(log_offset=0.0), dict(w_gmm=-1.0),
                dict(w_hue=float("inf")), dict(grey_texel_samples=0), dict(second_route_highlight=0),
                dict(reflectance_pairs=10), dict(map_levels=0), dict(gradient_eps=0.0),
                dict(gradient_eps=float("nan")), dict(texel_samples=0), dict(texel_samples=2.0),
                dict(gradient_alpha=1.0), dict(gradient_alpha=0.0), dict(gradient_alpha=True),
                dict(working_pixels=255), dict(working_pixels=1e6), dict(max_memory=0.0),
                dict(max_memory=float("inf")), dict(max_memory=True), dict(max_memory="4")):
        with pytest.raises(ConfigError) as e:
            Config(**bad)
        name = next(iter(bad))
        assert e.value.field == name and str(e.value).startswith(name), (bad, str(e.value))
    for gone in ("start_candidates", "grey_rounds", "start_on_colour_posterior", "gmm_volume", "light_gmm_volume",
                 "likelihood_kink"):
        assert not hasattr(cfg, gone)


def test_presets_and_prior_weights():
    assert list(PRESETS) == ["default", "fast"]
    assert PRESETS["default"] == Config()
    assert PRESETS["fast"] == Config(map_size=(16, 32))
    assert preset("fast") is PRESETS["fast"]
    with pytest.raises(ConfigError) as e:
        preset("benchmarked")
    assert "default, fast" in str(e.value) and "\n" not in str(e.value)
    w = Config(w_gmm=2.0).prior_weights(2 * PRIOR_PIXELS)
    assert w["gmm"] == pytest.approx(4.0) and w["hue"] == pytest.approx(2.0)


def test_every_field_is_described_in_the_docstring():
    """The Config docstring describes each field (the command line's help), and
    nothing else."""
    docs = field_docs()
    assert set(docs) == {f.name for f in dataclasses.fields(Config)}
    assert all(len(text) > 20 for text in docs.values())


def test_cli_prints_config_and_file_errors_as_one_line(tmp_path, capsys):
    assert main(["recover", "--scene", "x.xml", "--image", "y.exr", "--out", str(tmp_path / "o"),
                 "--max-rounds", "0"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("mi-dsbrdf: --max-rounds must be") and "\n" not in err
    assert main(["recover", "--scene", "x.xml", "--image", "y.exr", "--out", str(tmp_path / "o"),
                 "--texel-samples", "0"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("mi-dsbrdf: --texel-samples must be") and "\n" not in err
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["render", "sphere_envmap", "--out", str(blocker / "sub")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("mi-dsbrdf:") and "\n" not in err
