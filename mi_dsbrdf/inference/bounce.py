"""The light other shapes of the scene reflect onto the object: one bounce off each
diffuse surface, linear in the light. (Beyond the paper, whose object is alone.)

A pixel-direction pair whose shadow ray meets another shape s receives what s
reflects, not the light's radiance. For a shape whose BSDF is ``diffuse`` with a
constant reflectance rho_s (a table, a wall, the ground), taken as uniformly lit,
that is its radiance

    R_s = rho_s / pi * sum_j g_sj L_j,
    g_sj = mean over y of [max(0, n_s(y) . d_j) V(y, d_j)] Omega_j,

the mean over :data:`POINTS` points y of s that the object's blocked pairs meet
(so that the object's own shadow on s counts as often as the object sees it),
over the light's directions d_j with their solid angles (a map's texels; a
point light's direction and 1 / r^2 from y; a directional light's one
direction). Pixel p then gains b_s(p) R_s, b_s(p) the texel sum of p over the
pairs s blocks (the visibility's complement there), so that

    I = T L + sum_s b_s (m_s . L),   m_s = rho_s / pi * g_s:

a rank-one term per surface in the transport, and the illumination block stays
linear (:meth:`~mi_dsbrdf.inference.lobes.LobeSum.transport`). The light the
object reflects onto itself, and off surfaces of any other BSDF, is not
modelled (:mod:`~mi_dsbrdf.inference.scene_needs` says which).
"""
from __future__ import annotations

import dataclasses
import functools
import math

import drjit as dr
import mitsuba as mi
import numpy as np

#: points of a surface its light is averaged over (module doc)
POINTS = 512
#: under a point or a directional light: the map (texels, their centres) whose
#: directions find the surfaces each pixel sees (:attr:`Bounce.pairs`)
DIRECTIONS = (8, 16)
#: shadow rays from a surface's points traced at once
CHUNK_RAYS = 1 << 19


@dataclasses.dataclass(frozen=True)
class Bounce:
    """One diffuse surface's light onto the object, for one view and light.

    name : the shape's id (or kind)
    albedo : (3,) its reflectance
    blocked : (P, n) bool: the pixel-direction pairs it blocks, of ``pairs``
    weights : (n_texels,) g_s of the module doc under the view's light, summed over
        each texel's directions
    pairs : None: the view's own pairs (a map's); else the :class:`SurfacePairs`
        whose pairs ``blocked`` indexes: a point or a directional light's rays see the
        light alone, not the surface
    points : (points (N, 3), normals (N, 3)): the surface's points the weights
        average over (:func:`surface_points`), the same for every light
    """
    name: str
    albedo: np.ndarray
    blocked: np.ndarray
    weights: np.ndarray
    pairs: object = None
    points: tuple = None

    @property
    def transport_term(self) -> np.ndarray:
        """(3, n_texels) m_s: the surface's radiance per unit light in each texel."""
        return self.albedo[:, None] / math.pi * self.weights[None, :]

    def radiance(self, illumination) -> np.ndarray:
        """(3,) R_s under ``illumination`` (n_texels, 3)."""
        return (self.transport_term * np.asarray(illumination, dtype=np.float64).reshape(-1, 3).T).sum(axis=1)

    def subset(self, rows, pairs=None) -> "Bounce":
        """The bounce on the pixels ``rows``; ``pairs``: their :class:`SurfacePairs` (a
        light's), or None (a map's own pairs)."""
        return dataclasses.replace(self, blocked=self.blocked[rows], pairs=pairs)


class SurfacePairs:
    """Under a point or a directional light: the pixels of a view lit from the
    centres of a :data:`DIRECTIONS` map (``view``, a
    :class:`~mi_dsbrdf.inference.forward.TexelSum` with shadow rays), whose blocked
    pairs find the surfaces each pixel sees. Made once a view, shared by every
    light the view takes; what it derives is kept here."""

    def __init__(self, view):
        self.view = view
        #: sums over the pairs already made, for a few materials
        #: (:meth:`LobeSum._bounce_sums <mi_dsbrdf.inference.lobes.LobeSum._bounce_sums>`):
        #: they do not depend on the light, which a light search moves
        self.memo = {}

    @functools.cached_property
    def geometry(self) -> list:
        """:func:`compact_pairs` of the pairs each of ``view.bounces`` blocks."""
        return [compact_pairs(self.view.pair_geometry(b.blocked), b.blocked) for b in self.view.bounces]

    def subset(self, rows) -> "SurfacePairs":
        return SurfacePairs(self.view.subset(rows))


def map_bounces(scene, surfaces, which, positions, normals, directions, solid_angles, per_texel) -> tuple:
    """The :class:`Bounce` of each of ``surfaces`` (shapes) that blocks a pair of a
    map's view: ``which`` (P, n) int8, the index of the surface each pair's shadow ray
    meets (-1: none; :func:`~mi_dsbrdf.inference.rays.shadow_test`); the pixels'
    surface ``positions`` and geometric ``normals`` (3, P); the map's world
    ``directions`` (n, 3) with their ``solid_angles`` (n,), ``per_texel`` a texel."""
    bounces = []
    n = which.shape[1]
    for k, shape in enumerate(surfaces):
        blocked = which == k
        lanes = np.flatnonzero(blocked)
        if lanes.size == 0:
            continue
        lanes = lanes[np.linspace(0, lanes.size - 1, min(POINTS, lanes.size)).round().astype(np.int64)]   # evenly
        pix, pair = lanes // n, lanes % n
        points = surface_points(scene, positions[:, pix].T, normals[:, pix].T, directions[pair])
        weights = surface_weights(scene, points, light_directions=directions, solid_angles=solid_angles,
                                  per_texel=per_texel)
        bounces.append(Bounce(shape.id() or "surface %d" % k, diffuse_albedo(shape), blocked, weights,
                              points=points))
    return tuple(bounces)


def light_bounces(scene, pairs, position=None, direction=None) -> tuple:
    """The bounces of :class:`SurfacePairs` ``pairs`` (whose view's :func:`map_bounces`
    find the surfaces) under a point light at ``position``, else a directional light
    along ``direction`` (towards it) of unit irradiance. Every surface's points are
    traced in one launch (a light search moves the light hundreds of times)."""
    bounces = pairs.view.bounces
    if not bounces:
        return ()
    y, nrm = (np.concatenate([b.points[i] for b in bounces]) for i in range(2))
    lit = light_point_weights(scene, y, nrm, position, direction)
    ends = np.cumsum([b.points[0].shape[0] for b in bounces])
    return tuple(dataclasses.replace(b, pairs=pairs, weights=np.array([float(w.mean())]))
                 for b, w in zip(bounces, np.split(lit, ends[:-1])))


def light_point_weights(scene, y, normals, position=None, direction=None) -> np.ndarray:
    """(N,) max(0, n . d) V / r^2 at the surface points ``y`` (N, 3) of ``normals``
    (N, 3) from a point light at ``position``; else max(0, n . d) V along the
    unit ``direction`` (3,) of a directional light: g_s of the module doc per point."""
    if position is not None:
        to = np.asarray(position, dtype=np.float64).reshape(1, 3) - y
        r2 = np.maximum((to * to).sum(axis=1), 1e-12)
        dirs = to / np.sqrt(r2)[:, None]
        return np.maximum((dirs * normals).sum(axis=1), 0.0) * _unblocked(scene, y, normals, dirs, np.sqrt(r2)) / r2
    dirs = np.broadcast_to(np.asarray(direction, dtype=np.float64).reshape(1, 3), y.shape)
    return np.maximum((dirs * normals).sum(axis=1), 0.0) * _unblocked(scene, y, normals, dirs)


def diffuse_albedo(shape):
    """(3,) the constant reflectance of ``shape``'s BSDF when it is ``diffuse``
    with one; else None (a texture, another BSDF)."""
    bsdf = shape.bsdf()
    if bsdf is None or bsdf.class_name() != "SmoothDiffuse":
        return None
    value = mi.traverse(bsdf).get("reflectance.value")
    if value is None:
        return None
    rho = np.array(value, dtype=np.float64).reshape(-1)
    return np.resize(rho, 3) if rho.size in (1, 3) else None


def surface_points(scene, origins, normals, directions) -> tuple:
    """(points (N, 3), normals (N, 3) facing the object) of the surface that the rays
    from the object's points ``origins`` (N, 3) with geometric ``normals`` (N, 3)
    along ``directions`` (N, 3) meet (a sample of the pairs it blocks)."""
    si = dr.zeros(mi.SurfaceInteraction3f, origins.shape[0])
    si.p = mi.Point3f(*origins.T.astype(np.float32))
    si.n = mi.Normal3f(*normals.T.astype(np.float32))
    hit = scene.ray_intersect(si.spawn_ray(mi.Vector3f(*directions.T.astype(np.float32))))
    y = np.array(hit.p, dtype=np.float64).T
    nrm = np.array(hit.n, dtype=np.float64).T
    nrm *= np.where((nrm * directions).sum(axis=1) > 0, -1.0, 1.0)[:, None]          # the side the object sees
    return y, nrm


def surface_weights(scene, points, light_directions, solid_angles, per_texel=1) -> np.ndarray:
    """g_s of the module doc, (n_texels,), over the surface's ``points`` ((n, 3)
    points, (n, 3) normals: :func:`surface_points`) under the world directions
    ``light_directions`` (M, 3) with ``solid_angles`` (M,), in texels of
    ``per_texel`` consecutive directions (a map's). A point or a directional
    light's: :func:`light_point_weights`."""
    y, nrm = points
    m = light_directions.shape[0]
    g = np.zeros(m)
    step = max(1, CHUNK_RAYS // m)                  # points a launch: bounded memory at any map size
    for i in range(0, y.shape[0], step):
        yc, nc = y[i:i + step], nrm[i:i + step]
        ys, ns = np.repeat(yc, m, axis=0), np.repeat(nc, m, axis=0)
        ds = np.tile(light_directions, (yc.shape[0], 1))
        lit = _unblocked(scene, ys, ns, ds)
        g += (np.maximum((ds * ns).sum(axis=1), 0.0) * lit).reshape(yc.shape[0], m).sum(axis=0)
    g *= solid_angles / y.shape[0]
    return g.reshape(-1, int(per_texel)).sum(axis=1)


def _unblocked(scene, points, normals, directions, distance=None) -> np.ndarray:
    """(N,) bool: rays from ``points`` on surfaces of ``normals`` along ``directions``
    (for ``distance`` (N,) if given) meet nothing (Mitsuba's own offset of a ray
    leaving a surface: a fixed one met the surface itself)."""
    si = dr.zeros(mi.SurfaceInteraction3f, points.shape[0])
    si.p = mi.Point3f(*points.T.astype(np.float32))
    si.n = mi.Normal3f(*normals.T.astype(np.float32))
    d = mi.Vector3f(*directions.T.astype(np.float32))
    if distance is None:
        ray = si.spawn_ray(d)
    else:
        ray = si.spawn_ray_to(si.p + d * mi.Float(np.asarray(distance, dtype=np.float32)))
    return ~np.array(scene.ray_test(ray), dtype=bool)


def compact_pairs(geometry, blocked) -> tuple:
    """The pairs ``blocked`` (P, n) bool of a view's pair geometry (three Dr.Jit
    Floats of P * n lanes, pixel-major): (their geometry, three Floats of the blocked
    lanes alone, pixel-major; (P,) uint32 each pixel's first lane among them; (P,)
    uint32 their number). A surface blocks a fraction of a pixel's directions: the
    sums over them loop over those alone."""
    lanes = np.flatnonzero(blocked.reshape(-1)).astype(np.uint32)
    counts = blocked.sum(axis=1).astype(np.uint32)
    first = (np.cumsum(counts) - counts).astype(np.uint32)
    index = mi.UInt32(lanes)
    out = tuple(dr.gather(mi.Float, a, index) for a in geometry)
    dr.eval(*out)
    return out, first, counts

