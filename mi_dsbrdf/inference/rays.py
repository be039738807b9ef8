"""Camera rays onto the object: through each pixel's centre, or a regular grid of
points over each pixel's area (what a box pixel filter averages); and shadow rays
from the surface points they hit towards the light."""
from __future__ import annotations

import dataclasses
import functools

import drjit as dr
import mitsuba as mi
import numpy as np


def centre_hits(scene, sensor, shape) -> tuple:
    """(the SurfaceInteraction of the ray through each pixel centre of ``sensor``'s
    film, row by row; (H * W,) bool: the pixels whose centre ray sees ``shape``)."""
    w, h = (int(v) for v in sensor.film().crop_size())
    return sample_hits(scene, sensor, shape, np.arange(w * h), 1)


def sample_hits(scene, sensor, shape, pixels, side) -> tuple:
    """Rays through the centres of a ``side`` x ``side`` grid over the area of each
    pixel of ``pixels`` (flat film indices, row by row): (their SurfaceInteraction,
    pixel-major, a pixel's rays row by row; (len(pixels) * side^2,) bool: the rays
    that see ``shape``)."""
    w, h = (int(v) for v in sensor.film().crop_size())
    pixels = np.asarray(pixels, dtype=np.int64)
    sub = (np.arange(side) + 0.5) / side
    oy, ox = (a.reshape(-1) for a in np.meshgrid(sub, sub, indexing="ij"))
    x = (pixels % w)[:, None] + ox[None, :]
    y = (pixels // w)[:, None] + oy[None, :]
    uv = mi.Point2f((x.reshape(-1) / w).astype(np.float32), (y.reshape(-1) / h).astype(np.float32))
    rays, _ = sensor.sample_ray(0.0, 0.5, uv, mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(rays)
    return si, shape_index(si, [shape]) == 0


def shape_index(hits, shapes) -> np.ndarray:
    """(N,) int8: the index in ``shapes`` of the shape each intersection ``hits`` (a
    SurfaceInteraction or a PreliminaryIntersection) meets, -1 for none of them (or
    no hit)."""
    valid = np.array(hits.is_valid(), dtype=bool)
    ptr = np.array(dr.reinterpret_array(mi.UInt32, hits.shape))
    out = np.full(valid.shape, -1, dtype=np.int8)
    for i, shape in enumerate(shapes):
        out[valid & (ptr == np.array(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))))] = i
    return out


#: a light's shadow rays traced at once (:meth:`FootprintRays.shadow_test`)
SHADOW_CHUNK = 1 << 20


@dataclasses.dataclass(frozen=True)
class FootprintRays:
    """``side`` x ``side`` camera rays across the area of each of P pixels
    (:func:`sample_hits`), pixel-major, a pixel's rays row by row: the lanes of a
    point or directional light's texel sum over pixel footprints
    (:class:`~mi_dsbrdf.inference.forward.TexelSum`). A ray that misses the object
    carries its pixel's centre hit, with share 0 (what it sees is not the object's).

    side : rays per pixel side
    si : SurfaceInteraction3f of the P * side^2 rays
    frames : (s, t, n, wi), (3, P * side^2) float64 each: the shading frame and the
        direction to the camera in it
    positions, normals : (3, P * side^2) float64: surface points and geometric normals
    share : (P * side^2,) float64: 1 / side^2 for a ray that sees the object, else 0
    """
    side: int
    si: object
    frames: tuple
    positions: np.ndarray
    normals: np.ndarray
    share: np.ndarray

    @classmethod
    def trace(cls, scene, sensor, shape, pixels, centre_si, side) -> "FootprintRays":
        """The rays of the film pixels ``pixels`` (flat indices), whose centre rays'
        SurfaceInteraction is ``centre_si`` (side 1: those, traced again by none)."""
        side = int(side)
        if side == 1:
            si, hit = centre_si, np.ones(len(pixels), bool)
        else:
            si, hit = sample_hits(scene, sensor, shape, pixels, side)
            own = dr.arange(mi.UInt32, dr.width(si)) // (side * side)
            si = dr.select(mi.Bool(hit), si, dr.gather(mi.SurfaceInteraction3f, centre_si, own))
        frames = tuple(np.array(v, dtype=np.float64) for v in (si.sh_frame.s, si.sh_frame.t, si.sh_frame.n, si.wi))
        return cls(side, si, frames, np.array(si.p, dtype=np.float64), np.array(si.n, dtype=np.float64),
                   np.where(hit, 1.0 / side ** 2, 0.0))

    @functools.cached_property
    def frame_buffer(self):
        """The frames as one float32 Dr.Jit array, (s, t, n, wi) x (x, y, z) rows of
        P * side^2 values: uploaded once for every light of the view."""
        return mi.Float(np.concatenate(self.frames).reshape(-1).astype(np.float32))

    @functools.cached_property
    def shadow_buffer(self):
        """Each ray's surface point, geometric normal and shading normal, and the
        camera direction's cosine, as one float32 Dr.Jit array of 10 rows: uploaded
        once for every light's shadow rays (:meth:`shadow_test`)."""
        rows = [self.positions, self.normals, self.frames[2], self.frames[3][2:3]]
        return mi.Float(np.concatenate([r.reshape(-1) for r in rows]).astype(np.float32))

    def shadow_test(self, scene, position=None, direction=None) -> np.ndarray:
        """(N,) bool: the light reaches each ray's surface point, from a point light
        at ``position`` or a directional light along ``direction`` (towards it),
        through the whole scene: :func:`shadow_test` with ``ray_lanes`` (its plain
        form, which the tests hold this to), with the rays uploaded once a view and
        one kernel for every light (a light search tries hundreds)."""
        n = self.share.size
        light = np.asarray(position if position is not None else direction, dtype=np.float32).reshape(3)
        buf, lit = self.shadow_buffer, mi.Float(light)       # one fresh array: the same kernel for every light
        vis = np.ones(n, dtype=bool)
        for r0 in range(0, n, SHADOW_CHUNK):
            lane = dr.arange(mi.UInt32, min(SHADOW_CHUNK, n - r0)) + dr.opaque(mi.UInt32, r0)

            def vec(row):
                return mi.Vector3f(*(dr.gather(mi.Float, buf, lane + (row + k) * n) for k in range(3)))
            si = dr.zeros(mi.SurfaceInteraction3f, dr.width(lane))      # the geometric normal offsets the rays
            si.p, si.n = mi.Point3f(vec(0)), mi.Normal3f(vec(3))
            target = mi.Vector3f(*(dr.gather(mi.Float, lit, dr.zeros(mi.UInt32, dr.width(lane)) + k)
                                   for k in range(3)))
            if position is not None:
                ray = si.spawn_ray_to(mi.Point3f(target))
                towards = target - si.p
            else:
                ray = si.spawn_ray(target)
                towards = target
            active = (dr.dot(vec(6), towards) > 0) & (dr.gather(mi.Float, buf, lane + 9 * n) > 0)
            vis[r0:r0 + dr.width(lane)] = ~scene.ray_test(ray, active).numpy()
        return vis

    def subset(self, rows) -> "FootprintRays":
        """The rays of the pixels ``rows`` (indices into this object's P)."""
        n = self.side ** 2
        rays = (np.asarray(rows, dtype=np.int64)[:, None] * n + np.arange(n)).reshape(-1)
        return FootprintRays(self.side, dr.gather(mi.SurfaceInteraction3f, self.si, mi.UInt32(rays.astype(np.uint32))),
                             tuple(f[:, rays] for f in self.frames), self.positions[:, rays], self.normals[:, rays],
                             self.share[rays])


def shadow_test(scene, points, normals, frames, directions, position, n_pixels, n_directions, chunks,
                ray_lanes, surfaces=()) -> tuple:
    """((n_pixels, n_directions) bool: the light of each pixel-direction pair reaches
    the surface point; (n_pixels, n_directions) int8: the index in ``surfaces`` of
    the shape that blocks it, -1 for none of them; None without ``surfaces``), by
    shadow rays through the whole scene,
    so that the object shadows itself and every other shape shadows it. Pairs with
    the light or the camera below the surface are left True (their weight is zero).
    A ray runs towards the direction to infinity (a texel's direction, a directional
    light), or to the point light's ``position`` (None: none).

    ``points``, ``normals`` (3, N) and ``frames`` ((s, t, n, wi), (3, N) each): one
    per pixel (N = n_pixels), or with ``ray_lanes`` one per pair (a light's rays, N =
    n_pixels * n_directions); ``directions`` (M, 3): per direction of a pixel, or
    with ``ray_lanes`` per pair; ``chunks``: direction ranges [t0, t1) traced at once.
    """
    P, nd = n_pixels, n_directions
    n_light = directions.shape[0]
    width = P * nd if ray_lanes else P
    # All inputs in one array, gathered (no literals, one fresh array): a new
    # light then runs the same kernel, not a new one (a light search traces
    # hundreds of point lights)
    target = np.zeros(3) if position is None else position
    buf = mi.Float(np.concatenate([points.reshape(-1), normals.reshape(-1), *(f.reshape(-1) for f in frames),
                                   directions.T.reshape(-1), target]).astype(np.float32))
    light0 = 18 * width
    vis = np.ones((P, nd), dtype=bool)
    which = np.full((P, nd), -1, dtype=np.int8) if surfaces else None
    for t0, t1 in chunks:
        nt = t1 - t0
        lane = dr.arange(mi.UInt32, P * nt)
        pix = lane // nt
        tex = lane - pix * nt + dr.opaque(mi.UInt32, t0)
        geo = pix * nd + tex if ray_lanes else pix          # the lane's surface point
        per_light = geo if ray_lanes else tex

        def vec(first, index, width):
            return mi.Vector3f(*(dr.gather(mi.Float, buf, index + (first + k) * width) for k in range(3)))
        si = dr.zeros(mi.SurfaceInteraction3f, P * nt)      # the geometric normal offsets the rays
        si.p, si.n = mi.Point3f(vec(0, geo, width)), mi.Normal3f(vec(3, geo, width))
        frame = mi.Frame3f(vec(6, geo, width), vec(9, geo, width), vec(12, geo, width))
        wi_z = dr.gather(mi.Float, buf, geo + 17 * width)
        wo = frame.to_local(vec(0, per_light + light0, n_light))
        if position is not None:
            ray = si.spawn_ray_to(mi.Point3f(vec(0, dr.zeros(mi.UInt32, P * nt) + light0 + 3 * n_light, 1)))
        else:
            ray = si.spawn_ray(frame.to_world(wo))
        active = (wo.z > 0) & (wi_z > 0)
        if surfaces:
            pi = scene.ray_intersect_preliminary(ray, active=active)
            blocked = pi.is_valid() & active
            which[:, t0:t1] = shape_index(pi, surfaces).reshape(P, nt)
        else:
            blocked = scene.ray_test(ray, active)
        vis[:, t0:t1] = ~blocked.numpy().reshape(P, nt)
    if surfaces:
        which[vis] = -1
    return vis, which
