"""Files in and out: HDR images, masks, previews, result folders.

Every reader checks what it reads and raises :class:`~mi_dsbrdf.errors.InputError`
with the file's name and what is wrong.
"""
from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
import time

import mitsuba as mi
import numpy as np

from mi_dsbrdf.errors import InputError
from mi_dsbrdf.inference.images import as_rgb, open_bitmap

#: a staging folder beside a destination older than this (seconds) is a leftover,
#: whatever became of the process that made it
STALE_SECONDS = 24 * 3600


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
    (an earlier result); it is not a mount point; no input file lies inside it;
    its parent can hold the staging folder beside it. Staging folders earlier
    runs left beside it are removed (:func:`clear_leftovers`)."""
    out = os.fspath(out)
    if is_mount(out):
        raise InputError("output %s is a mount point: a result is written beside its folder and renamed into place, "
                         "which a mount point cannot be; give a folder inside it, e.g. %s"
                         % (out, os.path.join(out, "result")))
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
    clear_leftovers(out)


def is_mount(path) -> bool:
    """Whether ``path`` is a mount point: another file system's root
    (``os.path.ismount``) or a bind mount (listed in /proc/self/mountinfo)."""
    path = os.path.abspath(os.fspath(path))
    if os.path.ismount(path):
        return True
    try:
        with open("/proc/self/mountinfo") as f:
            points = {re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), line.split()[4]) for line in f}
    except (OSError, IndexError):
        return False
    return os.path.realpath(path) in points


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


def _staging_prefix(out, kind) -> str:
    """The name prefix of ``out``'s staging folders (and files, :func:`staged_file`)
    of ``kind`` ("partial": the result being written; "old": an earlier result being
    replaced), with this process's id, which tells a later run whether their writer
    is alive."""
    return ".%s.%s-%d-" % (os.path.basename(out), kind, os.getpid())


def _alive(pid) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:             # another user's process (EPERM)
        return True
    return True


def clear_leftovers(out) -> None:
    """Remove the staging folders and files (``.NAME.partial-*``, ``.NAME.old-*``)
    beside ``out`` that earlier runs left (killed while writing): those of a process
    that has ended, or older than a day (:data:`STALE_SECONDS`). InputError
    naming the folder or file for one that may still be written (its process alive,
    or unknown, and younger than a day), and for an ``.old-*`` folder that holds
    an earlier result while ``out`` does not exist (a run stopped while
    replacing it): it is the user's to move back."""
    out = os.path.abspath(os.fspath(out))
    parent, name = os.path.split(out)
    pattern = re.compile(r"^\.%s\.(partial|old)-(?:(\d+)-)?" % re.escape(name))
    try:
        entries = os.listdir(parent)
    except OSError:
        return
    for entry in sorted(entries):
        m = pattern.match(entry)
        path = os.path.join(parent, entry)
        if m is None or os.path.islink(path) or not (os.path.isdir(path) or os.path.isfile(path)):
            continue
        kind, pid = m.group(1), None if m.group(2) is None else int(m.group(2))
        try:
            age = time.time() - os.stat(path).st_mtime
        except OSError:
            continue
        if age < STALE_SECONDS and (pid is None or _alive(pid)):
            raise InputError("%s beside the output is being written by %s: wait for it to finish, or remove "
                             "that %s if no run is writing %s" % (
                                 path, "another process (pid %d)" % pid if pid is not None else "an earlier run",
                                 "folder" if os.path.isdir(path) else "file", out))
        if kind == "old" and not os.path.exists(out) and os.path.exists(os.path.join(path, "result")):
            raise InputError("a run was stopped while replacing %s: the earlier result is in %s; move it back to %s "
                             "or remove it" % (out, os.path.join(path, "result"), out))
        if os.path.isdir(path):
            shutil.rmtree(path, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                os.remove(path)


def umask() -> int:
    """The process's file-mode creation mask (read without changing it where
    /proc tells it)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def staged_output(out, force=False, ours=(), inputs=()):
    """Write a result folder all at once: yields a fresh folder beside ``out``,
    which replaces ``out`` only when the block finishes (:func:`check_out` first).
    The folder gets the permissions of a folder the user makes (0777 less the
    umask).

    An error or an interruption (an exception, KeyboardInterrupt included)
    leaves ``out`` as it was (an earlier result whole, or nothing) and no
    staging folder behind.
    """
    check_out(out, force, ours, inputs)
    out = os.path.abspath(os.fspath(out))
    parent = os.path.dirname(out)
    made = parent                       # the highest folder made here (removed again if the block fails)
    while not os.path.exists(os.path.dirname(made)):
        made = os.path.dirname(made)
    made = None if os.path.exists(made) else made
    try:
        os.makedirs(parent, exist_ok=True)
        tmp = tempfile.mkdtemp(prefix=_staging_prefix(out, "partial"), dir=parent)
    except OSError as e:
        raise InputError("cannot write into %s: %s" % (parent, e.strerror)) from None
    old = None
    try:
        os.chmod(tmp, 0o777 & ~umask())
        yield tmp
        if os.path.exists(out):
            old = tempfile.mkdtemp(prefix=_staging_prefix(out, "old"), dir=parent)
            os.rename(out, os.path.join(old, "result"))
        try:
            os.rename(tmp, out)
        except OSError as e:
            raise InputError("cannot move the result into place at %s: %s" % (out, e.strerror)) from None
    finally:
        if old is not None and not os.path.exists(out) and os.path.isdir(os.path.join(old, "result")):
            os.rename(os.path.join(old, "result"), out)         # the earlier result back in place
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None and os.path.exists(out):
            shutil.rmtree(old, ignore_errors=True)
        if made is not None and not os.path.exists(out):
            _remove_empty(parent, made)


def _remove_empty(folder, top) -> None:
    """Remove ``folder`` and its parents up to ``top`` while they are empty."""
    while True:
        try:
            os.rmdir(folder)
        except OSError:
            return
        if folder == top:
            return
        folder = os.path.dirname(folder)


def staged_file(out_file, force=False):
    """A temporary name beside ``out_file`` to write to, then ``os.replace`` it into
    place: ``.NAME.partial-PID-file.EXT`` (:func:`_staging_prefix`), e.g.
    ``.relit.exr.partial-1234-file.exr`` for ``relit.exr`` (the extension tells the
    writer its format). Staging files earlier runs left beside it are
    removed (:func:`clear_leftovers`). InputError if ``out_file`` has no extension,
    exists without ``force``, is a folder, or its folder does not exist or is not
    writable."""
    out_file = os.path.abspath(os.fspath(out_file))
    if os.path.isdir(out_file):
        raise InputError("output %s is a folder: give a file name" % out_file)
    ext = os.path.splitext(os.path.basename(out_file))[1]
    if not ext:
        raise InputError("output %s has no extension: give a file name ending in its format (.exr, .png)" % out_file)
    if os.path.exists(out_file) and not force:
        raise InputError("%s exists; pass --force to replace it" % out_file)
    folder = os.path.dirname(out_file)
    if not os.path.isdir(folder):
        raise InputError("folder %s of the output does not exist" % folder)
    _probe(folder)
    clear_leftovers(out_file)
    return os.path.join(folder, _staging_prefix(out_file, "partial") + "file" + ext)


def write_exr(path, image) -> None:
    """Write an (H, W, 3) float array as a float32 RGB EXR."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32), mi.Bitmap.PixelFormat.RGB).write(os.fspath(path))


def srgb_bitmap(image, exposure=0.0) -> "mi.Bitmap":
    """8-bit sRGB bitmap of a linear HDR image (H, W, 3) (scaled by 2^exposure, clipped)."""
    img = np.ascontiguousarray(np.asarray(image, dtype=np.float32) * 2.0 ** exposure)
    return mi.Bitmap(img, mi.Bitmap.PixelFormat.RGB).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8,
                                                              srgb_gamma=True)


def save_preview(image, path, exposure=0.0) -> None:
    """sRGB PNG of a linear HDR image (scaled by 2^exposure, clipped)."""
    srgb_bitmap(image, exposure).write(os.fspath(path))
