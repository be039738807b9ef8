"""Deterministic forward model: sum the illumination map's texels for each pixel.

For an object of known geometry under a lat-long illumination map L (H x W
texels t, direction d_t, solid angle Omega_t), the radiance of pixel p with
surface point x_p is

    I_p = sum_t L_t f(d_t, w_p) max(0, n_p . d_t) V(x_p, d_t) Omega_t

(f the BSDF of the object, w_p the direction to the camera, V the visibility:
shadow rays from x_p through the whole scene, so that the object shadows itself
and every other shape shadows it; traced when the object is not convex or other
shapes are in the scene, :mod:`~mi_dsbrdf.inference.scene_needs` decides).
Under a point or a directional light V is traced towards the light instead,
and each pixel is seen through ``pixel_rays`` x ``pixel_rays`` rays across its
area, their mean its value (what a box pixel filter averages): the light's
lanes are cheap (one per ray, not one per ray and texel), and at the
terminator or on a lobe narrower than one pixel's reflected directions the
centre ray alone is off by several per cent of Mitsuba's render.
With ``samples`` s > 1 each texel is lit from s x s directions of its
footprint, each with its share of the solid angle (the sum over t then runs
over them, L_t shared): the map as a piecewise-constant function of direction,
as a camera sees it. From the texel centres alone a lobe narrower than the
texel spacing sparkles where the image is smooth. A lobe narrower than the
directions one pixel reflects needs the pixel's area too: the highlight pairs
(:mod:`~mi_dsbrdf.inference.highlights`) take each pixel's texels nearest its
mirror direction out of the sum and integrate them over the pixel's area and
the texel. Unlike Monte Carlo rendering
this is noise-free, so gradients are exact and the optimiser can use line
searches.
Geometry comes from Mitsuba (one ray through each pixel centre); the BSDF is
the scene's ``dsbrdf`` (or any) Mitsuba BSDF, evaluated by Dr.Jit on
``llvm_ad_rgb``, so its parameters get gradients by automatic differentiation.

With the reflectance fixed, the image is linear in L: I = T L, and
:meth:`TexelSum.transport` returns T for the illumination block.
"""
from __future__ import annotations

import copy
import functools

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_dsbrdf.brdf.angles import pair_geometry
from mi_dsbrdf.inference.bounce import DIRECTIONS as BOUNCE_DIRECTIONS, SurfacePairs, light_bounces, map_bounces
from mi_dsbrdf.inference.highlights import TEXEL_SIDE, HighlightPairs
from mi_dsbrdf.inference.latlong import latlong_directions, texel_directions
from mi_dsbrdf.inference.rays import FootprintRays, centre_hits, shadow_test
from mi_dsbrdf.inference.transport import apply_transport

#: Pixel-texel pairs evaluated per Dr.Jit launch (memory / speed trade-off).
CHUNK = 1 << 22


class TexelSum:
    """Geometry of one view of one object, and the texel sums over it.

    Parameters
    ----------
    scene : mi.Scene with one sensor and the object
    shape : the object (a mi.Shape of the scene)
    map_size : (H, W) of the illumination map
    visibility : trace shadow rays through ``scene`` (a non-convex object, other shapes)
    to_world : 4x4 matrix of the envmap's to_world (default identity)
    samples : directions per texel side (s x s per texel, module doc)
    highlights : how many texels nearest each pixel's mirror direction are integrated
        over the pixel's area and the texel (:mod:`~mi_dsbrdf.inference.highlights`; 0: none)
    pixel_rays : rays per pixel side under a point or directional light
        (:meth:`with_point`, :meth:`with_directions` of one direction; module doc);
        1: the centre ray
    surfaces : other shapes of ``scene`` whose light onto the object is modelled (one
        bounce off a diffuse surface, :mod:`~mi_dsbrdf.inference.bounce`; needs
        ``visibility``): their :class:`~mi_dsbrdf.inference.bounce.Bounce` terms
        are ``bounces``
    """

    def __init__(self, scene, shape, map_size, visibility=False, to_world=None, samples=1, highlights=0,
                 pixel_rays=1, surfaces=()):
        sensor = scene.sensors()[0]
        w, h = (int(v) for v in sensor.film().crop_size())
        self.image_size = (h, w)
        si, hit = centre_hits(scene, sensor, shape)
        self.mask = hit.reshape(h, w)                      # pixels that see the object
        self.pixels = np.nonzero(hit)[0]
        idx = mi.UInt32(self.pixels.astype(np.uint32))
        self.si = dr.gather(mi.SurfaceInteraction3f, si, idx)
        # per pixel: shading frame (s, t, n), the direction to the camera in it and
        # the surface point, (3, P) each
        self.frames = tuple(np.array(v, dtype=np.float64) for v in (self.si.sh_frame.s, self.si.sh_frame.t,
                                                                    self.si.sh_frame.n, self.si.wi))
        self.positions = np.array(self.si.p, dtype=np.float64)
        self.pixel_rays = _rays_per_side(pixel_rays)
        self.bsdf = shape.bsdf()
        self._scene, self._sensor, self._shape, self._trace = scene, sensor, shape, visibility
        self._surfaces = tuple(surfaces) if visibility else ()
        self._to_world = None if to_world is None else np.asarray(to_world, dtype=np.float64)[:3, :3]
        self._map(map_size, samples, highlights)

    def _world(self, d) -> np.ndarray:
        """Map-frame directions (N, 3) in world space (the envmap's to_world)."""
        if self._to_world is None:
            return d
        d = d @ self._to_world.T
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def _map(self, map_size, samples=1, highlights=0):
        H, W = (int(v) for v in map_size)
        s = int(samples)
        if s < 1:
            raise ValueError("samples per texel side must be >= 1, got %r" % (samples,))
        self.map_size = (H, W)
        d, omega = texel_directions(H, W, s)
        self._light(self._world(d), omega, None, s * s)
        self.highlights = self._highlight_pairs(highlights)

    def _highlight_pairs(self, highlights):
        if not highlights:
            return None
        H, W = self.map_size
        fine, fine_omega = texel_directions(H, W, TEXEL_SIDE)
        return HighlightPairs.build(self._scene, self._sensor, self._shape, self.pixels, self.si,
                                    self._world(latlong_directions(H, W).reshape(-1, 3)), self._world(fine),
                                    fine_omega, self._trace, nearest=highlights)

    # A TexelSum is never changed once made: a new light, BSDF or pixel subset
    # is a new (shallow) copy that shares the geometry. (Its footprint_rays are
    # traced on first use and kept: geometry of its own, not a change.)
    def with_map_size(self, map_size, samples=1) -> "TexelSum":
        """This view under an illumination map of ``map_size`` (H, W) texels, each
        lit from ``samples`` x ``samples`` directions (module doc)."""
        out = copy.copy(self)
        out._map(map_size, samples)
        return out

    def with_highlights(self, highlights) -> "TexelSum":
        """This map view with the highlight pairs of ``highlights`` texels a pixel
        (class doc; 0: none). Its shadow rays and bounces are this view's: only the
        pairs are built."""
        if self.ray_lanes:
            raise ValueError("with_highlights: a map view's, not a point or directional light's")
        out = copy.copy(self)
        out.highlights = self._highlight_pairs(highlights)
        return out

    def with_directions(self, directions, solid_angles) -> "TexelSum":
        """This view lit from the world directions (T, 3) with solid angles (T,)
        instead of the map's texels. One direction with solid angle 1 makes the
        sum a directional light whose 'radiance' is its irradiance, seen over each
        pixel's footprint (module doc)."""
        directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        solid_angles = np.asarray(solid_angles, dtype=np.float64).reshape(-1)
        if directions.shape[0] == 1:
            return self._over_rays(lambda rays: (np.repeat(directions, rays.share.size, axis=0),
                                                 solid_angles[0] * rays.share), None)
        out = copy.copy(self)
        out._light(directions, solid_angles, None)
        return out

    def with_point(self, position) -> "TexelSum":
        """This view lit from a point at ``position`` (world): one 'texel' whose
        direction and solid angle 1/r^2 differ per ray of each pixel's footprint
        (module doc), so that its 'radiance' is the point light's intensity (W/sr,
        Mitsuba's ``point`` emitter)."""
        p = np.asarray(position, dtype=np.float64).reshape(3)

        def light(rays):
            d = p - rays.positions.T
            r2 = np.maximum((d * d).sum(axis=1), 1e-12)
            return d / np.sqrt(r2)[:, None], rays.share / r2
        return self._over_rays(light, p)

    def _over_rays(self, light, position) -> "TexelSum":
        """This view under a point or directional light over each pixel's footprint:
        ``light(footprint_rays)`` gives each ray's direction (N, 3) and solid angle
        times its share (N,)."""
        rays = self.footprint_rays       # traced once, shared by every light of this view
        if self._surfaces:
            self.bounce_view             # so are the pairs that find the surfaces
        out = copy.copy(self)
        out._light(*light(rays), position, per_texel=rays.side ** 2, ray_lanes=True)
        return out

    def with_pixel_rays(self, pixel_rays) -> "TexelSum":
        """This view, not yet under a point or directional light, with ``pixel_rays``
        x ``pixel_rays`` rays a pixel under one."""
        if self.ray_lanes:
            raise ValueError("with_pixel_rays: this view is lit already; change the rays before the light")
        out = copy.copy(self)
        out.__dict__.pop("footprint_rays", None)
        out.pixel_rays = _rays_per_side(pixel_rays)
        return out

    @functools.cached_property
    def footprint_rays(self) -> FootprintRays:
        """The ``pixel_rays`` x ``pixel_rays`` rays across each pixel that a point or
        directional light's lanes see (traced on first use: a map never needs them)."""
        return FootprintRays.trace(self._scene, self._sensor, self._shape, self.pixels, self.si, self.pixel_rays)

    def with_bsdf(self, bsdf) -> "TexelSum":
        """This view with the object's BSDF replaced by ``bsdf`` (a mi.BSDF)."""
        out = copy.copy(self)
        out.bsdf = bsdf
        return out

    def _light(self, directions, solid_angles, position, per_texel=1, ray_lanes=False):
        self.directions, self.solid_angles, self.light_position = directions, solid_angles, position
        self.per_texel = per_texel          # consecutive directions that share one texel's radiance
        # a light's lanes are the rays of footprint_rays, each with its own direction
        # and solid angle (times the ray's share of its pixel); a map's are pixel x direction
        self.ray_lanes = ray_lanes
        self.highlights = None              # a map's (_map) or none
        # (visibility, bounces): a map's traced now; a light's on first use (a light
        # search re-aims views it never renders), then kept like footprint_rays
        self._shadows = None if ray_lanes else self._trace_visibility(self._scene)

    @property
    def visibility(self):
        """(P, n_directions) bool: the light of each pixel-direction pair reaches its
        surface point (shadow rays through the scene); None without them."""
        return self._shadowing()[0]

    @property
    def bounces(self) -> tuple:
        """The :class:`~mi_dsbrdf.inference.bounce.Bounce` of each of ``surfaces``
        that blocks a pair."""
        return self._shadowing()[1]

    def _shadowing(self) -> tuple:
        if self._shadows is None:
            self._shadows = self._trace_visibility(self._scene)
        return self._shadows

    def subset(self, rows) -> "TexelSum":
        """The same view restricted to the pixels ``self.pixels[rows]`` (sharing the
        light directions): the reflectance block fits 16 variables and needs far
        fewer pixels than the illumination block, whose unknowns are the texels."""
        rows = np.asarray(rows, dtype=np.int64)
        sub = copy.copy(self)
        sub.pixels = self.pixels[rows]
        sub.si = dr.gather(mi.SurfaceInteraction3f, self.si, mi.UInt32(rows.astype(np.uint32)))
        sub.frames = tuple(f[:, rows] for f in self.frames)
        sub.positions = self.positions[:, rows]
        if "footprint_rays" in self.__dict__:              # traced already: the pixels' own
            sub.footprint_rays = self.footprint_rays.subset(rows)
        if "bounce_view" in self.__dict__:
            sub.bounce_view = self.bounce_view.subset(rows)
        if self._shadows is not None:                      # else the subset traces its own on first use
            vis, bounces = self._shadows
            sub._shadows = (None if vis is None else vis[rows],
                            tuple(b.subset(rows, None if b.pairs is None else sub.bounce_view) for b in bounces))
        if self.ray_lanes:
            lanes = (rows[:, None] * self.per_texel + np.arange(self.per_texel)).reshape(-1)
            sub.directions, sub.solid_angles = self.directions[lanes], self.solid_angles[lanes]
        if self.highlights is not None:
            sub.highlights = self.highlights.subset(rows)
        return sub

    @property
    def n_pixels(self) -> int:
        return self.pixels.size

    @property
    def n_texels(self) -> int:
        return self.n_directions // self.per_texel

    @property
    def n_directions(self) -> int:
        """Light directions per pixel (pixel-direction pairs per pixel): texels x samples,
        or a light's rays a pixel."""
        return self.per_texel if self.ray_lanes else self.directions.shape[0]

    def texel_sums(self, pairs, rows) -> np.ndarray:
        """(rows, texels) float32: sums over each texel's directions of ``pairs``, a
        Dr.Jit Float of rows x directions values (row-major; whole texels in order:
        all of them, or a chunk of :meth:`_chunks`). Summed by Dr.Jit before the copy
        to numpy (numpy's reduction over the short last axis is slow)."""
        if self.per_texel > 1:
            pairs = dr.block_sum(pairs, self.per_texel)
        return pairs.numpy().reshape(rows, -1)

    def _pairs(self, t0, t1):
        """Lanes for directions [t0, t1) x all pixels (pixel-major): (si, wo_local,
        pixel, direction, the lane's index into ``directions`` and ``solid_angles``)."""
        P, nt = self.n_pixels, t1 - t0
        lane = dr.arange(mi.UInt32, P * nt)
        pix = lane // nt
        tex = lane - pix * nt + t0
        if self.ray_lanes:
            light = pix * self.n_directions + tex          # the ray's index
            si = dr.gather(mi.SurfaceInteraction3f, self.footprint_rays.si, light)
        else:
            light = tex
            si = dr.gather(mi.SurfaceInteraction3f, self.si, pix)
        d = mi.Vector3f(*(mi.Float(self.directions[:, k].astype(np.float32)) for k in range(3)))
        wo = si.to_local(dr.gather(mi.Vector3f, d, light))
        return si, wo, pix, tex, light

    def _chunks(self):
        """Direction ranges [t0, t1), whole texels each."""
        step = max(1, CHUNK // max(self.n_pixels, 1) // self.per_texel) * self.per_texel
        return [(t, min(t + step, self.n_directions)) for t in range(0, self.n_directions, step)]

    def _trace_visibility(self, scene):
        """((P, n_directions) bool: the light of each pixel-direction pair reaches its
        surface point (:func:`~mi_dsbrdf.inference.rays.shadow_test`): a light's rays
        (one per lane), or the pixels' centre hits; the
        :class:`~mi_dsbrdf.inference.bounce.Bounce` of each of ``surfaces`` that
        blocks a pair); (None, ()) without shadow rays."""
        if not self._trace:
            return None, ()
        if self.ray_lanes:
            # a light's rays see the light alone: the surfaces the pixels see come
            # from bounce_view's map of directions
            vis = self.footprint_rays.shadow_test(scene, self.light_position, self.directions[0]).reshape(
                self.n_pixels, self.n_directions)
            if not self._surfaces:
                return vis, ()
            return vis, light_bounces(scene, self.bounce_view, self.light_position, self.directions[0])
        normals = np.array(self.si.n, dtype=np.float64)
        vis, which = shadow_test(scene, self.positions, normals, self.frames, self.directions, None,
                                 self.n_pixels, self.n_directions, self._chunks(), False, self._surfaces)
        if not self._surfaces:
            return vis, ()
        return vis, map_bounces(scene, self._surfaces, which, self.positions, normals, self.directions,
                                self.solid_angles, self.per_texel)

    @functools.cached_property
    def bounce_view(self) -> SurfacePairs:
        """This view's pixels lit from the centres of a
        :data:`~mi_dsbrdf.inference.bounce.DIRECTIONS` map, shadow rays traced: the
        pairs in which a point or directional light's view sees the other surfaces
        (traced on first use, shared by every light of the view)."""
        return SurfacePairs(self.with_map_size(BOUNCE_DIRECTIONS))

    def _weights(self, si, wo, light, t0, t1, mask=None):
        """BSDF * cosine * solid angle (* visibility) per lane, as a Color3f
        (``light``: the lanes' indices into ``solid_angles``, of :meth:`_pairs`).
        ``mask`` (P, n_directions) bool: the lanes kept instead of the visible ones
        (a bounce's blocked pairs), the highlight pairs among them."""
        ctx = mi.BSDFContext()
        f = self.bsdf.eval(ctx, si, wo)
        omega = dr.gather(mi.Float, mi.Float(self.solid_angles.astype(np.float32)), light)
        f = f * omega
        if mask is not None:
            return dr.select(mi.Bool(mask[:, t0:t1].reshape(-1)), f, 0.0)
        if self.visibility is not None:
            v = mi.Bool(self.visibility[:, t0:t1].reshape(-1))
            f = dr.select(v, f, 0.0)
        if self.highlights is not None:               # those pairs are the highlights' (class doc)
            out = np.zeros(self.n_pixels * (t1 - t0), bool)
            out[self.highlights.excluded(self.per_texel, t0, t1)] = True
            f = dr.select(mi.Bool(out), 0.0, f)
        return f

    def transport(self) -> np.ndarray:
        """(3, P, T) float32 transport, channel-major so that the products with a
        map are matrix-vector products: radiance[p, c] = T[c, p] @ L[:, c]."""
        out = np.zeros((3, self.n_pixels, self.n_texels), dtype=np.float32)
        k = self.per_texel
        with dr.suspend_grad():
            for t0, t1 in self._chunks():
                si, wo, _, _, light = self._pairs(t0, t1)
                f = self._weights(si, wo, light, t0, t1)
                for c in range(3):
                    out[c, :, t0 // k:t1 // k] = self.texel_sums(f[c], self.n_pixels)
            if self.highlights is not None:
                h = dr.block_sum(self.highlights.plugin_weights(self.bsdf), self.highlights.per_pair)
                self.highlights.add_to(out, np.array(h).reshape(3, self.n_pixels, -1))
            for bounce in self.bounces:                  # rank one a surface (inference/bounce.py)
                b = sum(np.array(f).reshape(3, self.n_pixels) for f in self._bounce_chunks(bounce))
                m = bounce.transport_term.astype(np.float32)
                for c in range(3):
                    out[c] += np.multiply.outer(b[c].astype(np.float32), m[c])
        return out

    def _bounce_chunks(self, bounce):
        """Yield (P,) Color3f: each pixel's sum of BSDF * cosine * solid angle over the
        pairs ``bounce`` blocks, a chunk of directions at a time (with whatever AD
        graph the BSDF parameters carry)."""
        view = self if bounce.pairs is None else bounce.pairs.view.with_bsdf(self.bsdf)
        for t0, t1 in view._chunks():
            si, wo, _, _, light = view._pairs(t0, t1)
            yield dr.block_sum(view._weights(si, wo, light, t0, t1, bounce.blocked), t1 - t0)

    def pair_geometry(self, mask=None) -> tuple:
        """What an isotropic BRDF sees of each pixel-texel pair: (log cos theta_h,
        theta_d, weight), three Dr.Jit Floats of P * n_directions lanes (pixel-major), the
        weight cos theta_o * solid angle (* visibility), zero unless the camera and
        the texel are both above the surface (the plugins' ``both_above``). ``mask``
        (P, n_directions) bool: the pairs weighted instead of the visible ones (a
        bounce's blocked pairs, :mod:`~mi_dsbrdf.inference.bounce`).
        :class:`~mi_dsbrdf.inference.lobes.LobeSum` evaluates the DSBRDF on them."""
        P, nt = self.n_pixels, self.n_directions
        n_light = self.directions.shape[0]
        lane = dr.arange(mi.UInt32, P * nt)
        pix = lane // nt
        light = np.concatenate([self.directions.T.reshape(-1), self.solid_angles.reshape(-1)]).astype(np.float32)
        if self.ray_lanes:
            # a light's rays (one per lane): their frames are the view's, kept in one
            # Dr.Jit array (FootprintRays.frame_buffer), and the light is one fresh array
            frames, buf = self.footprint_rays.frame_buffer, mi.Float(light)
            geo, per_light, stride, first = lane, lane, P * nt, 0
        else:
            # All inputs in one array: with several fresh input arrays Dr.Jit's kernel
            # hash depends on their allocation order, and every call compiled anew.
            frames = buf = mi.Float(np.concatenate([np.concatenate(self.frames).reshape(-1).astype(np.float32),
                                                    light]))
            geo, per_light, stride, first = pix, lane - pix * nt, P, 12 * P
        # frames: 12 rows of ``stride`` values; the light's from ``first`` in buf
        s_, t_, n_, wi = ([dr.gather(mi.Float, frames, geo + (3 * i + k) * stride) for k in range(3)]
                          for i in range(4))
        d = [dr.gather(mi.Float, buf, per_light + first + k * n_light) for k in range(3)]
        omega = dr.gather(mi.Float, buf, per_light + first + 3 * n_light)
        log_cos, theta_d, weight = pair_geometry((s_, t_, n_), wi, d, omega)
        if mask is not None:                          # a bounce's blocked pairs
            weight = dr.select(mi.Bool(mask.reshape(-1)), weight, 0.0)
        elif self.visibility is not None:
            weight = dr.select(mi.Bool(self.visibility.reshape(-1)), weight, 0.0)
        if self.highlights is not None and mask is None:       # those pairs are the highlights' (class doc)
            dr.scatter(weight, 0.0, mi.UInt32(self.highlights.excluded(self.per_texel, 0, nt).astype(np.uint32)))
        out = (log_cos, theta_d, weight)
        dr.eval(*out)
        return out

    def render(self, illumination) -> np.ndarray:
        """(P, 3) float64 pixel radiance for an (H, W, 3) map (no gradients)."""
        return apply_transport(self.transport(), illumination)

    def _radiance_chunks(self, illumination):
        """Yield (P,) Color3f radiance from each chunk of texels under
        ``illumination`` (T, 3), with whatever AD graph the BSDF parameters carry."""
        L = np.asarray(illumination, dtype=np.float32).reshape(-1, 3)
        Lt = mi.Color3f(*(mi.Float(L[:, c]) for c in range(3)))
        for t0, t1 in self._chunks():
            si, wo, _, tex, light = self._pairs(t0, t1)
            f = self._weights(si, wo, light, t0, t1) * dr.gather(mi.Color3f, Lt, tex // self.per_texel)
            yield dr.block_sum(f, t1 - t0)                   # (P,) radiance from these texels
        if self.highlights is not None:
            h = self.highlights
            _, direction = h.lanes()
            f = h.plugin_weights(self.bsdf) * dr.gather(mi.Color3f, Lt, direction // h.texel_side ** 2)
            yield dr.block_sum(f, h.texels.shape[1] * h.per_pair)
        for bounce in self.bounces:                      # its radiance on the pairs it blocks
            R = mi.Color3f(*(float(v) for v in bounce.radiance(L)))
            for f in self._bounce_chunks(bounce):
                yield f * R

    def reflectance_jacobian(self, illumination, params, keys):
        """Pixel radiance (P, 3) and its Jacobian (P, 3, n) with respect to the BSDF
        parameters ``keys`` of ``params`` (gradients enabled by the caller), by
        forward-mode AD through the plugin, one chunk of texels at a time."""
        image, jac = np.zeros((self.n_pixels, 3)), None
        for partial in self._radiance_chunks(illumination):
            image += np.array(dr.detach(partial)).T
            cols = _forward_columns(partial, [params[k] for k in keys])
            jac = cols if jac is None else jac + cols
        return image, jac


def _rays_per_side(value) -> int:
    """``pixel_rays`` as an int; ValueError below 1."""
    if int(value) < 1:
        raise ValueError("rays per pixel side must be >= 1, got %r" % (value,))
    return int(value)


def _forward_columns(partial, variables):
    """Forward-mode derivatives of ``partial`` (a Color3f of P pixels) with respect
    to every entry of every Float in ``variables``: a (P, 3, n) float64 array."""
    cols = []
    for var in variables:
        n = dr.width(var)
        for i in range(n):
            e = np.zeros(n, dtype=np.float32)
            e[i] = 1.0
            dr.set_grad(var, type(var)(e))
            cols.append(np.array(dr.forward_to(partial, flags=dr.ADFlag.ClearInput | dr.ADFlag.ClearInterior)).T)
            dr.clear_grad(partial)
            dr.clear_grad(var)
    return np.stack(cols, axis=-1).astype(np.float64)

