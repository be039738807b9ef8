"""Files in and out: HDR images, masks, previews, result folders.

Every reader checks what it reads and raises :class:`~mi_dsbrdf.errors.InputError`
with the file's name and what is wrong.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile

import mitsuba as mi
import numpy as np

from mi_dsbrdf.errors import InputError
from mi_dsbrdf.inference.images import (as_radiance, as_rgb, open_bitmap, read_image,  # noqa: F401 (re-exported)
                                        srgb_to_linear)


def read_mask(path, shape) -> np.ndarray:
    """(H, W) bool: pixels brighter than half the mask file's maximum (any format:
    a PNG of 0/255 or a float image); InputError if missing, non-finite, the wrong
    size or empty."""
    a = as_rgb(open_bitmap(path, "mask")).mean(axis=2)
    return as_mask(a, shape, "mask %s" % os.fspath(path))


def as_mask(a, shape, what="mask") -> np.ndarray:
    """(H, W) bool from a mask array (bool, or numbers: above half the maximum);
    InputError if it is non-finite, the wrong size or empty."""
    a = np.asarray(a)
    if a.ndim == 3:
        a = a.mean(axis=2)
    if a.ndim != 2:
        raise InputError("%s must be an (H, W) array, got shape %s" % (what, a.shape))
    if a.dtype != bool:
        a = a.astype(np.float64)
        check_finite(a, what)
        a = a > 0.5 * a.max() if a.max() > 0 else np.zeros(a.shape, bool)
    if a.shape != tuple(shape):
        raise InputError("%s is %dx%d but the image is %dx%d" % (what, a.shape[1], a.shape[0], shape[1], shape[0]))
    if not a.any():
        raise InputError("%s is empty: no pixel to recover from" % what)
    return a


def check_finite(a, what, unit="pixel") -> None:
    """InputError naming the first NaN/Inf of ``a`` (H, W[, C]) as (x, y)."""
    bad = ~np.isfinite(a)
    if bad.any():
        raise InputError("%s has %d NaN/Inf values (first at %s %s)" % (
            what, int(bad.sum()), unit, tuple(int(v) for v in np.argwhere(bad)[0][:2][::-1])))


def check_radiance(a, what, unit="pixel") -> None:
    """InputError for non-finite or negative radiance."""
    check_finite(a, what, unit)
    if (a < 0).any():
        raise InputError("%s has %d negative values: radiance is >= 0" % (what, int((a < 0).sum())))


def check_image(image, path="image") -> None:
    """InputError for non-finite, negative or all-black images."""
    check_radiance(image, path)
    if not (image > 0).any():
        raise InputError("%s is black everywhere: nothing to recover" % path)


def _inside(path, folder) -> bool:
    path, folder = os.path.realpath(path), os.path.realpath(folder)
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def check_out(out, force=False, ours=(), inputs=()) -> None:
    """InputError unless the folder ``out`` can take a new result: it does not
    exist, or is empty, or (with ``force``) holds only files named in ``ours``
    (an earlier result); no input file lies inside it; its parent is writable."""
    out = os.fspath(out)
    for f in inputs:
        if f is not None and _inside(f, out):
            raise InputError("output folder %s holds the input %s: choose another output folder, "
                             "nothing of the input is overwritten" % (out, os.fspath(f)))
    if os.path.exists(out):
        if not os.path.isdir(out):
            raise InputError("output %s is a file, not a folder: choose a folder name" % out)
        names = sorted(os.listdir(out))
        if names and not force:
            raise InputError("output folder %s exists and is not empty; pass --force to replace it" % out)
        foreign = [n for n in names if n not in ours]
        if foreign:
            raise InputError("output folder %s holds files that are not a result of this command (%s): "
                             "choose another output folder" % (out, ", ".join(foreign[:3])))
    parent = os.path.dirname(os.path.abspath(out))
    while not os.path.exists(parent):
        parent = os.path.dirname(parent)
    _probe(parent)


def _probe(folder) -> None:
    """InputError unless a folder can be made in ``folder`` (made and removed, not
    guessed from permission bits: root passes those, and /proc or a read-only
    mount do not)."""
    if not os.path.isdir(folder):
        raise InputError("cannot write into %s: not a folder" % folder)
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".mi-dsbrdf-probe-", dir=folder))
    except OSError as e:
        raise InputError("cannot write into %s: %s" % (folder, e.strerror)) from None


@contextlib.contextmanager
def staged_output(out, force=False, ours=(), inputs=()):
    """Write a result folder all at once: yields a fresh folder beside ``out``,
    which replaces ``out`` only when the block finishes (:func:`check_out` first).

    An error or an interruption leaves ``out`` as it was (an earlier result
    whole, or nothing) and no partial folder behind.
    """
    check_out(out, force, ours, inputs)
    out = os.path.abspath(os.fspath(out))
    parent = os.path.dirname(out)
    try:
        os.makedirs(parent, exist_ok=True)
        tmp = tempfile.mkdtemp(prefix=".%s.partial-" % os.path.basename(out), dir=parent)
    except OSError as e:
        raise InputError("cannot write into %s: %s" % (parent, e.strerror)) from None
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if os.path.exists(out):
        old = tempfile.mkdtemp(prefix=".%s.old-" % os.path.basename(out), dir=parent)
        os.rename(out, os.path.join(old, "result"))
    os.rename(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def staged_file(out_file, force=False):
    """A temporary name beside ``out_file`` to write to, then ``os.replace`` it into
    place (InputError if ``out_file`` exists without ``force``, is a folder, or
    its folder does not exist or is not writable)."""
    out_file = os.path.abspath(os.fspath(out_file))
    if os.path.isdir(out_file):
        raise InputError("output %s is a folder: give a file name" % out_file)
    if os.path.exists(out_file) and not force:
        raise InputError("%s exists; pass --force to replace it" % out_file)
    folder = os.path.dirname(out_file)
    if not os.path.isdir(folder):
        raise InputError("folder %s of the output does not exist" % folder)
    _probe(folder)
    stem, ext = os.path.splitext(os.path.basename(out_file))
    return os.path.join(folder, ".%s.partial%s" % (stem, ext))


def write_exr(path, image) -> None:
    """Write an (H, W, 3) float array as a float32 RGB EXR."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32), mi.Bitmap.PixelFormat.RGB).write(os.fspath(path))


def save_preview(image, path, exposure=0.0) -> None:
    """sRGB PNG of a linear HDR image (scaled by 2^exposure, clipped)."""
    img = np.ascontiguousarray(np.asarray(image, dtype=np.float32) * 2.0 ** exposure)
    bmp = mi.Bitmap(img, mi.Bitmap.PixelFormat.RGB)
    bmp.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(os.fspath(path))
