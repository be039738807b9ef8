"""Per-channel clipping: a camera clips each channel at its own white level after
white balance; a pixel with a clipped channel is left out of the likelihood,
found as a plateau of that channel's maximum or given by --white-level."""
import math

import mitsuba as mi
import numpy as np
import pytest

import mi_dsbrdf
from mi_dsbrdf.app.cli import main
from mi_dsbrdf.app.io import write_exr
from mi_dsbrdf.app.scenes import scene_path
from mi_dsbrdf.inference.pixels import saturated, usable_pixels

RES = 32


def angle(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return math.degrees(math.acos(min(1.0, float(a @ b / np.linalg.norm(a) / np.linalg.norm(b)))))


def global_plateau(image):
    """The clipping rule before per-channel plateaus: a channel at the image's
    maximum, shared by at least 4 pixels."""
    at_top = np.any(image >= image.max() * (1 - 1e-6), axis=2)
    return at_top if at_top.sum() >= 4 else np.zeros(at_top.shape, bool)


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    """The shipped directional-light scene at RES pixels, its image
    (gold-metallic-paint), the object's pixels, and the image with its red channel
    clipped at half its maximum: the highlight's red, below green's maximum."""
    d = tmp_path_factory.mktemp("clipping")
    xml = open(scene_path("sphere_directional")).read().replace('name="res" value="128"', 'name="res" value="%d"' % RES)
    (d / "scene.xml").write_text(xml)
    truth = xml.replace('<bsdf type="dsbrdf" id="material"/>', '<bsdf type="dsbrdf" id="material">'
                        '<string name="material" value="gold-metallic-paint"/></bsdf>')
    img = np.array(mi.render(mi.load_string(truth), spp=64, seed=0), dtype=np.float64)
    on = img.max(axis=2) > 0
    level = 0.5 * img[..., 0].max()
    clipped = img.copy()
    clipped[..., 0] = np.minimum(img[..., 0], level)
    assert level < clipped[..., 1].max()
    return d, img, on, clipped, level


def test_a_red_channel_clipped_below_the_image_s_maximum_is_left_out(photo):
    d, img, on, clipped, level = photo
    red = img[..., 0] >= level                            # the pixels whose red is clipped
    assert red.sum() >= 10
    assert not (global_plateau(clipped) & red).any()      # the image's maximum does not show them
    assert np.array_equal(saturated(clipped), red)        # red's plateau does
    keep = usable_pixels(on, clipped)
    assert not (keep & red).any() and np.array_equal(keep, usable_pixels(on, img) & ~red)
    # an image without clipping: as before
    assert not saturated(img).any() and np.array_equal(saturated(img), global_plateau(img))
    # a white level names the same pixels
    assert np.array_equal(saturated(clipped, np.array([level, 10.0, 10.0])), red)


def test_white_level_reaches_recovery_and_is_checked_in_one_line(photo, tmp_path, capsys):
    d, img, on, clipped, level = photo
    with pytest.raises(mi_dsbrdf.InputError, match="only 11 usable pixels"):   # the black ones left
        mi_dsbrdf.recover(str(d / "scene.xml"), img, white_level=1e-9)
    with pytest.raises(mi_dsbrdf.InputError, match="--white-level"):
        mi_dsbrdf.recover(str(d / "scene.xml"), img, white_level=[1.0, -1.0, 1.0])
    write_exr(d / "clipped.exr", clipped)
    base = ["recover", "--scene", str(d / "scene.xml"), "--image", str(d / "clipped.exr")]
    for bad, words in ((["0"], "finite and > 0"), (["nan"], "finite and > 0"), (["1", "2"], "one value or 3")):
        assert main(base + ["--white-level"] + bad + ["--out", str(tmp_path / "o")]) == 1
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "--white-level" in err and words in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_recovery_from_a_clipped_image_matches_the_unclipped_one(photo):
    d, img, on, clipped, level = photo
    cfg = mi_dsbrdf.Config(max_rounds=2, block_iters=15)
    r0 = mi_dsbrdf.recover(str(d / "scene.xml"), img, config=cfg)
    r1 = mi_dsbrdf.recover(str(d / "scene.xml"), clipped, config=cfg)
    assert not (r1.used & (img[..., 0] >= level)).any()
    truth = np.array([0.5, 0.5, 0.7071])
    assert angle(r1.light["direction"], truth) < 1.0 and angle(r1.light["direction"], r0.light["direction"]) < 1.5
    used = r0.used & r1.used & (img.min(axis=2) > 1e-3 * img.max())
    assert np.median(np.abs(np.log(r1.rerender[used] / r0.rerender[used]))) < 0.03
