"""Which pixels of an image the likelihood (Eq. 19) uses: the one rule of the
app (:func:`mi_dsbrdf.recover`) and of every benchmark that scores it.

A pixel is usable when its centre sees the object, its four neighbours do too
(a silhouette pixel of a photograph also sees the background: its value is a
mixture the forward model does not render), it lies inside the user's mask, and
it is not on a clipping plateau.

Dropping the silhouette ring costs some accuracy on images that have no such
mixture (a render at pixel centres); the benchmarks measure what a user gets,
so they drop it too.
"""
from __future__ import annotations

import numpy as np


def interior(mask) -> np.ndarray:
    """(H, W) bool: pixels of ``mask`` (H, W) whose four neighbours are in it too."""
    mask = np.asarray(mask, bool)
    keep = mask.copy()
    for axis in (0, 1):
        for shift in (1, -1):
            keep &= np.roll(mask, shift, axis=axis)
    return keep


def saturated(image) -> np.ndarray:
    """(H, W) bool: pixels of ``image`` (H, W, C) on a clipping plateau (a channel at
    the image's maximum, shared by at least 4 pixels); a lone brightest pixel is a
    highlight, not clipping."""
    image = np.asarray(image)
    top = image.max()
    at_top = np.any(image >= top * (1 - 1e-6), axis=2)
    return at_top if at_top.sum() >= 4 else np.zeros(at_top.shape, bool)


def usable_pixels(object_mask, image, user_mask=None) -> np.ndarray:
    """(H, W) bool: the pixels inference uses (module doc). ``object_mask`` (H, W):
    pixels whose centre sees the object (``TexelSum.mask``); ``image`` (H, W, C);
    ``user_mask`` (H, W) bool or None."""
    keep = interior(object_mask)
    if user_mask is not None:
        keep &= np.asarray(user_mask, bool)
    return keep & ~saturated(image)
