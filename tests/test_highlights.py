"""Highlight pairs (inference/highlights.py): each pixel's texels nearest its mirror
direction, integrated over the pixel's area and over the texel, against plain
references: the same sum over a finer film and a finer map, and the fast path
(LobeSum) against the plugin (TexelSum)."""
import copy
import dataclasses

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_dsbrdf.evaluation.experiment import dsbrdf_bsdf, texels
from mi_dsbrdf.inference.highlights import PIXEL_SIDE, TEXEL_SIDE
from mi_dsbrdf.inference.latlong import latlong_directions, procedural_sky
from mi_dsbrdf.inference.lobes import LobeSum, observed_directions
from mi_dsbrdf.inference.pixels import interior
from mi_dsbrdf.inference.reflectance import psi_jacobian
from mi_dsbrdf.model import model_file as model_data

#: image size, map size, highlight texels a pixel
RES, MAP, NEAREST = 16, (8, 16), 9


def relative(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


def highlight_mask(h, n_texels):
    mask = np.zeros((h.n_pixels, n_texels), bool)
    mask[np.arange(h.n_pixels)[:, None], h.texels] = True
    return mask


def test_highlight_pairs_are_the_sum_over_a_finer_film_and_map():
    """A pixel's highlight texels hold the mean over the q x q pixels of a film q
    times finer, each texel lit from S x S directions; its other texels hold the
    plain texel sum. The highlight texels are those nearest the mirror direction."""
    bsdf = dsbrdf_bsdf(model_data.shipped_model().library_material("chrome"))
    plain = texels(bsdf, RES, MAP, samples=2)
    lit = plain.with_map_size(MAP, samples=2).with_highlights(NEAREST)
    h = lit.highlights
    assert h.texels.shape == (plain.n_pixels, NEAREST) and plain.highlights is None
    T, T0 = lit.transport(), plain.transport()
    mask = highlight_mask(h, lit.n_texels)
    assert relative(T[:, ~mask], T0[:, ~mask]) < 1e-6
    # the highlight texels surround each pixel's mirror direction
    si = plain.si
    n, v = np.array(si.sh_frame.n).T, np.array(si.to_world(si.wi)).T
    r = 2 * (n * v).sum(axis=1, keepdims=True) * n - v
    centres = latlong_directions(*MAP).reshape(-1, 3)
    assert np.all(np.argmax(r @ centres.T, axis=1) == h.texels[np.arange(h.n_pixels), np.argmax(
        np.einsum("pc,pkc->pk", r, centres[h.texels]), axis=1)])
    # against the finer film and map
    q, S = PIXEL_SIDE, TEXEL_SIDE
    fine = texels(bsdf, RES * q, MAP, samples=S)
    Tf = fine.transport()
    row_of = np.full(fine.mask.size, -1)
    row_of[fine.pixels] = np.arange(fine.n_pixels)
    inner = interior(plain.mask).reshape(-1)[plain.pixels]
    checked = 0
    for i in np.nonzero(inner)[0]:
        y, x = divmod(int(plain.pixels[i]), RES)
        subs = [row_of[(q * y + a) * RES * q + q * x + b] for a in range(q) for b in range(q)]
        if min(subs) < 0:
            continue
        ref = Tf[:, subs][:, :, h.texels[i]].mean(axis=1)
        assert np.abs(T[:, i, h.texels[i]] - ref).max() <= 1e-4 * Tf.max()
        checked += 1
    assert checked > 20


def test_fast_path_matches_the_plugin_with_highlights():
    """LobeSum's transport, subset, unseen texels, observed directions and Jacobian
    with the highlight pairs equal the plugin's (forward-mode AD)."""
    model = model_data.shipped_model()
    psi = np.linspace(-0.6, 0.6, model.basis.n_bases)
    chroma = np.array([[0.5, 0.3, 0.2], [0.2, 0.3, 0.5], [0.3, 0.4, 0.3]])
    props = {"type": "dsbrdf", "psi": " ".join(map(str, psi))}
    props.update({"chromaticity_%d" % r: " ".join(map(str, chroma[r])) for r in range(3)})
    from mi_dsbrdf.brdf.dsbrdf import Material
    material = Material.from_basis(model.basis, psi, chroma)
    ts = texels(props, RES, MAP).with_map_size(MAP, samples=2).with_highlights(NEAREST)
    fast = LobeSum(ts)
    T = ts.transport()
    assert T.max() > 0 and relative(fast.transport(material), T) < 1e-5
    rows = np.arange(0, ts.n_pixels, 5)
    assert relative(fast.subset(rows).transport(material), T[:, rows]) < 1e-5
    plain = LobeSum(texels(props, RES, MAP).with_map_size(MAP, samples=2))
    assert np.array_equal(fast.unseen, ~(T > 0).any(axis=(0, 1)))      # this material is > 0 above the horizon
    L = procedural_sky(*MAP).reshape(-1, 3)
    every = np.arange(ts.n_pixels)
    a, b = observed_directions(ts, L, every).weights, observed_directions(plain.texels, L, every).weights
    # the highlight pairs' lanes carry no weight: what the image looked at without them
    dropped = copy.copy(ts)
    dropped.highlights = dataclasses.replace(ts.highlights, solid_angles=0 * ts.highlights.solid_angles)
    c = observed_directions(dropped, L, every).weights
    # the same light integrated finer: nearer the centre sum's cells than without the
    # highlight pairs, and as much of it near the specular peak (small theta_h)
    assert 0.5 * np.abs(a - b).sum() < 0.6 * 0.5 * np.abs(c - b).sum()
    assert 0.5 < a[:4].sum() / b[:4].sum() < 2 and c[:4].sum() == 0
    params = mi.traverse(ts.bsdf)
    dr.enable_grad(params["psi"])
    dr.enable_grad(params["chromaticity"])
    params.update()
    image, J = ts.reflectance_jacobian(L, params, ["psi", "chromaticity"])
    jac = fast.jacobian(material, L)
    assert relative(jac.image, image) < 1e-5
    k = model.basis.n_bases
    assert relative(psi_jacobian(model.basis, psi, jac.controls).transpose(2, 1, 0), J[:, :, :k]) < 1e-4


def test_highlight_shadows_from_the_pixel_centre_agree_with_each_ray_across_the_pixel():
    """A card hides part of the map: the highlight pairs' shadow rays, traced from
    each pixel's centre hit, agree with rays from each of the q^2 points across the
    pixel on nearly every lane; with_highlights keeps the view's own shadows."""
    from test_scene_needs import card

    from mi_dsbrdf.inference.forward import TexelSum
    from mi_dsbrdf.inference.scene_dicts import camera
    s = mi.load_dict({"type": "scene", "sensor": camera(24), "object": {"type": "sphere", "bsdf": {"type": "dsbrdf"}},
                      "light": {"type": "constant"}, "card": card(0.5)})
    obj = [sh for sh in s.shapes() if sh.id() == "object"][0]
    view = TexelSum(s, obj, MAP, visibility=True, samples=2)
    lit = view.with_highlights(NEAREST)
    assert lit.visibility is view.visibility and lit.highlights is not None and view.highlights is None
    h = lit.highlights
    ray, direction = h.lanes()
    si = dr.gather(mi.SurfaceInteraction3f, h.si, ray)
    wo = dr.gather(mi.Vector3f, mi.Vector3f(*(mi.Float(h.directions[:, k].astype(np.float32)) for k in range(3))),
                   direction)
    each = ~s.ray_test(si.spawn_ray(wo), (si.to_local(wo).z > 0) & (si.wi.z > 0)).numpy().reshape(h.n_pixels, -1)
    assert not each.all() and not h.visibility.all()
    # measured: 0.2 % of the lanes differ, of 3 % in shadow (a shadow's edge within a pixel)
    assert np.mean(each != h.visibility) < 0.15 * np.mean(~each), (np.mean(each != h.visibility), np.mean(~each))
