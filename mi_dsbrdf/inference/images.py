"""Image files read as linear radiance: what inference takes in.

Every reader checks what it reads and raises :class:`~mi_dsbrdf.errors.InputError`
with the file's name and what is wrong. The app's file handling
(:mod:`mi_dsbrdf.app.io`) and the evaluation's probes read images through these.
"""
from __future__ import annotations

import os

import mitsuba as mi
import numpy as np

from mi_dsbrdf.errors import InputError


def open_bitmap(path, what="image"):
    """The ``mi.Bitmap`` of an image file; InputError (naming ``what`` and the file) if
    it is missing, a folder or unreadable."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError("%s %s does not exist" % (what, path))
    if os.path.isdir(path):
        raise InputError("%s %s is a folder, not an image file" % (what, path))
    try:
        return mi.Bitmap(path)
    except Exception as e:  # noqa: BLE001  (Mitsuba raises RuntimeError subclasses with varied text)
        raise InputError("%s %s is unreadable: %s" % (what, path, str(e).splitlines()[-1])) from None


def as_rgb(a) -> np.ndarray:
    """(H, W, 3) float64 copy of (H, W) or (H, W, C) pixels: grey (with or without
    alpha) repeated, RGB(A) cut to RGB."""
    a = np.array(a, dtype=np.float64)
    if a.ndim == 2:
        a = a[..., None]
    if a.shape[2] <= 2:
        a = np.repeat(a[..., :1], 3, axis=2)
    return a[..., :3]


def srgb_to_linear(v) -> np.ndarray:
    """The sRGB transfer function inverted (IEC 61966-2-1), on values in [0, 1]."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def as_radiance(pixels, srgb=False, what="image") -> np.ndarray:
    """(H, W, 3) float64 linear radiance from (H, W[, C]) pixels, a copy.

    8- or 16-bit integer pixels (a PNG or JPEG, or a uint8/uint16 array) hold
    display values: with ``srgb`` they are linearised by the sRGB curve to [0, 1],
    without it an InputError names the fix (a raw 8-bit value taken as radiance
    is wrong by the curve and a factor of 255). ``srgb`` with any other pixels is
    an InputError too (float radiance is linear already: the curve would silently
    not apply).
    """
    a = np.asarray(pixels)
    if srgb and a.dtype not in (np.uint8, np.uint16):
        raise InputError("%s holds %s values, which are linear radiance already: --srgb (srgb=True) linearises "
                         "8- or 16-bit display values (PNG/JPEG); leave it out" % (what, a.dtype))
    if a.dtype in (np.uint8, np.uint16):
        if not srgb:
            raise InputError("%s holds %d-bit display values, not radiance: give a linear HDR image (EXR/HDR)%s"
                             % (what, 8 * a.itemsize, "" if what.startswith("envmap") else
                                ", or pass --srgb (srgb=True) to linearise it from sRGB"))
        a = srgb_to_linear(a / float(np.iinfo(a.dtype).max))
    if not np.issubdtype(a.dtype, np.number) or a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] > 4):
        raise InputError("%s must be an (H, W, 3) array of radiance, got %s of shape %s" % (what, a.dtype, a.shape))
    return as_rgb(a)


def read_image(path, srgb=False, what="image") -> np.ndarray:
    """(H, W, 3) float64 linear radiance from an image file (:func:`as_radiance`:
    an 8- or 16-bit file only with ``srgb``, and ``srgb`` only for one);
    InputError if missing or unreadable."""
    return as_radiance(np.array(open_bitmap(path, what)), srgb, "%s %s" % (what, os.fspath(path)))
