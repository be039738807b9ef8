"""Photographs at their own size: the working grid, the chunked re-render and the
memory estimate made before any work.

An image whose film has more than ``Config.working_pixels`` pixels is cropped to the
rows and columns of the object (inside the mask, if any) and block-averaged by the
smallest integer factor k that fits (:func:`working_grid`, :func:`block_factor`):
inference renders one ray through the centre of each k x k block
(:class:`BlockView`: the scene's own camera, whatever its kind) and compares it with
the block's mean. A working pixel is used only if every pixel of its block is usable
at full size (on the object, inside the mask, off the silhouette, unclipped:
:func:`usable_blocks`). The re-render is rendered on the working grid in chunks of
pixels (:func:`rerender`) and shown at full size. A film within
``Config.working_pixels`` is the working grid itself, and nothing changes.

The memory these need is estimated before the work by :mod:`mi_dsbrdf.app.memory`.
"""
from __future__ import annotations

import dataclasses
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_dsbrdf.inference.rays import centre_hits
from mi_dsbrdf.inference.lobes import LobeSum, pixel_ranges
from mi_dsbrdf.inference.pixels import usable_pixels

#: film pixels whose rays are traced at once when the full-size object mask is found
#: (:func:`object_mask`): a SurfaceInteraction is about 200 bytes a ray
TRACE_PIXELS = 1 << 20


def block_factor(size, working_pixels) -> int:
    """The smallest integer k with ceil(W / k) * ceil(H / k) <= ``working_pixels``
    for a region of ``size`` (W, H) pixels (1 when it fits)."""
    W, H = (int(v) for v in size)
    k = max(1, math.isqrt(W * H // max(int(working_pixels), 1)))    # below it the product is too large
    while -(-W // k) * -(-H // k) > working_pixels:
        k += 1
    return k


@dataclasses.dataclass(frozen=True)
class WorkingGrid:
    """The grid inference works on: ``working`` (h, w) blocks of ``block`` x ``block``
    pixels of a film of ``image`` (H, W) pixels, the first block's top-left pixel at
    ``origin`` (row, column) (the last row and column of blocks may reach past the
    film). The whole film at block 1 is the image itself."""
    image: tuple
    working: tuple
    block: int
    origin: tuple = (0, 0)

    @classmethod
    def of(cls, size, working_pixels, region=None) -> "WorkingGrid":
        """The grid of a film of ``size`` (W, H) under ``Config.working_pixels``: the
        whole film at block 1 when it fits, else the pixel rows and columns
        ``region`` ((r0, r1), (c0, c1), ends exclusive; default the whole film) in
        blocks of the smallest factor that fits."""
        W, H = (int(v) for v in size)
        if W * H <= working_pixels or region is None:
            (r0, r1), (c0, c1) = (0, H), (0, W)
        else:
            (r0, r1), (c0, c1) = region
        k = block_factor((c1 - c0, r1 - r0), working_pixels)
        return cls((H, W), (-(-(r1 - r0) // k), -(-(c1 - c0) // k)), k, (int(r0), int(c0)))

    @property
    def whole(self) -> bool:
        """Whether the grid is the film itself (block 1, no crop)."""
        return self.block == 1 and self.working == self.image

    def log(self) -> dict:
        """{"image": [H, W], "working": [h, w], "block": k, "origin": [row, column]}
        (``log.json``)."""
        return {"image": list(self.image), "working": list(self.working), "block": self.block,
                "origin": list(self.origin)}

    def _blocks(self, a, fill):
        """The grid's part of ``a`` (H, W, ...), padded with ``fill`` past the film and
        split into blocks: (h, k, w, k, ...)."""
        (h, w), k, (r0, c0) = self.working, self.block, self.origin
        a = a[r0:r0 + h * k, c0:c0 + w * k]
        pad = [(0, h * k - a.shape[0]), (0, w * k - a.shape[1])] + [(0, 0)] * (a.ndim - 2)
        if pad[0][1] or pad[1][1]:
            a = np.pad(a, pad, constant_values=fill)
        return a.reshape((h, k, w, k) + a.shape[2:])

    def all(self, mask) -> np.ndarray:
        """(h, w) bool: the blocks whose every pixel is in ``mask`` (H, W) (pixels past
        the film are not)."""
        if self.whole:
            return np.asarray(mask, bool)
        return self._blocks(np.asarray(mask, bool), False).all(axis=(1, 3))

    def mean(self, image) -> np.ndarray:
        """(h, w, C) float64: each block's mean of ``image`` (H, W, C), over its pixels
        on the film."""
        if self.whole:
            return image
        (H, W), (h, w), k, (r0, c0) = self.image, self.working, self.block, self.origin
        sums = self._blocks(np.asarray(image), 0).sum(axis=(1, 3), dtype=np.float64)
        rows = np.minimum(H - r0 - k * np.arange(h), k)
        cols = np.minimum(W - c0 - k * np.arange(w), k)
        return sums / (rows[:, None] * cols[None, :])[..., None]

    def repeat(self, a) -> np.ndarray:
        """``a`` (h, w, ...) at full size (H, W, ...): each block's value on its
        pixels, zero outside the grid."""
        if self.whole:
            return a
        (H, W), (h, w), k, (r0, c0) = self.image, self.working, self.block, self.origin
        out = np.zeros((H, W) + a.shape[2:], a.dtype)
        cols = min(w * k, W - c0)
        wide = np.repeat(a, k, axis=1)[:, :cols]          # (h, cols, ...): 1/k of the film's rows
        for i in range(k):                                  # film rows r0 + i, r0 + i + k, ...
            rows = out[r0 + i:r0 + h * k:k, c0:c0 + cols]
            rows[...] = wide[:rows.shape[0]]
        return out


def object_region(mask) -> tuple:
    """((r0, r1), (c0, c1)): the rows and columns (ends exclusive) of the pixels of
    ``mask`` (H, W); the whole film when it is empty."""
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    if rows.size == 0:
        return (0, mask.shape[0]), (0, mask.shape[1])
    return (int(rows[0]), int(rows[-1]) + 1), (int(cols[0]), int(cols[-1]) + 1)


class _Film:
    def __init__(self, size):
        self._size = size

    def crop_size(self):
        return self._size


class _BlockSensor:
    """A sensor seen as a grid of ``cells`` (w, h), each ``block`` x ``block`` pixels of
    the real sensor's film, its top-left at the film's pixel ``origin`` (row,
    column): the ray through a cell's centre is the real sensor's ray through that
    point of its film. What :class:`~mi_dsbrdf.inference.forward.TexelSum` asks of a
    sensor: ``film().crop_size()`` and ``sample_ray``."""

    def __init__(self, sensor, cells, block=1, origin=(0, 0)):
        self._sensor = sensor
        W, H = (int(v) for v in sensor.film().crop_size())
        w, h = (int(v) for v in cells)
        self._scale = (w * block / W, h * block / H)
        self._offset = (origin[1] / W, origin[0] / H)
        self._film = _Film((w, h))

    def film(self):
        return self._film

    def sample_ray(self, time, wavelength, position, aperture):
        uv = mi.Point2f(dr.fma(position.x, self._scale[0], self._offset[0]),
                        dr.fma(position.y, self._scale[1], self._offset[1]))
        return self._sensor.sample_ray(time, wavelength, uv, aperture)


class BlockView:
    """A scene whose camera sees a grid of blocks (:class:`_BlockSensor`): every other
    method is the scene's own (ray tracing, shapes, emitters), so that a
    :class:`~mi_dsbrdf.inference.forward.TexelSum` of it is the working grid's view."""

    def __init__(self, scene, cells, block=1, origin=(0, 0)):
        self._scene = scene
        self._sensor = _BlockSensor(scene.sensors()[0], cells, block, origin)

    def sensors(self):
        return [self._sensor]

    def __getattr__(self, name):
        return getattr(self._scene, name)


def working_scene(scene, grid: WorkingGrid):
    """The scene as inference sees it on ``grid``: itself when the grid is the film."""
    if grid.whole:
        return scene
    h, w = grid.working
    return BlockView(scene, (w, h), grid.block, grid.origin)


def working_grid(scene, shape, user_mask, working_pixels) -> tuple:
    """(the :class:`WorkingGrid` of ``scene``'s film, the film's object mask (H, W) or
    None): the whole film when it has at most ``working_pixels`` pixels, else the
    rows and columns of the pixels that see ``shape`` (and lie inside ``user_mask``,
    (H, W) bool or None) in blocks of the smallest factor that fits."""
    W, H = (int(v) for v in scene.sensors()[0].film().crop_size())
    if W * H <= working_pixels:
        return WorkingGrid.of((W, H), working_pixels), None
    on = object_mask(scene, shape)
    return WorkingGrid.of((W, H), working_pixels, object_region(on if user_mask is None else on & user_mask)), on


def usable_blocks(grid: WorkingGrid, working_mask, on_object, image, user_mask, white_level=None) -> np.ndarray:
    """(h, w) bool: the working pixels inference uses: on the grid's view of the object
    (``working_mask``, ``TexelSum.mask``) with every pixel of the block usable at full
    size (:func:`~mi_dsbrdf.inference.pixels.usable_pixels` of the film's object mask
    ``on_object``, the ``image`` (H, W, 3), ``user_mask`` and ``white_level`` (3,) or
    None). On the film itself, :func:`usable_pixels` of ``working_mask``."""
    if grid.whole:
        return usable_pixels(working_mask, image, user_mask, white_level)
    return grid.all(usable_pixels(on_object, image, user_mask, white_level)) & working_mask


def object_mask(scene, shape, rows=None) -> np.ndarray:
    """(H, W) bool: the film's pixels whose centre sees ``shape`` (as
    :attr:`TexelSum.mask <mi_dsbrdf.inference.forward.TexelSum.mask>`), traced
    ``rows`` film rows at a time (default: about :data:`TRACE_PIXELS` pixels)."""
    W, H = (int(v) for v in scene.sensors()[0].film().crop_size())
    rows = rows or max(1, TRACE_PIXELS // W)
    out = np.zeros((H, W), bool)
    for r0 in range(0, H, rows):
        n = min(rows, H - r0)
        _, hit = centre_hits(scene, _BlockSensor(scene.sensors()[0], (W, n), 1, (r0, 0)), shape)
        out[r0:r0 + n] = hit.reshape(n, W)
    return out


def render_chunks(lit, material, illumination, pairs) -> np.ndarray:
    """(P, 3) float64: :meth:`LobeSum.render <mi_dsbrdf.inference.lobes.LobeSum.render>`
    of the view ``lit`` (a TexelSum) under ``illumination`` (T, 3), at most ``pairs``
    pixel-direction pairs at a time: each pixel's pairs are the numbers of one call
    over all pixels, their float32 sum over texels (BLAS) the same to rounding."""
    ranges = pixel_ranges(lit.n_pixels, lit.n_directions, pairs)
    if len(ranges) == 1:
        return LobeSum(lit).render(material, illumination)
    out = np.empty((lit.n_pixels, 3))
    for p0, p1 in ranges:
        out[p0:p1] = LobeSum(lit.subset(np.arange(p0, p1))).render(material, illumination)
    return out


def _shifted(a, dy, dx, fill):
    """``a`` (h, w, ...) moved by (dy, dx) pixels, ``fill`` where nothing moved in."""
    out = np.full_like(a, fill)
    h, w = a.shape[:2]
    out[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] = a[max(-dy, 0):h - max(dy, 0),
                                                                   max(-dx, 0):w - max(dx, 0)]
    return out


def fill_rim(image, on) -> np.ndarray:
    """``image`` (h, w, 3) with each pixel off ``on`` (h, w) that has an 8-neighbour on
    it given the first such neighbour's value: at full size, a pixel on the object
    whose block's centre missed it takes a neighbouring block's value."""
    out, filled = image.copy(), on.copy()
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1)):
        take = _shifted(on, dy, dx, False) & ~filled
        out[take] = _shifted(image, dy, dx, 0.0)[take]
        filled |= take
    return out


def rerender(grid: WorkingGrid, lit, material, illumination, pairs, on_object=None) -> np.ndarray:
    """(H, W, 3) float64: the image under ``material`` and ``illumination`` (T, 3) as
    inference renders it, on the working grid's view ``lit`` (a TexelSum) in chunks of
    at most ``pairs`` pixel-direction pairs (:func:`render_chunks`), each block's value
    on its pixels that see the object (``on_object`` (H, W), the film's object mask;
    only needed when the grid is not the film)."""
    h, w = grid.working
    if not grid.whole:
        dr.flush_malloc_cache()          # inference's Dr.Jit buffers, before the full-size arrays
    small = np.zeros((h * w, 3))
    small[lit.pixels] = render_chunks(lit, material, illumination, pairs)
    small = small.reshape(h, w, 3)
    if grid.whole:
        return small
    on = np.zeros(h * w, bool)
    on[lit.pixels] = True
    full = grid.repeat(fill_rim(small, on.reshape(h, w)))
    full[~np.asarray(on_object, bool)] = 0.0
    return full
