"""The pixels inference uses (mi_dsbrdf.inference.pixels): one rule for the app
and the benchmarks that score it."""
import numpy as np
import pytest

from mi_dsbrdf.errors import InputError
from mi_dsbrdf.inference.pixels import interior, saturated, usable_pixels, white_levels


def disc(n=21, r=7.5):
    y, x = np.mgrid[:n, :n] + 0.5
    return (x - n / 2) ** 2 + (y - n / 2) ** 2 < r * r


def test_interior_drops_exactly_the_silhouette_ring():
    m = disc()
    keep = interior(m)
    ring = m & ~keep
    assert keep.sum() > 0 and ring.sum() > 0
    # every ring pixel has a 4-neighbour off the object; every kept one has none
    off = ~m
    near_off = np.zeros_like(m)
    near_off[1:] |= off[:-1]
    near_off[:-1] |= off[1:]
    near_off[:, 1:] |= off[:, :-1]
    near_off[:, :-1] |= off[:, 1:]
    assert np.array_equal(ring, m & near_off)


def test_usable_pixels_leave_out_the_ring_the_user_mask_and_a_clipping_plateau():
    m = disc()
    img = np.full(m.shape + (3,), 0.5)
    img[10, 10] = 2.0                                    # a lone brightest pixel: a highlight, kept
    assert not saturated(img).any()
    assert np.array_equal(usable_pixels(m, img), interior(m))
    user = np.ones_like(m)
    user[:, :10] = False
    assert np.array_equal(usable_pixels(m, img, user), interior(m) & user)
    img[8:10, 8:10] = 2.0                                # a plateau of 5 pixels at the maximum: clipped
    keep = usable_pixels(m, img)
    assert not keep[8:10, 8:10].any() and not keep[10, 10] and keep[11, 11]


def global_plateau(image):
    """The clipping rule before per-channel plateaus: any channel at the image's
    maximum, shared by at least 4 pixels."""
    at_top = np.any(image >= image.max() * (1 - 1e-6), axis=2)
    return at_top if at_top.sum() >= 4 else np.zeros(at_top.shape, bool)


def test_each_channel_clips_at_its_own_plateau():
    """White balance after clipping: red clips at 0.8, below green's maximum (a lone
    highlight); the red plateau is clipped, which the image's maximum does not show."""
    m = disc()
    img = np.full(m.shape + (3,), 0.3)
    img[10, 10] = (0.5, 1.5, 0.6)                        # a lone highlight in green: not clipping
    img[6:8, 8:11, 0] = 0.8                              # red's maximum on 6 pixels: clipped
    assert not global_plateau(img).any()
    sat = saturated(img)
    assert sat[6:8, 8:11].all() and sat.sum() == 6
    keep = usable_pixels(m, img)
    assert not keep[6:8, 8:11].any() and keep[10, 10]
    img[..., 2] = 0.0                                    # a black channel is not a plateau
    assert saturated(img).sum() == 6


def test_no_clipping_leaves_the_usable_pixels_as_before():
    rng = np.random.default_rng(0)
    m = disc(31, 12.0)
    for _ in range(20):
        img = rng.uniform(0, 1, m.shape + (3,)) ** 3
        assert np.array_equal(saturated(img), global_plateau(img))
        assert np.array_equal(usable_pixels(m, img), interior(m) & ~global_plateau(img))
    img[3:6, 3:6] = img.max()                            # a plateau at the image's maximum: as before
    assert np.array_equal(saturated(img), global_plateau(img)) and saturated(img)[3:6, 3:6].all()


def test_white_level_clips_each_channel_and_is_checked():
    m = disc()
    img = np.random.default_rng(1).uniform(0.1, 0.3, m.shape + (3,))
    img[8, 8] = (0.9, 0.2, 0.2)
    img[9, 9] = (0.2, 0.2, 0.7)
    np.testing.assert_array_equal(white_levels(0.5), [0.5, 0.5, 0.5])
    np.testing.assert_array_equal(white_levels([0.9, 1.0, 0.7]), [0.9, 1.0, 0.7])
    assert white_levels(None) is None
    sat = saturated(img, white_levels([0.9, 1.0, 0.7]))
    assert sat[8, 8] and sat[9, 9] and sat.sum() == 2
    assert saturated(img, white_levels(1.0)).sum() == 0
    keep = usable_pixels(np.ones(m.shape, bool), img, white_level=white_levels([0.9, 1.0, 0.7]))
    assert not keep[8, 8] and not keep[9, 9] and keep.sum() == keep.size - 2
    user = np.zeros(m.shape, bool)
    user[:, :9] = True
    assert np.array_equal(usable_pixels(m, img, user, white_levels([0.9, 1.0, 0.7])),
                          usable_pixels(m, img) & keep & user)
    assert np.array_equal(usable_pixels(m, img, user, None), usable_pixels(m, img) & user)
    assert np.array_equal(usable_pixels(m, img), interior(m))
    for bad, words in ((float("nan"), "finite and > 0"), (0, "finite and > 0"), (-1.0, "finite and > 0"),
                       ([1.0, float("inf"), 1.0], "finite and > 0"), ([1.0, 2.0], "one value or 3"),
                       ("high", "one number or 3")):
        with pytest.raises(InputError, match="--white-level") as e:
            white_levels(bad)
        assert words in str(e.value) and "\n" not in str(e.value)
