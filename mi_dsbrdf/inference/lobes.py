"""Fast forward model of a ``dsbrdf`` object: the texel sum with Eq. 4 evaluated
on each pixel-texel pair's stored angles, and its exact derivatives in closed form.

:class:`~mi_dsbrdf.inference.forward.TexelSum` evaluates any Mitsuba BSDF
through its plugin and differentiates it by Dr.Jit's forward-mode AD, one
parameter per pass: the plain reference, which the tests hold this module to.
Inference only ever needs the DSBRDF, which sees a pair through three numbers
(log cos theta_h, theta_d and the weight cos theta_o * solid angle * visibility,
:meth:`~mi_dsbrdf.inference.forward.TexelSum.pair_geometry`) and whose
derivatives by the spline control values (:mod:`mi_dsbrdf.brdf.curves`) are

    lobe_r = expm1(u_r),   u_r = kappa_r(theta_d) exp(x_r),   x_r = gamma_r(theta_d) log cos theta_h
    d lobe_r / d a_rm = e^{u_r} u_r B_m(theta_d)                    (a: log kappa control values)
    d lobe_r / d g_rm = e^{u_r} kappa_r x_r e^{x_r} B_m(theta_d)    (g: log gamma control values)

(a curve clamp never binds: the control values are clamped, and the B-spline
weights are >= 0 and sum to one). So :class:`LobeSum` stores the three numbers
once per view and light, and one Dr.Jit kernel evaluates every lobe and all 36
derivative columns; the sums over texels are float32 BLAS products with the
map. With highlight pairs (:mod:`~mi_dsbrdf.inference.highlights`) the same
values and columns are summed over each pair's lanes in a Dr.Jit loop and added to
its texel's. Hand-written for speed: the
plugin path needs one forward-mode pass per column and re-derives the angles in
every pass. The kernel is Dr.Jit code of the active variant (``cuda_ad_rgb``
runs it on a GPU); the BLAS products run on the CPU.
"""
from __future__ import annotations

import dataclasses
import functools

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_dsbrdf.brdf.curves import N_CONTROL, spline_basis
from mi_dsbrdf.brdf.dsbrdf import LOG_COS_H_MIN, lobe_curves, lobe_rgb, lobe_value
from mi_dsbrdf.brdf.observed import N_CELLS, DirectionWeights, cell_sums
from mi_dsbrdf.inference.bounce import compact_pairs
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.inference.transport import apply_transport, unit_scaled

#: materials whose sums over a light's bounce pairs are kept (LobeSum._bounce_sums)
MEMO_MATERIALS = 4
#: pairs per kernel launch: the transport writes 3 floats a pair (a 128x128 sphere
#: under a 32x64 map, 24.5M pairs, in one launch), the Jacobian 39
VALUE_CHUNK, JACOBIAN_CHUNK = 1 << 25, 1 << 22


@dataclasses.dataclass(frozen=True)
class LobeJacobian:
    """Pixel radiance and its derivatives under a fixed light.

    image : (P, 3) radiance
    controls : (R, 2, 6, 3, P) d radiance / d control value (``[r, 0, m]``
        log kappa, ``[r, 1, m]`` log gamma of lobe r)
    chromaticity : (R, 3, P) d radiance_c / d chromaticity_{r, c} (channel c
        depends on its own chromaticity only)

    Variable- and channel-major, pixels last: the chain rule to psi is one
    matrix product over contiguous rows, and every elementwise step loops over
    pixels (faster than pixel-major with the 3 channels innermost).
    """
    image: np.ndarray
    controls: np.ndarray
    chromaticity: np.ndarray


class LobeSum:
    """The view of a :class:`~mi_dsbrdf.inference.forward.TexelSum` (its pixels,
    light and visibility) for DSBRDF materials given as
    :class:`~mi_dsbrdf.brdf.dsbrdf.Material`. Immutable, like the TexelSum."""

    def __init__(self, texels: TexelSum):
        self.texels = texels
        self.n_pixels, self.n_texels = texels.n_pixels, texels.n_texels
        self.n_directions = texels.n_directions              # pairs per pixel: texels x samples

    @functools.cached_property
    def geometry(self) -> tuple:
        """(log cos theta_h, theta_d, weight) of every pair (computed on first use:
        a light search re-aims views it never renders)."""
        return self.texels.pair_geometry()

    @functools.cached_property
    def highlight_geometry(self) -> tuple:
        """(log cos theta_h, theta_d, weight) of the highlight pairs' lanes
        (:meth:`HighlightPairs.geometry <mi_dsbrdf.inference.highlights.HighlightPairs.geometry>`),
        or None without them."""
        h = self.texels.highlights
        return None if h is None else h.geometry()

    @functools.cached_property
    def bounce_geometry(self) -> list:
        """Per :class:`~mi_dsbrdf.inference.bounce.Bounce` of the view: the
        (log cos theta_h, theta_d, weight) of the pairs it blocks, compacted
        (:func:`~mi_dsbrdf.inference.bounce.compact_pairs`): a map's own pairs, or
        its ``pairs`` view's (a light's map of directions, shared by its lights)."""
        out = []
        for k, b in enumerate(self.texels.bounces):
            if b.pairs is None:
                dense = (*self.geometry[:2], self.texels.pair_geometry(b.blocked)[2])
                out.append(compact_pairs(dense, b.blocked))
            else:
                out.append(b.pairs.geometry[k])
        return out

    def _bounce_sums(self, terms, n_terms, chunk, material, kind):
        """Per bounce: yield (its index, p0, p1, (n_terms, p1 - p0)): each pixel's sum
        over all the pairs it blocks of ``terms(lc, td, w)`` for ``material`` (``kind``
        names the terms). Under a light they are kept for the next light
        (:attr:`SurfacePairs.memo <mi_dsbrdf.inference.bounce.SurfacePairs.memo>`)."""
        for k, (geometry, first, counts) in enumerate(self.bounce_geometry):
            pairs = self.texels.bounces[k].pairs
            memo = {} if pairs is None else pairs.memo
            key = (kind, k, material.log_kappa.tobytes(), material.log_gamma.tobytes(),
                   material.chromaticity.tobytes(), np.asarray(material.knots).tobytes())
            rows = memo.get(key)
            if rows is None:
                rows = list(self._ragged_sums(geometry, first, counts, terms, n_terms, chunk))
                while len(memo) >= MEMO_MATERIALS:
                    memo.pop(next(iter(memo)))
                memo[key] = rows
            for p0, p1, sums in rows:
                yield k, p0, p1, sums

    @functools.cached_property
    def unseen(self) -> np.ndarray:
        """(T,) bool: texels no observed pixel can receive light from, whatever the
        material: below every pixel's horizon, or blocked. (A test on the transport
        instead, relative to its largest entry, hid most of a map behind one sharp
        lobe's peak.)"""
        seen = (self.texels.texel_sums(self.geometry[2], self.n_pixels) > 0).any(axis=0)   # weights >= 0
        h = self.texels.highlights
        if h is not None:
            lit = dr.block_sum(self.highlight_geometry[2], h.per_pair).numpy() > 0
            seen[h.texels.reshape(-1)[lit]] = True
        for b, (geometry, _, _) in zip(self.texels.bounces, self.bounce_geometry):   # seen through its light
            if dr.width(geometry[2]) and dr.max(geometry[2])[0] > 0:
                seen |= b.weights > 0
        return ~seen

    def subset(self, rows) -> "LobeSum":
        """The same view restricted to the pixels ``texels.pixels[rows]``."""
        return LobeSum(self.texels.subset(rows))

    def with_point(self, position) -> "LobeSum":
        return LobeSum(self.texels.with_point(position))

    def with_directions(self, directions, solid_angles) -> "LobeSum":
        return LobeSum(self.texels.with_directions(directions, solid_angles))

    # --- kernels -----------------------------------------------------------------
    def _rows(self, chunk):
        """Pixel ranges [p0, p1) of at most ``chunk`` pairs, and for each of a texel's
        directions (``texels.per_texel`` of them) the geometry of the range's
        pixel-texel lanes (pixel-major). The kernels sum a texel's directions in
        registers (an evaluated array per direction and a reduction after it
        would double the inference's time at ``texel_samples`` 2)."""
        k = self.texels.per_texel
        step = max(1, chunk // max(self.n_directions, 1))
        if k == 1 and step >= self.n_pixels:
            yield 0, self.n_pixels, [self.geometry]
            return
        for p0 in range(0, self.n_pixels, step):
            p1 = min(p0 + step, self.n_pixels)
            lanes = dr.arange(mi.UInt32, p0 * self.n_texels, p1 * self.n_texels) * k     # direction of pair (p, t, 0)
            yield p0, p1, [[dr.gather(mi.Float, a, lanes + j) for a in self.geometry] for j in range(k)]

    @staticmethod
    def _scalars(material):
        """The material's log kappa, log gamma control values and chromaticity as
        lists (per lobe) of Dr.Jit scalars, gathered from one array: not literals,
        so that a new material does not compile a new kernel (and one fresh array,
        whose kernels hash the same on every call)."""
        R = material.n_lobes
        buf = mi.Float(np.concatenate([material.log_kappa.reshape(-1), material.log_gamma.reshape(-1),
                                       material.chromaticity.reshape(-1)]).astype(np.float32))

        def scalars(first, width):
            return [[dr.gather(mi.Float, buf, first + r * width + j) for j in range(width)] for r in range(R)]
        return scalars(0, N_CONTROL), scalars(R * N_CONTROL, N_CONTROL), scalars(2 * R * N_CONTROL, 3)

    def _highlight_sums(self, terms, n_terms, chunk):
        """:meth:`_lane_sums` over the highlight pairs' lanes (K pairs a pixel)."""
        h = self.texels.highlights
        if h is not None:
            yield from self._lane_sums(self.highlight_geometry, h.texels.shape[1], h.per_pair, terms, n_terms, chunk)

    def _ray_sums(self, terms, n_terms, chunk):
        """:meth:`_lane_sums` over a light's rays (``texels.ray_lanes``), one sum a pixel."""
        yield from self._lane_sums(self.geometry, 1, self.texels.per_texel, terms, n_terms, chunk)

    @staticmethod
    def _lane_sums(geometry, K, m, terms, n_terms, chunk):
        """Yield pixel ranges [p0, p1) of at most ``chunk`` pairs (K a pixel, each of
        ``m`` consecutive lanes of ``geometry``) and each pair's sum over its lanes of
        ``terms(lc, td, w)`` (a list of ``n_terms`` Dr.Jit Floats), as (n_terms,
        p1 - p0, K) float32 (:func:`_loop_sums`)."""
        n_pixels = dr.width(geometry[0]) // (K * m)
        for p0, p1 in pixel_ranges(n_pixels, K, chunk):
            first = dr.arange(mi.UInt32, p0 * K, p1 * K) * m         # each pair's first lane
            yield p0, p1, _loop_sums(geometry, first, m, terms, n_terms).reshape(n_terms, p1 - p0, K)

    @staticmethod
    def _ragged_sums(geometry, first, counts, terms, n_terms, chunk):
        """Yield pixel ranges [p0, p1) and each pixel's sum of ``terms(lc, td, w)``
        over its ``counts`` lanes of ``geometry`` from lane ``first`` (P,), as
        (n_terms, p1 - p0) float32: :meth:`_lane_sums` with a count a pixel."""
        P = counts.size
        for p0, p1 in pixel_ranges(P, max(1, int(np.ceil(counts.mean()))) if P else 1, chunk):
            yield p0, p1, _loop_sums(geometry, mi.UInt32(first[p0:p1]), mi.UInt32(counts[p0:p1]), terms, n_terms)

    def _rgb(self, material):
        """The terms of the image: ``rgb(lc, td, w)``, weight * Eq. 4 per colour channel."""
        lk, lg, ch = self._scalars(material)

        def rgb(lc, td, w):
            return [w * v for v in lobe_rgb(lc, td, lk, lg, ch, material.knots)]
        return rgb

    def _channels(self, material, out):
        """Fill ``out`` (3, P, T) with weight * Eq. 4 per colour channel."""
        rgb = self._rgb(material)
        if self.texels.ray_lanes:
            for p0, p1, sums in self._ray_sums(rgb, 3, VALUE_CHUNK):
                out[:, p0:p1] = sums
            return out
        for p0, p1, directions in self._rows(VALUE_CHUNK):
            total = 0.0
            for lc, td, w in directions:
                total = total + mi.Color3f(*rgb(lc, td, w))
            dr.eval(total)
            for c in range(3):
                out[c, p0:p1] = total[c].numpy().reshape(p1 - p0, self.n_texels)
        for p0, p1, sums in self._highlight_sums(rgb, 3, VALUE_CHUNK):
            self.texels.highlights.add_to(out, sums, p0)
        return out

    def transport(self, material) -> np.ndarray:
        """(3, P, T) float32 transport of :meth:`TexelSum.transport`:
        radiance[p, c] = T[c, p] @ L[:, c]; with the view's bounces, their rank-one
        terms (:mod:`~mi_dsbrdf.inference.bounce`)."""
        out = self._channels(material, np.empty((3, self.n_pixels, self.n_texels), np.float32))
        if self.texels.bounces:
            for k, p0, p1, b in self._bounce_sums(self._rgb(material), 3, VALUE_CHUNK, material, "rgb"):
                m = self.texels.bounces[k].transport_term.astype(np.float32)
                for c in range(3):                   # in float32, a channel at a time: no large temporaries
                    out[c, p0:p1] += np.multiply.outer(b[c].astype(np.float32), m[c])
        return out

    def render(self, material, illumination) -> np.ndarray:
        """(P, 3) float64 radiance under ``illumination`` (T, 3)."""
        return apply_transport(self.transport(material), illumination)

    def _column_sums(self, terms, n_terms):
        """Yield pixel ranges [p0, p1) and the sums of ``terms(lc, td, w)`` (``n_terms``
        Dr.Jit Floats) over each pixel-texel pair's directions, n_terms arrays (p1 - p0,
        T) float32: a light's rays in a Dr.Jit loop (:meth:`_ray_sums`), a map texel's
        directions in registers (:meth:`_rows`)."""
        if self.texels.ray_lanes:
            yield from self._ray_sums(terms, n_terms, JACOBIAN_CHUNK)
            return
        for p0, p1, directions in self._rows(JACOBIAN_CHUNK):
            cols = None
            for lc, td, w in directions:            # a texel's directions, summed in the kernel
                values = terms(lc, td, w)
                cols = values if cols is None else [a + b for a, b in zip(cols, values)]
            dr.eval(*cols)
            yield p0, p1, [c.numpy().reshape(p1 - p0, self.n_texels) for c in cols]     # not stacked: a copy

    def jacobian(self, material, illumination) -> LobeJacobian:
        """Radiance under ``illumination`` (T, 3) and its exact derivatives by every
        control value and chromaticity of ``material`` (see the module doc)."""
        lk, lg, _ = self._scalars(material)
        R = material.n_lobes
        L, s = unit_scaled(illumination)
        sums = np.empty((R, 1 + 2 * N_CONTROL, 3, self.n_pixels))

        def terms(lc, td, w):
            return _jacobian_terms(lc, td, w, lk, lg, material.knots)
        n_cols = R * (1 + 2 * N_CONTROL)
        for p0, p1, A in self._column_sums(terms, n_cols):          # A: (columns, pixels, texels)
            if self.n_texels == 1:                  # one light: the sum over texels is a product
                flat = L[0][None, :, None] * np.asarray(A)[:, None, :, 0]
            else:
                flat = np.stack([(a @ L).T for a in A])
            sums[..., p0:p1] = flat.reshape(R, 1 + 2 * N_CONTROL, 3, p1 - p0)
        h = self.texels.highlights
        for p0, p1, A in self._highlight_sums(terms, n_cols, JACOBIAN_CHUNK):
            flat = np.einsum("npk,pkc->ncp", A, L[h.texels[p0:p1]])          # A: (columns, pixels, K)
            sums[..., p0:p1] += flat.reshape(R, 1 + 2 * N_CONTROL, 3, p1 - p0)
        for k, p0, p1, A in self._bounce_sums(terms, n_cols, JACOBIAN_CHUNK, material, "jacobian"):
            rad = self.texels.bounces[k].radiance(L)                # (3,): the surface's, under L
            sums[..., p0:p1] += (A[:, None, :] * rad[None, :, None]).reshape(R, 1 + 2 * N_CONTROL, 3, p1 - p0)
        sums *= s
        c = material.chromaticity[:, :, None]                      # (R, 3, 1)
        image = (sums[:, 0] * c).sum(axis=0).T
        d_ctrl = (sums[:, 1:] * c[:, None]).reshape(R, 2, N_CONTROL, 3, self.n_pixels)
        d_chroma = sums[:, 0]                                       # (R, 3, P)
        return LobeJacobian(image, d_ctrl, d_chroma)


def _jacobian_terms(lc, td, w, lk, lg, knots) -> list:
    """Per lobe r: weight * lobe_r, then its derivatives by the log kappa and the
    log gamma control values (module doc), for lanes of geometry (lc, td, w)."""
    basis = spline_basis(td, knots)
    kappa, gamma = lobe_curves(td, lk, lg, knots)
    terms = []
    for k, g in zip(kappa, gamma):
        x = g * dr.fmax(lc, LOG_COS_H_MIN)
        ex = dr.exp(x)
        u = k * ex
        lobe = lobe_value(lc, k, g)
        e = (lobe + 1.0) * w            # e^u * weight (the product's order keeps float32 finite)
        d_kappa, d_gamma = e * u, (e * k) * (x * ex)
        terms += [w * lobe] + [d_kappa * b for b in basis] + [d_gamma * b for b in basis]
    return terms


def _loop_sums(geometry, first, count, terms, n_terms) -> np.ndarray:
    """(n_terms, n) float32: for each of n sums, ``terms(lc, td, w)`` (a list of
    ``n_terms`` Dr.Jit Floats) summed over ``count`` (an int, or a UInt32 a sum)
    consecutive lanes of ``geometry`` from lane ``first`` (UInt32, n). The lanes are
    summed in a Dr.Jit loop: none is stored (a stored lane of 39 Jacobian columns
    made the highlight pairs 8 times the cost of the texel sum's, and a light's rays
    summed after evaluation 1.5 times)."""
    n = dr.width(first)

    def body(j, *acc):
        values = terms(*(dr.gather(mi.Float, a, first + j) for a in geometry))
        return (j + 1,) + tuple(a + v for a, v in zip(acc, values))
    state = (dr.zeros(mi.UInt32, n),) + tuple(dr.zeros(mi.Float, n) for _ in range(n_terms))
    sums = dr.while_loop(state, lambda j, *acc: j < count, body)[1:]
    dr.eval(*sums)
    return np.stack([a.numpy() for a in sums])


def pixel_ranges(n_pixels, n_directions, pairs) -> list:
    """[(p0, p1), ...]: ``n_pixels`` pixels in ranges of at most ``pairs``
    pixel-direction pairs (one pixel at least), each pixel with ``n_directions``."""
    step = max(1, int(pairs) // max(int(n_directions), 1))
    return [(p0, min(p0 + step, n_pixels)) for p0 in range(0, n_pixels, step)]


def observed_directions(texels: TexelSum, illumination, rows, chunk=JACOBIAN_CHUNK) -> DirectionWeights:
    """Where the pixels ``texels.pixels[rows]`` look in (theta_h, theta_d) under
    ``illumination`` (T, 3): every pair's cell (:mod:`~mi_dsbrdf.brdf.observed`)
    weighted by cos theta_o * solid angle * visibility * the grey level (channel
    mean) of its texel's light. Pixels in chunks of at most ``chunk`` pairs (each
    pair's geometry is held in float32 and float64 once: 36 bytes)."""
    grey = np.asarray(illumination, dtype=np.float64).reshape(-1, 3).mean(axis=1)
    nd = texels.n_directions
    light = grey[np.arange(nd) // texels.per_texel]           # (directions,): the light each one carries
    rows = np.asarray(rows, dtype=np.int64)
    total = np.zeros((N_CELLS, N_CELLS))
    for r0, r1 in pixel_ranges(rows.size, nd, chunk):
        view = LobeSum(texels.subset(rows[r0:r1]))
        log_cos, theta_d, weight = (a.numpy().astype(np.float64) for a in view.geometry)
        theta_h = np.arccos(np.clip(np.exp(log_cos), 0.0, 1.0))
        total += cell_sums(theta_h, theta_d, weight.reshape(-1, nd) * light)
        h = view.texels.highlights
        if h is not None:
            log_cos, theta_d, weight = (a.numpy().astype(np.float64) for a in view.highlight_geometry)
            theta_h = np.arccos(np.clip(np.exp(log_cos), 0.0, 1.0))
            total += cell_sums(theta_h, theta_d, weight.reshape(h.texels.size, -1) * grey[h.texels.reshape(-1), None])
    return DirectionWeights(total)


#: pixels a chunk of the highlight check builds the pairs of at once: the check's
#: memory stays a fraction of a pass with the pairs (which only a sharp lobe needs)
CHECK_CHUNK = 1024


def highlight_change(view: TexelSum, rows, material, illumination, highlights, chunk=CHECK_CHUNK) -> float:
    """Relative L1 change, over the pixels ``rows`` of the map view ``view``, of the
    image of ``material`` under ``illumination`` (T, 3) when the highlight pairs of
    ``highlights`` texels a pixel integrate the texels nearest each mirror direction
    over the pixel's area and the texel (:mod:`~mi_dsbrdf.inference.highlights`):
    sum |with - without| / sum |with|, the pairs built ``chunk`` pixels at a time."""
    change = total = 0.0
    for r0 in range(0, len(rows), chunk):
        sub = view.subset(rows[r0:r0 + chunk])
        plain = LobeSum(sub).render(material, illumination)
        pairs = LobeSum(sub.with_highlights(highlights)).render(material, illumination)
        change += float(np.abs(pairs - plain).sum())
        total += float(np.abs(pairs).sum())
    return change / max(total, 1e-300)
