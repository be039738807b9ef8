"""The pixels inference uses (mi_dsbrdf.inference.pixels): one rule for the app
and the benchmarks that score it."""
import numpy as np

from mi_dsbrdf.inference.pixels import interior, saturated, usable_pixels


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
