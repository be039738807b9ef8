"""Files in and out: HDR images, masks, previews, result folders.

Every reader checks what it reads and raises :class:`~mi_dsbrdf.errors.InputError`
with the file's name and what is wrong.
"""
from __future__ import annotations

import os

import mitsuba as mi
import numpy as np

from mi_dsbrdf.errors import InputError


def read_image(path) -> np.ndarray:
    """(H, W, 3) float64 from an EXR/HDR/PNG file; InputError if missing or unreadable."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError("image %s does not exist" % path)
    try:
        bmp = mi.Bitmap(path)
    except Exception as e:  # noqa: BLE001  (Mitsuba raises RuntimeError subclasses with varied text)
        raise InputError("image %s is unreadable: %s" % (path, str(e).splitlines()[-1])) from None
    a = np.array(bmp, dtype=np.float64)
    if a.ndim == 2:
        a = a[..., None]
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    return a[..., :3]


def read_mask(path, shape) -> np.ndarray:
    """(H, W) bool: pixels brighter than half the mask file's maximum (PNG 0-255 or float)."""
    a = read_image(path).mean(axis=2)
    m = a > 0.5 * a.max() if a.max() > 0 else np.zeros(a.shape, bool)
    if m.shape != shape:
        raise InputError("mask %s is %dx%d but the image is %dx%d" % (path, m.shape[1], m.shape[0], shape[1], shape[0]))
    if not m.any():
        raise InputError("mask %s is empty: no pixel to recover from" % path)
    return m


def check_image(image, film_size, path="image") -> None:
    """InputError for size mismatch, non-finite, negative or all-black images."""
    h, w = image.shape[:2]
    if (w, h) != tuple(film_size):
        raise InputError("%s is %dx%d but the scene's film is %dx%d" % (path, w, h, film_size[0], film_size[1]))
    bad = ~np.isfinite(image)
    if bad.any():
        raise InputError("%s has %d NaN/Inf values (first at pixel %s)" % (
            path, int(bad.sum()), tuple(int(v) for v in np.argwhere(bad)[0][:2][::-1])))
    if (image < 0).any():
        raise InputError("%s has %d negative values: an HDR image of radiance is >= 0" % (path, int((image < 0).sum())))
    if not (image > 0).any():
        raise InputError("%s is black everywhere: nothing to recover" % path)


def saturated(image) -> np.ndarray:
    """(H, W) bool: pixels on a clipping plateau (a channel at the image's maximum,
    shared by at least 4 pixels); a lone brightest pixel is a highlight, not clipping."""
    top = image.max()
    at_top = np.any(image >= top * (1 - 1e-6), axis=2)
    return at_top if at_top.sum() >= 4 else np.zeros(at_top.shape, bool)


def prepare_out(path, force) -> None:
    if os.path.exists(path) and os.listdir(path) and not force:
        raise InputError("output directory %s exists and is not empty; pass --force to write into it" % path)
    os.makedirs(path, exist_ok=True)


def write_exr(path, image) -> None:
    """Write an (H, W, 3) float array as a float32 RGB EXR."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32), mi.Bitmap.PixelFormat.RGB).write(os.fspath(path))


def save_preview(image, path, exposure=0.0) -> None:
    """sRGB PNG of a linear HDR image (scaled by 2^exposure, clipped)."""
    img = np.ascontiguousarray(np.asarray(image, dtype=np.float32) * 2.0 ** exposure)
    bmp = mi.Bitmap(img, mi.Bitmap.PixelFormat.RGB)
    bmp.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(os.fspath(path))
