"""Highlight pairs: the pixel-texel pairs around each pixel's mirror direction,
integrated over the pixel's area and over the texel.

The texel sum (:mod:`~mi_dsbrdf.inference.forward`) sees a pixel through the ray
at its centre and a texel from s x s directions. A lobe narrower than the
directions one pixel reflects, or than the spacing of those directions, is
sampled too coarsely there; Mitsuba, which averages each pixel over its area
(box filter) and the map over every direction, renders it tens of percent
differently (``benchmarks/mitsuba_roundtrip.py --footprint``). Only pairs near a pixel's
mirror direction see such a lobe. So for each pixel the K texels
(``Config.highlight_texels``) whose centres lie closest to the mirror direction
of its centre ray are taken out of the texel sum and integrated instead over
:data:`PIXEL_SIDE` squared rays across the pixel times :data:`TEXEL_SIDE` squared
directions across the texel, each direction with its share of the texel's solid
angle. Elsewhere the lobe is smooth across a pixel and a texel, and the texel
sum's samples suffice. :class:`~mi_dsbrdf.inference.lobes.LobeSum` sums each
pair's lanes in a Dr.Jit loop; :meth:`HighlightPairs.plugin_weights` is the
plain reference (the plugin, every lane stored) the tests hold it to.

A ray across the pixel that misses the object takes the centre ray's geometry
(the pixels inference uses lie inside the silhouette).

Lanes are (pixel p, nearest texel k, ray a, direction j), j fastest:
lane = ((p K + k) q^2 + a) S^2 + j.
"""
from __future__ import annotations

import dataclasses

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_dsbrdf.brdf.angles import pair_geometry
from mi_dsbrdf.inference.rays import sample_hits

#: rays across a pixel per side, directions across a texel per side
PIXEL_SIDE, TEXEL_SIDE = 4, 3
#: lanes per Dr.Jit launch of the shadow rays
CHUNK = 1 << 22


def mirror_directions(si) -> np.ndarray:
    """(P, 3) float64 world directions of the mirror reflection of the camera
    direction about each shading normal of ``si``."""
    n = np.array(si.sh_frame.n, dtype=np.float64)
    v = np.array(si.to_world(si.wi), dtype=np.float64)
    r = 2 * (n * v).sum(axis=0) * n - v
    return (r / np.linalg.norm(r, axis=0)).T


def nearest_texels(directions, centres, k) -> np.ndarray:
    """(P, k) int64: for each of ``directions`` (P, 3) the ``k`` texels whose
    ``centres`` (T, 3) are nearest it by angle."""
    k = min(int(k), centres.shape[0])
    out = np.empty((directions.shape[0], k), dtype=np.int64)
    step = max(1, (1 << 22) // centres.shape[0])
    for p0 in range(0, directions.shape[0], step):
        dots = directions[p0:p0 + step] @ centres.T
        out[p0:p0 + step] = np.argpartition(-dots, k - 1, axis=1)[:, :k]
    return out


@dataclasses.dataclass(frozen=True)
class HighlightPairs:
    """The highlight pairs of one view under one map (module doc).

    texels : (P, K) int64 the texels each pixel integrates finely
    si : mi.SurfaceInteraction3f of the rays across the pixels (P q^2, pixel-major)
    frames : (s, t, n, wi) float64 (3, P q^2) each: their shading frames and the
        direction to the camera in them
    directions : (T S^2, 3) float64 world directions across the texels (texel-major);
    solid_angles : (T S^2,) their shares of the texels' solid angles
    pixel_side, texel_side : q and S
    visibility : (P, K q^2 S^2) bool (shadow rays) or None
    """
    texels: np.ndarray
    si: object
    frames: tuple
    directions: np.ndarray
    solid_angles: np.ndarray
    pixel_side: int
    texel_side: int
    visibility: np.ndarray = None

    @classmethod
    def build(cls, scene, sensor, shape, pixels, centre_si, centres, directions, solid_angles, trace, nearest,
              pixel_side=PIXEL_SIDE) -> "HighlightPairs":
        """The pairs of the pixels ``pixels`` (flat film indices; their centre rays
        ``centre_si``) with their ``nearest`` texels, of world ``centres`` (T, 3),
        each lit from the ``directions`` (T S^2, 3) with ``solid_angles`` (T S^2,)
        (texel-major); ``trace``: shadow rays through ``scene``."""
        texels = nearest_texels(mirror_directions(centre_si), centres, nearest)
        q2 = pixel_side * pixel_side
        si, hit = sample_hits(scene, sensor, shape, pixels, pixel_side)
        centre = np.repeat(np.arange(len(pixels)), q2)
        si = dr.select(mi.Bool(hit), si, dr.gather(mi.SurfaceInteraction3f, centre_si, mi.UInt32(centre)))
        frames = tuple(np.array(v, dtype=np.float64) for v in (si.sh_frame.s, si.sh_frame.t, si.sh_frame.n, si.wi))
        s2 = directions.shape[0] // centres.shape[0]
        out = cls(texels, si, frames, np.asarray(directions, np.float64), np.asarray(solid_angles, np.float64),
                  int(pixel_side), int(round(np.sqrt(s2))))
        return dataclasses.replace(out, visibility=out._shadow_rays(scene, centre_si)) if trace else out

    @property
    def n_pixels(self) -> int:
        return self.texels.shape[0]

    @property
    def per_pair(self) -> int:
        """Lanes per pixel-texel pair: q^2 rays x S^2 directions."""
        return self.pixel_side ** 2 * self.texel_side ** 2

    @property
    def n_lanes(self) -> int:
        return self.texels.size * self.per_pair

    def subset(self, rows) -> "HighlightPairs":
        """The pairs of the pixels ``rows``."""
        rows = np.asarray(rows, dtype=np.int64)
        q2 = self.pixel_side ** 2
        rays = (rows[:, None] * q2 + np.arange(q2)).reshape(-1)
        si = dr.gather(mi.SurfaceInteraction3f, self.si, mi.UInt32(rays.astype(np.uint32)))
        return dataclasses.replace(self, texels=self.texels[rows], si=si, frames=tuple(f[:, rays] for f in self.frames),
                                   visibility=None if self.visibility is None else self.visibility[rows])

    def excluded(self, per_texel, t0, t1) -> np.ndarray:
        """(N,) int64: the lanes of the texel sum's pairs that are highlight pairs
        (so the texel sum leaves them out), among its lanes for the light directions
        [t0, t1) (pixel-major; ``per_texel`` directions a texel, contiguous)."""
        d = (self.texels[:, :, None] * per_texel + np.arange(per_texel)).reshape(self.n_pixels, -1)
        p, i = np.nonzero((d >= t0) & (d < t1))
        return p * (t1 - t0) + d[p, i] - t0

    def lanes(self, l0=0, l1=None):
        """(ray index, direction index) of lanes [l0, l1) (Dr.Jit UInt32)."""
        l1 = self.n_lanes if l1 is None else l1
        K, q2, s2 = self.texels.shape[1], self.pixel_side ** 2, self.texel_side ** 2
        lane = dr.arange(mi.UInt32, l0, l1)
        pair = lane // self.per_pair                            # p K + k
        a = (lane // s2) % q2
        j = lane % s2
        texel = dr.gather(mi.UInt32, mi.UInt32(self.texels.reshape(-1).astype(np.uint32)), pair)
        return (pair // K) * q2 + a, texel * s2 + j

    def _shadow_rays(self, scene, centre_si) -> np.ndarray:
        """(P, K q^2 S^2) bool: the visibility of each lane, traced from the pixel's
        centre hit ``centre_si`` (as the texel sum's is) towards each of the pair's
        directions, the same for the pair's q^2 rays across the pixel: a shadow's edge
        moves little within one pixel, and this is q^2 times fewer rays."""
        K, q2, s2 = self.texels.shape[1], self.pixel_side ** 2, self.texel_side ** 2
        n = self.texels.size * s2                             # lanes (p K + k) S^2 + j
        out = np.ones(n, dtype=bool)
        d = mi.Vector3f(*(mi.Float(self.directions[:, k].astype(np.float32)) for k in range(3)))
        texels = mi.UInt32(self.texels.reshape(-1).astype(np.uint32))
        for l0 in range(0, n, CHUNK):
            lane = dr.arange(mi.UInt32, l0, min(l0 + CHUNK, n))
            pair = lane // s2
            si = dr.gather(mi.SurfaceInteraction3f, centre_si, pair // K)
            wo = dr.gather(mi.Vector3f, d, dr.gather(mi.UInt32, texels, pair) * s2 + lane % s2)
            blocked = scene.ray_test(si.spawn_ray(wo), (si.to_local(wo).z > 0) & (si.wi.z > 0))
            out[l0:l0 + dr.width(lane)] = ~blocked.numpy()
        out = np.broadcast_to(out.reshape(-1, 1, s2), (self.texels.size, q2, s2))
        return out.reshape(self.n_pixels, -1)

    def geometry(self) -> tuple:
        """(log cos theta_h, theta_d, weight) of every lane, as
        :meth:`TexelSum.pair_geometry <mi_dsbrdf.inference.forward.TexelSum.pair_geometry>`
        (the weight cos theta_o * solid angle / q^2 * visibility)."""
        q2 = self.pixel_side ** 2
        S = self.frames[0].shape[1]
        n_dir = self.directions.shape[0]
        buf = mi.Float(np.concatenate([np.concatenate(self.frames).reshape(-1), self.directions.T.reshape(-1),
                                       self.solid_angles.reshape(-1) / q2]).astype(np.float32))
        ray, direction = self.lanes()
        s_, t_, n_, wi = ([dr.gather(mi.Float, buf, ray + (3 * i + k) * S) for k in range(3)] for i in range(4))
        d = [dr.gather(mi.Float, buf, direction + 12 * S + k * n_dir) for k in range(3)]
        omega = dr.gather(mi.Float, buf, direction + 12 * S + 3 * n_dir)
        log_cos, theta_d, weight = pair_geometry((s_, t_, n_), wi, d, omega)
        if self.visibility is not None:
            weight = dr.select(mi.Bool(self.visibility.reshape(-1)), weight, 0.0)
        out = (log_cos, theta_d, weight)
        dr.eval(*out)
        return out

    def plugin_weights(self, bsdf):
        """BSDF (by its Mitsuba plugin) * cosine * solid angle / q^2 (* visibility)
        of every lane, a Color3f: the plain reference of :meth:`geometry`."""
        ray, direction = self.lanes()
        si = dr.gather(mi.SurfaceInteraction3f, self.si, ray)
        d = mi.Vector3f(*(mi.Float(self.directions[:, k].astype(np.float32)) for k in range(3)))
        f = bsdf.eval(mi.BSDFContext(), si, si.to_local(dr.gather(mi.Vector3f, d, direction)))
        f = f * dr.gather(mi.Float, mi.Float((self.solid_angles / self.pixel_side ** 2).astype(np.float32)),
                          direction)
        if self.visibility is not None:
            f = dr.select(mi.Bool(self.visibility.reshape(-1)), f, 0.0)
        return f

    def add_to(self, out, values, p0=0) -> np.ndarray:
        """Add per-pair ``values`` (3, n, K) of the pixels [p0, p0 + n) into the
        transport ``out`` (3, P, T)."""
        n, K = values.shape[1], self.texels.shape[1]
        rows = np.repeat(np.arange(p0, p0 + n), K)
        for c in range(3):
            out[c][rows, self.texels[p0:p0 + n].reshape(-1)] += values[c].reshape(-1)
        return out
