"""Which pixels of an image the likelihood (Eq. 19) uses: the one rule of the
app (:func:`mi_dsbrdf.recover`) and of every benchmark that scores it.

A pixel is usable when its centre sees the object, its four neighbours do too
(a silhouette pixel of a photograph also sees the background: its value is a
mixture the forward model does not render), it lies inside the user's mask, and
none of its channels is clipped.

A camera clips each channel at its own white level, after white balance scales
the channels: a clipped channel holds its level, not the light. A channel is
clipped on a plateau of its own maximum (:func:`saturated`), or at or above a
white level the user gives (:func:`white_levels`); a pixel with any clipped
channel is left out whole.

Dropping the silhouette ring costs some accuracy on images that have no such
mixture (a render at pixel centres); the benchmarks measure what a user gets,
so they drop it too.
"""
from __future__ import annotations

import math

import numpy as np

from mi_dsbrdf.errors import InputError

#: fewest pixels that share a channel's maximum on a clipping plateau (fewer: a highlight)
MIN_PLATEAU = 4
#: a value within this relative distance below a maximum or a white level is at it
CLIP_TOLERANCE = 1e-6


def interior(mask) -> np.ndarray:
    """(H, W) bool: pixels of ``mask`` (H, W) whose four neighbours are in it too."""
    mask = np.asarray(mask, bool)
    keep = mask.copy()
    for axis in (0, 1):
        for shift in (1, -1):
            keep &= np.roll(mask, shift, axis=axis)
    return keep


def saturated(image, white_level=None) -> np.ndarray:
    """(H, W) bool: pixels of ``image`` (H, W, C) with a clipped channel.

    A channel is clipped where it is on a plateau of its own maximum: at least
    MIN_PLATEAU pixels within CLIP_TOLERANCE of it (a lone brightest pixel is a
    highlight, not clipping); so is any channel value at the image's maximum when
    MIN_PLATEAU pixels share it. With ``white_level`` (C,) (:func:`white_levels`),
    a channel at or above its level is clipped too.
    """
    image = np.asarray(image)
    top = image.max()
    at_top = np.any(image >= top * (1 - CLIP_TOLERANCE), axis=2)
    out = at_top if at_top.sum() >= MIN_PLATEAU else np.zeros(at_top.shape, bool)
    for c in range(image.shape[2]):
        channel = image[..., c]
        level = channel.max()
        if level > 0:
            plateau = channel >= level * (1 - CLIP_TOLERANCE)
            if plateau.sum() >= MIN_PLATEAU:
                out = out | plateau
        if white_level is not None:
            out = out | (channel >= white_level[c] * (1 - CLIP_TOLERANCE))
    return out


def white_levels(value, channels=3):
    """(channels,) float64 white levels of the image's channels, from one number
    (every channel) or one per channel (R G B); None for None. InputError naming
    ``--white-level`` unless finite and > 0."""
    if value is None:
        return None
    try:
        levels = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InputError("--white-level (white_level) must be one number or %d, got %r" % (channels, value)) from None
    if levels.size not in (1, channels):
        raise InputError("--white-level (white_level) takes one value or %d (one per channel R G B), got %d"
                         % (channels, levels.size))
    if not all(math.isfinite(v) and v > 0 for v in levels):
        raise InputError("--white-level (white_level) must be finite and > 0, got %s"
                         % " ".join("%g" % v for v in levels))
    return np.broadcast_to(levels, (channels,)).copy()


def usable_pixels(object_mask, image, user_mask=None, white_level=None) -> np.ndarray:
    """(H, W) bool: the pixels inference uses (module doc). ``object_mask`` (H, W):
    pixels whose centre sees the object (``TexelSum.mask``); ``image`` (H, W, C);
    ``user_mask`` (H, W) bool or None; ``white_level`` (C,) or None
    (:func:`white_levels`)."""
    keep = interior(object_mask)
    if user_mask is not None:
        keep &= np.asarray(user_mask, bool)
    return keep & ~saturated(image, white_level)


def image_level(observed, mask) -> float:
    """The mean of the usable pixels (``mask`` (H, W)) of ``observed`` (H, W, C), over
    channels: the image's units (InputError if not finite and > 0)."""
    px = np.asarray(observed, dtype=np.float64)[np.asarray(mask, bool)]
    level = float(px[..., :3].mean()) if px.size else 0.0
    if not (np.isfinite(level) and level > 0):
        raise InputError("the usable pixels' mean must be finite and > 0, got %r" % level)
    return level
