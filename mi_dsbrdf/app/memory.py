"""The memory a recovery needs, estimated before the image is read, and the check
that refuses what the machine (or ``Config.max_memory``) cannot hold, naming the
setting that lowers it (:func:`check_memory`)."""
from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from mi_dsbrdf.app.working_grid import WorkingGrid
from mi_dsbrdf.config import Config
from mi_dsbrdf.errors import ConfigError
from mi_dsbrdf.inference.bounce import DIRECTIONS as BOUNCE_DIRECTIONS
from mi_dsbrdf.inference.envmap import map_sizes
from mi_dsbrdf.inference.highlights import PIXEL_SIDE, TEXEL_SIDE
from mi_dsbrdf.inference.objective import MAX_REFLECTANCE_PIXELS, MIN_REFLECTANCE_PIXELS
from mi_dsbrdf.inference.scene_needs import dsbrdf_object, light_kind, needs_visibility

GB = float(1 << 30)


def memory_needs(scene) -> tuple:
    """(under an illumination map?, :func:`~mi_dsbrdf.inference.scene_needs.needs_visibility`
    of the object: (shadow rays?, reason)) of ``scene`` for :func:`memory_estimate`,
    before the image is read; the pair goes on to
    :func:`~mi_dsbrdf.inference.scene_needs.decide`. SceneError without exactly one
    ``dsbrdf`` object or with a light inference does not take; a scene with other
    lights than one is refused later."""
    shape = dsbrdf_object(scene)
    emitters = scene.emitters()
    light = light_kind(emitters[0]) if len(emitters) == 1 else None
    return light == "envmap", needs_visibility(scene, shape, light)


# The model below was fitted to the peak resident memory (ru_maxrss, one process
# each) of recover() on a 128 x 128 sphere under a map (the benchmarks' camera, fov
# 34 degrees, 8.9k object pixels; max_rounds 1): measured 1265 MB at the defaults,
# 1275 MB at --map-size 64x128, 2053 MB at 128x256, 2519 MB at --texel-samples 4,
# 866 MB with the fast preset; the model gives 1258, 1274, 2084, 2481 and 936 MB.
#: bytes per pixel-direction pair a posterior's view holds (its three float32 numbers
#: per pair, :meth:`~mi_dsbrdf.inference.forward.TexelSum.pair_geometry`)
PAIR_BYTES = 12.0
#: bytes per pixel-texel lane of a reflectance block's Jacobian launch (39 float32
#: columns, in Dr.Jit, copied to numpy and stacked)
JACOBIAN_BYTES = 470.0
#: bytes per pixel-texel pair of a posterior's transport (3 float32, two alive)
TRANSPORT_BYTES = 24.0
#: bytes per light direction of a view (directions and solid angles in float64 and
#: float32, and the copies made on the way)
DIRECTION_BYTES = 120.0
#: bytes per ray of a point or directional light's view (Config.pixel_rays^2 a pixel):
#: its SurfaceInteraction, frames and points in float64 and float32, direction and
#: solid angle, in the view and its reflectance subset. Fitted to recover() of a
#: 128 x 128 point-lit sphere: peaks of 221, 344 and 772 MB at 1, 4x4 and 8x8 rays a
#: pixel, for which the model gives 313, 448 and 877 MB (an upper bound: it counts
#: every working pixel, not only the object's)
RAY_BYTES = 560.0
#: bytes per pixel of the film: the image as read and in float64, the re-render, the
#: masks, the block sums and the previews
IMAGE_PIXEL_BYTES = 150.0
#: the process's footprint besides: Python, Mitsuba, Dr.Jit's LLVM, the model
BASE_BYTES = 300 * float(1 << 20)
#: pixel-texel lanes of one Jacobian launch (:data:`mi_dsbrdf.inference.lobes.JACOBIAN_CHUNK`)
JACOBIAN_LANES = 1 << 22


#: bytes per pixel-direction pair and surface whose light onto the object is modelled
#: (:mod:`~mi_dsbrdf.inference.bounce`): the pairs it blocks (a bool) and their weights
#: (float32) in a map's view; a light's views hold a map of
#: :data:`~mi_dsbrdf.inference.bounce.DIRECTIONS` for them, its geometry per pair
BOUNCE_PAIR_BYTES = 5.0


def memory_estimate(cfg: Config, grid: WorkingGrid, envmap=True, visibility=False, surfaces=0) -> dict:
    """Estimated peak memory (bytes) of :func:`mi_dsbrdf.recover` on ``grid`` under
    ``cfg``: {"total", "views" (the posteriors' pairs, Jacobians and transports),
    "visibility", "directions", "image", "base"}. The working grid's pixels stand for
    the object's (an upper bound); ``envmap``: under an illumination map (else one
    light: one direction a pixel); ``visibility``: shadow rays (a bool per object
    pixel and direction of each view); ``surfaces``: other shapes whose light onto the
    object is modelled. The constants were fitted to measurements (see the comment
    above them)."""
    h, w = grid.working
    pixels = h * w
    views = vis = directions = 0.0
    if envmap:
        T = cfg.map_size[0] * cfg.map_size[1]
        post = min(pixels, max(cfg.map_pairs // T, MIN_REFLECTANCE_PIXELS))   # Posterior's pixel budget
        g = cfg.grey_texel_samples or cfg.texel_samples
        start, full = map_sizes(cfg.map_size, cfg.map_levels, 1)
        lanes = 0
        for (mh, mw), s in {(start, g), (full, g), (full, cfg.texel_samples)}:    # start, grey, colour views
            t, d = mh * mw, mh * mw * s * s
            refl = min(post, int(np.clip(cfg.reflectance_pairs // t, MIN_REFLECTANCE_PIXELS,
                                         MAX_REFLECTANCE_PIXELS)))
            views += PAIR_BYTES * (post + refl) * d
            lanes = max(lanes, min(refl, max(1, JACOBIAN_LANES // d)) * t)
            directions += DIRECTION_BYTES * d
            vis += (pixels + post) * d * (1 + BOUNCE_PAIR_BYTES * surfaces) if visibility else 0
        views += JACOBIAN_BYTES * lanes + TRANSPORT_BYTES * post * T
        # the colour view's highlight pairs: their lanes' geometry, as a pair's
        refl = min(post, int(np.clip(cfg.reflectance_pairs // T, MIN_REFLECTANCE_PIXELS, MAX_REFLECTANCE_PIXELS)))
        views += PAIR_BYTES * (post + refl) * cfg.highlight_texels * (PIXEL_SIDE * TEXEL_SIDE) ** 2
    else:
        rays = pixels * cfg.pixel_rays ** 2         # a light's lanes: the rays across each pixel
        views = ((PAIR_BYTES + RAY_BYTES) * rays + TRANSPORT_BYTES * pixels
                 + JACOBIAN_BYTES * min(pixels, MAX_REFLECTANCE_PIXELS))
        vis = 2 * rays if visibility else 0
        if visibility and surfaces:
            bounce_pairs = pixels * BOUNCE_DIRECTIONS[0] * BOUNCE_DIRECTIONS[1]
            vis += (PAIR_BYTES + 1 + BOUNCE_PAIR_BYTES * surfaces) * bounce_pairs
    H, W = grid.image
    parts = {"views": views, "visibility": float(vis), "directions": directions,
             "image": IMAGE_PIXEL_BYTES * H * W, "base": BASE_BYTES}
    parts["total"] = sum(parts.values())
    return parts


def available_memory() -> float:
    """Bytes of memory available to a new allocation (``MemAvailable`` of
    /proc/meminfo; the free physical pages where there is none)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return math.inf


def check_memory(cfg: Config, grid: WorkingGrid, envmap=True, visibility=False, available=None, surfaces=0) -> dict:
    """:func:`memory_estimate`, or a one-line ConfigError when it is over
    ``cfg.max_memory`` (GB) or the memory available (``available`` bytes, default
    :func:`available_memory`) that names the setting that lowers it most."""
    est = memory_estimate(cfg, grid, envmap, visibility, surfaces)
    if cfg.max_memory is not None:
        limit, what = cfg.max_memory * GB, "--max-memory %g GB" % cfg.max_memory
    else:
        limit = available_memory() if available is None else available
        what = "the %.1f GB of memory available" % (limit / GB)
    if est["total"] <= limit:
        return est
    h, w = grid.working
    lower = {"--map-size": dataclasses.replace(cfg, map_size=(max(cfg.map_size[0] // 2, 2),
                                                              max(cfg.map_size[1] // 2, 4))),
             "--texel-samples": dataclasses.replace(cfg, texel_samples=1, grey_texel_samples=1),
             "--working-pixels": dataclasses.replace(cfg, working_pixels=max(h * w // 4, 256))}
    now = {"--map-size": "%dx%d" % cfg.map_size, "--texel-samples": str(cfg.texel_samples),
           "--working-pixels": str(cfg.working_pixels)}
    gains = {}
    for name, c in lower.items():
        g = grid if name != "--working-pixels" else WorkingGrid.of(grid.image[::-1], c.working_pixels)
        gains[name] = est["total"] - memory_estimate(c, g, envmap, visibility, surfaces)["total"]
    best = max(gains, key=gains.get)
    if gains[best] <= 0.01 * est["total"] or est["image"] > limit:
        hint = "the %dx%d image alone needs %.1f GB: give a smaller image" % (grid.image[1], grid.image[0],
                                                                               est["image"] / GB)
    else:
        hint = "lower %s (now %s)" % (best, now[best])
    raise ConfigError("these settings need about %.1f GB of memory, over %s: %s" % (est["total"] / GB, what, hint))
