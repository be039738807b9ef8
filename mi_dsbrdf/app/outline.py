"""A sphere's outline in an image: the circle (cx, cy, r) it covers.

Pixel coordinates: x right, y down, pixel (row i, column j) covers
[j, j + 1] x [i, i + 1], its centre at (j + 0.5, i + 0.5).

* :func:`fit_circle` fits the user's mask (a disc of whole pixels).
* :func:`fit_outline` fits the image itself, without a mask, on a black
  background. The object is every pixel brighter than the background
  (estimated on the image's border) by more than the background's noise, so
  that a dim limb still counts. Its boundary is sampled to sub-pixel precision
  (:func:`boundary_points`), and a circle is fitted to the points that lie on
  one with none outside it (a random-sample consensus, then a soft-L1
  least-squares refinement): where the sphere's unlit side is as black as the
  background, the rest of the boundary is the terminator, inside the outline.
  The outline may leave the frame only where the object touches the frame, and
  the sphere is at most twice the frame's size across.

Without a mask the answer is refused (an InputError asking for one) when it
cannot be trusted:

* a boundary with no terminator (less than :data:`TERMINATOR_SHARE` of it
  :data:`MIN_DEPTH` inside the circle), taken for a whole disc, whose outline
  is not one circle: it covers
  less than :data:`MIN_DISC_ARC` of it (a crescent too thin to tell its two
  edges apart), or circles fitted to its two halves, split along any diameter,
  disagree by more than :data:`MAX_SPLIT` (a lit part that ends just inside
  the outline on one side, which a circle between the two fits);
* a lit part with a terminator that covers more than :data:`MAX_LIT` of the
  disc: the terminator then lies near the outline and bends like it, and no
  fit to the boundary tells them apart;
* a lit part whose outline arc is shorter than :data:`MIN_ARC` of the circle,
  or an object reaching outside the fitted circle.

Measured on rendered spheres of radius 14-30 px in 80x72 images, 4 random
placements each (``tests/test_outline.py`` holds a few): centre and radius
within 0.2 px under a distant light from the camera (a dim limb) or at 90
degrees from it (half lit), 0.4 px at 60-75 degrees, 0.1 px under maps; 0.55 px
for a crescent lit from 150 degrees. Lit 15-60 degrees from the camera the
unlit side is a thin crescent: refused. A point light near the camera lights
less than the visible half; the lit part is then a disc inside the outline
(2 % of the radius smaller at 5 radii, 0.7-1.0 px here), which nothing in the
image tells from the outline.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import ndimage, optimize

from mi_dsbrdf.errors import InputError
from mi_dsbrdf.inference.pixels import interior

#: the fitted circle must cover a mask this well (intersection over union)
MIN_IOU = 0.9
#: a mask's outline: its largest rms distance from the fitted circle, this many
#: pixels or this fraction of the radius if larger
OUTLINE_RMS, OUTLINE_RMS_RELATIVE = 0.5, 0.02
#: fewest outline pixels a circle is fitted to
MIN_OUTLINE = 12

#: width of the image's border the background is estimated on, in pixels
BORDER = 2
#: a pixel differs from the background when it is brighter than the background
#: by this many of the background's noise (standard deviations), and by at
#: least TINY of the object's brightness (its 99th percentile)
NOISE_SIGMAS, TINY = 5.0, 1e-4
#: the background is black when its level is at most this fraction of the
#: object's brightness, or this many of its noise (a camera's noise clipped at 0)
BLACK, BLACK_NOISE = 0.02, 2.0
#: a boundary point lies on the circle within this many pixels, or this
#: fraction of the radius if larger
ON_CIRCLE, ON_CIRCLE_RELATIVE = 0.7, 0.005
#: the outline's points must cover this fraction of the circle's length (of its
#: part inside the frame where the object touches the frame): a lit part's
#: outline, and a whole disc's
MIN_ARC, MIN_DISC_ARC = 0.43, 0.75
#: a terminator is seen (a lit part, not a whole disc) when at least this
#: fraction of the boundary lies more than MIN_DEPTH pixels inside the circle
TERMINATOR_SHARE, MIN_DEPTH = 0.02, 3.0
#: a disc: the circles of the outline's two halves, split along a diameter, lie
#: this many pixels apart at most, or this fraction of the radius if larger
MAX_SPLIT, MAX_SPLIT_RELATIVE = 0.4, 0.005
#: a lit part with a terminator covers at most this fraction of the disc
MAX_LIT = 0.78
#: at most this fraction of the object (and of the boundary points, in the
#: consensus) lies outside the circle by more than ON_CIRCLE
MAX_OUTSIDE = 0.01
#: random three-point circles tried for the consensus
TRIALS = 400
#: most boundary points the consensus and the split test look at
MAX_POINTS = 4000
ASK = "give a mask of the sphere (--mask)"


# --- a mask ------------------------------------------------------------------------

def fit_circle(mask) -> tuple:
    """(cx, cy, r) in pixels of the disc the user's ``mask`` (H, W bool) shows;
    InputError if it is not a disc.

    A circle is fitted by algebraic least squares (Kasa) to the outline pixels
    away from the frame; inside the frame the centroid and the area give the disc
    more precisely. The outline must lie within OUTLINE_RMS of the circle (a
    rasterised disc: 0.25 px) and the circle must cover the mask (MIN_IOU).
    """
    m = np.asarray(mask, bool)
    h, w = m.shape
    ys, xs = np.nonzero(m)
    if xs.size < MIN_OUTLINE:
        raise InputError("the sphere covers %d pixels: too few to fit its outline" % xs.size)
    edge = m & ~interior(m)
    edge[0], edge[-1], edge[:, 0], edge[:, -1] = False, False, False, False
    ey, ex = np.nonzero(edge)
    if ex.size < MIN_OUTLINE:
        raise InputError("the sphere's outline inside the frame has %d pixels: too few to fit it" % ex.size)
    x, y = ex + 0.5, ey + 0.5
    cx, cy, r = _kasa(x, y)
    rms = float(np.sqrt(np.mean((np.hypot(x - cx, y - cy) - r) ** 2)))
    if rms > max(OUTLINE_RMS, OUTLINE_RMS_RELATIVE * r):
        raise InputError("the mask's outline is not a circle (%.2g px rms from the best one): is it a sphere?" % rms)
    on_frame = m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any()
    if on_frame:
        r += 0.5                       # outline pixel centres lie half a pixel inside the disc
    else:
        cx, cy, r = xs.mean() + 0.5, ys.mean() + 0.5, math.sqrt(xs.size / math.pi)
    disc = disc_pixels((h, w), (cx, cy, r))
    iou = (disc & m).sum() / max((disc | m).sum(), 1)
    if iou < MIN_IOU:
        raise InputError("the mask is not a disc (a fitted circle covers it to %.0f %%, need %.0f %%): "
                         "is it a sphere?" % (100 * iou, 100 * MIN_IOU))
    return float(cx), float(cy), float(r)


def disc_pixels(shape, circle):
    """(H, W) bool: the pixels of a frame of ``shape`` whose centre lies in the
    circle (cx, cy, r)."""
    h, w = shape
    cx, cy, r = circle
    out = np.zeros((h, w), bool)
    x0, x1 = max(0, int(math.floor(cx - r))), min(w, int(math.ceil(cx + r)) + 1)
    y0, y1 = max(0, int(math.floor(cy - r))), min(h, int(math.ceil(cy + r)) + 1)
    if x0 < x1 and y0 < y1:
        yy, xx = np.mgrid[y0:y1, x0:x1]
        out[y0:y1, x0:x1] = (xx + 0.5 - cx) ** 2 + (yy + 0.5 - cy) ** 2 <= r * r
    return out


def _kasa(x, y) -> tuple:
    """(cx, cy, r): the algebraic least-squares circle through points (N,) x, y."""
    (a, b, c), *_ = np.linalg.lstsq(np.stack([x, y, np.ones_like(x)], axis=1), x * x + y * y, rcond=None)
    cx, cy = a / 2, b / 2
    return cx, cy, math.sqrt(max(c + cx * cx + cy * cy, 0.0))


# --- the image, without a mask -------------------------------------------------------

def background(lum) -> tuple:
    """(level, noise) of the image's background, from its border of BORDER
    pixels: the median and the median absolute deviation (as a standard
    deviation) of ``lum`` (H, W) there. The object may cover less than half
    of the border."""
    lum = np.asarray(lum, np.float64)
    b = max(1, min(BORDER, min(lum.shape) // 4))
    ring = np.concatenate([lum[:b].ravel(), lum[-b:].ravel(), lum[b:-b, :b].ravel(), lum[b:-b, -b:].ravel()])
    level = float(np.median(ring))
    return level, 1.4826 * float(np.median(np.abs(ring - level)))


def bright_region(image) -> tuple:
    """((H, W) bool region, (H, W) float64 brightness above the background) of the
    object in ``image`` (H, W, C): the pixels brighter than the background by more
    than its noise (NOISE_SIGMAS, TINY), their largest 8-connected part with its
    holes filled. InputError when the background is not black (BLACK), or when
    nothing stands out of it."""
    lum = np.asarray(image, np.float64).mean(axis=2)
    level, noise = background(lum)
    above = lum - level
    standing = above > NOISE_SIGMAS * noise
    top = float(np.percentile(above[standing], 99)) if standing.any() else 0.0
    if level > max(BLACK * top, BLACK_NOISE * noise):
        raise InputError("the image's background is not black (its border is at %.3g%s): without a mask the sphere "
                         "is found against a black background; %s"
                         % (level, ", %.0f %% of the object's brightness" % (100 * level / top) if top else "", ASK))
    if not top > 0:
        raise InputError("no object stands out of the image's background: %s" % ASK)
    region = above > max(NOISE_SIGMAS * noise, TINY * top)
    labels, n = ndimage.label(region, structure=np.ones((3, 3), bool))
    if n > 1:
        region = labels == 1 + int(np.argmax(ndimage.sum_labels(region, labels, np.arange(1, n + 1))))
    return ndimage.binary_fill_holes(region), above


def boundary_points(region, above) -> np.ndarray:
    """(N, 2) points (x, y) on the boundary of ``region`` (H, W bool) inside the
    frame: one per region pixel and 4-neighbour off the region, on the line from
    the pixel's centre to that neighbour's, placed by the pixel's coverage: its
    ``above`` (H, W) over its inner neighbour's, in [0, 1] (1 puts the point on
    the pixel's outer edge, 0 on its inner edge; 1 without an inner neighbour)."""
    h, w = region.shape
    ys0, xs0 = np.nonzero(region)
    out = []
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        ny, nx = ys0 + dy, xs0 + dx
        keep = (ny >= 0) & (ny < h) & (nx >= 0) & (nx < w)
        keep[keep] = ~region[ny[keep], nx[keep]]
        ys, xs = ys0[keep], xs0[keep]
        iy, ix = ys - dy, xs - dx                            # the inner neighbour
        has = (iy >= 0) & (iy < h) & (ix >= 0) & (ix < w)
        iy, ix = np.clip(iy, 0, h - 1), np.clip(ix, 0, w - 1)
        ref = np.where(has & region[iy, ix], above[iy, ix], 0.0)
        cover = np.where(ref > 0, np.clip(above[ys, xs] / np.where(ref > 0, ref, 1.0), 0.0, 1.0), 1.0)
        out.append(np.stack([xs + 0.5 + (cover - 0.5) * dx, ys + 0.5 + (cover - 0.5) * dy], axis=1))
    return np.concatenate(out)


def on_circle(r):
    """How near a circle of radius ``r`` (px) a point lies on it, in pixels."""
    return np.maximum(ON_CIRCLE, ON_CIRCLE_RELATIVE * np.asarray(r))


def _circles_through(p) -> np.ndarray:
    """(T, 3) circles (cx, cy, r) through the point triples ``p`` (T, 3, 2); NaN
    where the three points are (nearly) on a line."""
    a, b, c = p[:, 0], p[:, 1], p[:, 2]
    d = 2 * ((a[:, 0] - c[:, 0]) * (b[:, 1] - c[:, 1]) - (b[:, 0] - c[:, 0]) * (a[:, 1] - c[:, 1]))
    sa, sb, sc = (a ** 2).sum(1), (b ** 2).sum(1), (c ** 2).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cx = ((sa - sc) * (b[:, 1] - c[:, 1]) - (sb - sc) * (a[:, 1] - c[:, 1])) / d
        cy = ((sb - sc) * (a[:, 0] - c[:, 0]) - (sa - sc) * (b[:, 0] - c[:, 0])) / d
    out = np.stack([cx, cy, np.hypot(a[:, 0] - cx, a[:, 1] - cy)], axis=1)
    out[np.abs(d) < 1e-9] = np.nan
    return out


def consensus_circle(points, size_limit, rng) -> np.ndarray:
    """(cx, cy, r): of TRIALS circles through random triples of ``points`` (N, 2),
    the one most points lie on (within :func:`on_circle`) with at most
    MAX_OUTSIDE of them outside it. ``size_limit``: the largest radius
    considered, in pixels."""
    pool = points if len(points) <= MAX_POINTS else points[rng.choice(len(points), MAX_POINTS, replace=False)]
    trials = _circles_through(pool[rng.integers(0, len(pool), (TRIALS, 3))])
    trials = trials[np.isfinite(trials).all(1) & (trials[:, 2] > 2) & (trials[:, 2] < size_limit)]
    tol = on_circle(trials[:, 2])[:, None]
    signed = np.hypot(pool[None, :, 0] - trials[:, :1], pool[None, :, 1] - trials[:, 1:2]) - trials[:, 2:]
    score = (np.abs(signed) <= tol).sum(1)
    score[(signed > tol).mean(1) > MAX_OUTSIDE] = 0
    if not len(trials) or score.max() < MIN_OUTLINE:
        raise InputError("the object's outline is not a circle (no circle holds the object with its outline on it): "
                         "is it a sphere? %s" % ASK)
    return trials[int(np.argmax(score))]


def refine_circle(points, circle, radius=None) -> np.ndarray:
    """(cx, cy, r): the soft-L1 least-squares circle through ``points`` (N, 2),
    from ``circle``; with ``radius``, only the centre is fitted."""
    x, y = points[:, 0], points[:, 1]
    if radius is not None:
        fit = optimize.least_squares(lambda c: np.hypot(x - c[0], y - c[1]) - radius, circle[:2],
                                     loss="soft_l1", f_scale=0.5)
        return np.array([fit.x[0], fit.x[1], radius])
    return optimize.least_squares(lambda c: np.hypot(x - c[0], y - c[1]) - c[2], circle, loss="soft_l1",
                                  f_scale=0.5).x


def arc_coverage(points, circle, shape=None, bins=72) -> float:
    """Fraction of the circle (cx, cy, r) that the ``points`` (N, 2) on it cover,
    in ``bins`` equal arcs; with ``shape`` (H, W), of its part inside that frame
    (an object cut by the frame)."""
    cx, cy, r = circle
    mid = (np.arange(bins) + 0.5) * 2 * math.pi / bins
    mx, my = cx + r * np.cos(mid), cy + r * np.sin(mid)
    framed = np.ones(bins, bool)
    if shape is not None:
        h, w = shape
        framed = (mx > 0.5) & (mx < w - 0.5) & (my > 0.5) & (my < h - 0.5)
    if not framed.any() or not len(points):
        return 0.0
    at = np.floor((np.arctan2(points[:, 1] - cy, points[:, 0] - cx) % (2 * math.pi)) / (2 * math.pi) * bins)
    hit = np.zeros(bins, bool)
    hit[np.clip(at.astype(int), 0, bins - 1)] = True
    return float((hit & framed).sum() / framed.sum())


def split_disagreement(points, circle, splits=12, bins=72) -> float:
    """Largest distance (px) between the centres of the circles of radius r fitted
    to the two halves of ``points`` (N, 2) on the circle (cx, cy, r), over
    ``splits`` diameters; a split is skipped when either half covers less than a
    quarter of the circle (as where the frame cuts it)."""
    cx, cy, r = circle
    angle = np.arctan2(points[:, 1] - cy, points[:, 0] - cx)
    at = np.clip(np.floor(angle % (2 * math.pi) / (2 * math.pi) * bins).astype(int), 0, bins - 1)
    worst = 0.0
    for psi in np.arange(splits) * math.pi / splits:
        half = np.sin(angle - psi) >= 0
        if min(np.unique(at[half]).size, np.unique(at[~half]).size) < bins // 4:
            continue
        a = refine_circle(points[half], circle, radius=r)
        b = refine_circle(points[~half], circle, radius=r)
        worst = max(worst, float(np.hypot(a[0] - b[0], a[1] - b[1])))
    return worst


def fit_outline(image) -> tuple:
    """(cx, cy, r) in pixels of the sphere in ``image`` (H, W, C) on a black
    background, without a mask (module doc); InputError, asking for a mask, when
    the background is not black or the answer cannot be trusted."""
    region, above = bright_region(image)
    h, w = region.shape
    if region.sum() < MIN_OUTLINE:
        raise InputError("the object covers %d pixels: too few to fit its outline; %s" % (region.sum(), ASK))
    points = boundary_points(region, above)
    if len(points) < MIN_OUTLINE:
        raise InputError("the object's outline inside the frame has %d pixels: too few to fit it; %s"
                         % (len(points), ASK))
    rng = np.random.default_rng(0)
    circle = consensus_circle(points, max(h, w), rng)
    for _ in range(2):
        on = np.abs(np.hypot(points[:, 0] - circle[0], points[:, 1] - circle[1]) - circle[2]) <= on_circle(circle[2])
        if on.sum() < MIN_OUTLINE:
            break
        circle = refine_circle(points[on], circle)
    cx, cy, r = (float(v) for v in circle)
    signed = np.hypot(points[:, 0] - cx, points[:, 1] - cy) - r
    on = np.abs(signed) <= on_circle(r)
    cut = region[0].any() or region[-1].any() or region[:, 0].any() or region[:, -1].any()
    arc = arc_coverage(points[on], (cx, cy, r), (h, w) if cut else None)
    ys, xs = np.nonzero(region)
    outside = float((np.hypot(xs + 0.5 - cx, ys + 0.5 - cy) > r + on_circle(r)).mean())
    why = ("Without a mask the outline is where the image turns black, and a sphere's unlit side is black too: "
           + ASK)
    if outside > MAX_OUTSIDE:
        raise InputError("the object's outline is not a circle: %.0f %% of the object lies outside the best circle "
                         "through it (is it a sphere, alone on a black background?). %s" % (100 * outside, why))
    if (signed < -MIN_DEPTH).mean() < TERMINATOR_SHARE:          # a whole disc
        if on.sum() < MIN_OUTLINE or arc < MIN_DISC_ARC:
            raise InputError("the object's outline is not a circle: only %.0f deg of it lie on one, and the rest "
                             "lies near it. %s" % (360 * arc, why))
        sample = points[on] if on.sum() <= MAX_POINTS else points[on][rng.choice(on.sum(), MAX_POINTS, False)]
        split = split_disagreement(sample, (cx, cy, r))
        if split > max(MAX_SPLIT, MAX_SPLIT_RELATIVE * r):
            raise InputError("the object's outline is not a circle: its halves fit circles %.1f px apart (a lit "
                             "part that ends just inside the outline?). %s" % (split, why))
    else:                                                         # a lit part and its terminator
        lit = float(region.sum() / max(disc_pixels((h, w), (cx, cy, r)).sum(), 1))
        if on.sum() < MIN_OUTLINE or arc < MIN_ARC:
            raise InputError("the object's outline is not a circle: only %.0f deg of it lie on one. %s"
                             % (360 * arc, why))
        if lit > MAX_LIT:
            raise InputError("the object's outline is not a circle: its lit part covers %.0f %% of the best circle, "
                             "and the edge of its unlit side lies too near the outline to tell them apart. %s"
                             % (100 * lit, why))
    return cx, cy, r
