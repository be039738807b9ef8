"""The inverse rendering a Mitsuba user would write instead: Monte Carlo
differentiable rendering (``prb``) and Adam, no priors.

Two BSDFs share one loop (:func:`adam_recover`):

* ``principled-adam``: Mitsuba's ``principled`` BSDF (base colour, roughness,
  metallic, specular), the baseline of the experiments report;
* ``dsbrdf-adam``: the ``dsbrdf`` plugin's basis coefficients psi and lobe
  chromaticities, which isolates the optimiser and the Monte Carlo gradients
  from the model when compared with :func:`mi_dsbrdf.inference.envmap.recover`.

The illumination is an ``envmap`` whose log radiance is an Adam variable
(positive by construction); the loss is the Laplacian likelihood on log pixel
values (Eq. 19 without priors, as a mean), each iteration's render with a new
seed at ``spp`` samples per pixel.
"""
from __future__ import annotations

import time

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_dsbrdf.brdf.dsbrdf import Material
from mi_dsbrdf.inference.scene_dicts import camera, shape_dict

#: Adam's learning rate for the BSDF variables and for the log illumination
LR_BSDF, LR_MAP = 0.02, 0.05
#: the largest gradient component Adam is given (its square stays a float32)
GRAD_LIMIT = 1e15


def _scene(bsdf, res, map_hw, shape, level, base=None):
    H, W = map_hw
    env = mi.Bitmap(np.full((H, W, 3), level, dtype=np.float32))
    if base is None:
        d = {"type": "scene", "integrator": {"type": "prb", "max_depth": 2 if shape == "sphere" else 3},
             "sensor": camera(res), "object": shape_dict(shape, bsdf)}
    else:                   # the user's scene: one bounce off its other shapes, as the tool models
        d = dict(base, integrator={"type": "prb", "max_depth": 3}, object=dict(base["object"], bsdf=bsdf))
    return mi.load_dict(dict(d, emitter={"type": "envmap", "bitmap": env}))


def drop_non_finite_gradients(opt) -> int:
    """Set every non-finite gradient component of the optimizer's variables to 0
    (that component skips the step; Adam's moments keep it moving) and clip the
    others to +-GRAD_LIMIT (Adam squares them in float32). A Monte Carlo
    gradient through the ``dsbrdf`` plugin can overflow at extreme psi under a
    noisy image. Returns how many components were dropped."""
    dropped = 0
    for key in list(opt.keys()):
        g = dr.grad(opt[key])
        bad = ~dr.isfinite(g)
        dropped += int(np.count_nonzero(np.array(bad)))
        dr.set_grad(opt[key], dr.clip(dr.select(bad, 0, g), -GRAD_LIMIT, GRAD_LIMIT))
    return dropped


def adam_recover(image, mask, res, map_hw, method, model=None, spp=16, iters=100, shape="sphere", seed=0,
                 progress=None, scene=None, seconds=None) -> dict:
    """Fit ``method``'s BSDF and an envmap of ``map_hw`` to ``image`` (res, res, 3)
    over ``mask`` (res, res) bool by Adam through Mitsuba's ``prb``: the object
    ``shape`` alone before the front camera, or a ``scene`` dict with a "sensor",
    the "object" (its BSDF replaced) and other shapes but no emitter. At most
    ``iters`` iterations, and none begun after ``seconds`` (a budget: matched time).

    Returns {"bsdf": the Mitsuba BSDF (principled) or a DSBRDF Material,
    "map": (H, W, 3) float64, "rows": [{"round", "neg_log_posterior", "seconds"}]}:
    the last iterate's, or if the loss or a variable turns non-finite (Adam
    diverged) the lowest-loss iterate's, the loop stopped there.
    """
    if method == "principled-adam":
        bsdf = {"type": "principled", "base_color": {"type": "rgb", "value": [0.5, 0.5, 0.5]},
                "roughness": 0.5, "metallic": 0.0, "specular": 0.5}
        keys = {"object.bsdf.base_color.value": (0.0, 1.0), "object.bsdf.roughness.value": (0.01, 1.0),
                "object.bsdf.metallic.value": (0.0, 1.0), "object.bsdf.specular": (0.0, 1.0)}
    elif method == "dsbrdf-adam":
        k, R = model.basis.n_bases, model.basis.n_lobes
        bsdf = {"type": "dsbrdf", "model": model.source, "psi": " ".join(["0"] * k)}
        keys = {"object.bsdf.psi": (-10.0, 10.0), "object.bsdf.chromaticity": (1e-3, 1.0)}
    else:
        raise ValueError("method must be principled-adam or dsbrdf-adam, got %r" % (method,))
    obs = np.asarray(image, np.float64)
    m = np.asarray(mask, bool)
    level = float(np.median(obs[m])) * 2.0
    scene = _scene(bsdf, res, map_hw, shape, level, scene)
    params = mi.traverse(scene)
    opt = mi.ad.Adam(lr=LR_BSDF)
    for key in keys:
        opt[key] = params[key]
    opt["log_map"] = dr.log(params["emitter.data"])
    opt.set_learning_rate({"log_map": LR_MAP})
    offset = 1e-3 * float(obs[m].mean())
    target = mi.TensorXf(np.log(np.maximum(obs, 0) + offset).astype(np.float32))
    weight = mi.TensorXf(np.repeat(m[..., None], 3, axis=2).astype(np.float32) / (3 * m.sum()))
    rows, t0 = [], time.perf_counter()
    best = (np.inf, None)           # the lowest loss so far and the variables it was rendered with
    for it in range(iters):
        if seconds is not None and it and time.perf_counter() - t0 >= seconds:
            break
        params["emitter.data"] = dr.exp(opt["log_map"])
        params.update(opt)
        img = mi.render(scene, params, spp=spp, seed=seed + it)
        loss = dr.sum(dr.abs(dr.log(dr.fmax(img, 0.0) + offset) - target) * weight, axis=None)
        before = {key: dr.detach(opt[key]) for key in opt.keys()}     # references: a step makes new arrays
        dr.backward(loss)
        drop_non_finite_gradients(opt)
        opt.step()
        for key, (lo, hi) in keys.items():
            opt[key] = dr.clip(opt[key], lo, hi)
        if method == "dsbrdf-adam":          # chromaticity: each lobe's three values sum to one
            c = np.array(opt["object.bsdf.chromaticity"], np.float64).reshape(-1, 3)
            opt["object.bsdf.chromaticity"] = mi.Float((c / c.sum(axis=1, keepdims=True)).reshape(-1))
        # the loss read after the step (read before it, it costs 15 % of the time)
        value = float(np.array(loss).reshape(-1)[0])
        rows.append({"round": it, "neg_log_posterior": value, "seconds": time.perf_counter() - t0})
        # a NaN variable renders black through dr.fmax, so the loss alone may stay finite
        finite = [dr.all(dr.isfinite(opt[key]), axis=None) for key in opt.keys()]
        dr.eval(*finite)                     # one launch for all of them
        if not (np.isfinite(value) and all(bool(f) for f in finite)):
            # Adam diverged (a noisy image can drive the dsbrdf plugin's psi to where it
            # overflows): the answer is the best iterate, as a user's loop would keep
            # (otherwise the last one)
            for key, v in (best[1] or before).items():
                opt[key] = v
            break
        if value < best[0]:
            best = (value, before)
        if progress:
            progress(rows[-1])
    params["emitter.data"] = dr.exp(opt["log_map"])
    params.update(opt)
    env = np.array(params["emitter.data"], np.float64)[:, 1:-1, :3]
    if method == "dsbrdf-adam":
        psi = np.array(params["object.bsdf.psi"], np.float64)
        chroma = np.array(params["object.bsdf.chromaticity"], np.float64).reshape(R, 3)
        fitted = Material.from_basis(model.basis, psi, chroma)
    else:
        fitted = [sh for sh in scene.shapes() if sh.id() == "object"][0].bsdf()
    return {"bsdf": fitted, "map": env, "rows": rows}
