"""Joint MAP estimation of reflectance and illumination (paper §5).

The negative log posterior (Eq. 18) of the DSBRDF variables (psi, chromaticity)
and the log illumination map x = log L is minimised by alternating two blocks:

* illumination: reflectance fixed, the image is linear in L (I = T L, T from
  :class:`~mi_dsbrdf.inference.forward.TexelSum`), so each evaluation is a product with T;
  L-BFGS-B on x with the likelihood (Eq. 19) and the entropy and gradient priors
  (Eq. 13-16). Texels no observed pixel sees are masked and left black.
* reflectance: illumination fixed; Levenberg-Marquardt with reweighted
  residuals (:func:`_reflectance_block`) on (psi, chromaticity variables, the
  light's log scale), its Jacobian by forward-mode AD through the ``dsbrdf``
  plugin, with the GMM and hue priors (Eq. 6, 12) and a penalty on curves
  beyond the library's range.

Start: random chromaticity (seeded) and, for each of :func:`reflectance_starts`
(psi = 0 and the GMM means), a constant map at the image's level refined by a
short grey illumination block and a short reflectance block; the best starts
the rounds. Rounds of the two blocks continue until the negative log posterior
changes by less than ``tol`` (relative). Two passes: grey illumination first
(one map shared by the channels: the grey-world assumption), then colour from
that start, unless the image is grey (:mod:`mi_dsbrdf.inference.scene_needs` decides).
A point or directional light (:func:`recover_light`) replaces the illumination
block by Powell's method on its direction and intensity.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
from scipy.optimize import minimize

from mi_dsbrdf.model.fitting import chroma_logits, softmax_chroma
from mi_dsbrdf.inference.forward import TexelSum, apply_transport, transport_adjoint, unseen_texels
from mi_dsbrdf.inference.likelihood import LOG_OFFSET, log_likelihood_terms
from mi_dsbrdf.model.priors import EntropyPrior, GradientPrior

#: bound of the chromaticity variables (softmax logits): c >= ~e^-6 / 2
CHROMA_LIMIT = 6.0
#: log radiance of masked (unseen) texels: black, and below every bin of the entropy prior
BLACK = -30.0
#: how far (natural log) a recovered kappa/gamma control value may leave the range the
#: library's materials span at that control point before CURVE_PENALTY applies
CURVE_MARGIN = 1.0
#: weight of the squared excess (log units) of a control value beyond that range
CURVE_PENALTY = 100.0
#: largest change of the light's log scale in one Levenberg-Marquardt step
MAX_SCALE_STEP = 5.0
#: observed pixels at which the prior weights of :class:`Config` apply as given (a
#: 64-pixel sphere covers 3000, the renders they were tuned on): the likelihood sums over pixels,
#: so the weights are scaled by (observed pixels / PRIOR_PIXELS) to keep the balance
#: of likelihood and priors the same at any image resolution
PRIOR_PIXELS = 3000


@dataclasses.dataclass
class Config:
    map_size: tuple = (16, 32)
    max_rounds: int = 6
    tol: float = 1e-3
    seed: int = 0
    block_iters: int = 40
    #: L-BFGS iterations of the illumination block (each is a product with T: cheap)
    illumination_iters: int = 60
    #: Laplacian scale b of Eq. 19 in log units: the expected |log error| of a pixel
    likelihood_scale: float = 0.05
    #: prior weights (lambda of Eq. 18) at PRIOR_PIXELS observed pixels, chosen on
    #: held-out materials and a held-out probe by ``benchmarks/tune_priors.py``
    #: (``benchmarks/results/prior_weights.json``): the GMM prior strong (it resolves
    #: the split of gloss between material and light), the others at 1 (a strong hue
    #: prior traps the chromaticity from its random start)
    w_gmm: float = 300.0
    w_hue: float = 1.0
    w_entropy: float = 1.0
    w_gradient: float = 1.0
    #: pixel-texel pairs the reflectance block differentiates per step: it fits
    #: 16 variables, so an evenly spread subset of the pixels does (Jacobian cost
    #: is proportional to pixels x texels)
    reflectance_pairs: int = 500_000


@dataclasses.dataclass
class State:
    psi: np.ndarray
    logits: np.ndarray          # (R, 2) chromaticity variables
    log_map: np.ndarray         # (H, W, 3)

    @property
    def chromaticity(self):
        return softmax_chroma(self.logits)


class Posterior:
    """-log p(psi, c, L | I) for one scene and image, with gradients by block."""

    def __init__(self, texels: TexelSum, observed, mask, model, config: Config, point=None):
        import drjit as dr
        import mitsuba as mi
        self.ts, self.model, self.cfg = texels, model, config
        obs = np.asarray(observed, dtype=np.float64).reshape(-1, observed.shape[-1])[texels.pixels, :3]
        keep = np.asarray(mask, bool).reshape(-1)[texels.pixels]
        self.observed, self.keep = obs, keep
        self.offset = LOG_OFFSET * float(np.mean(obs[keep]))    # > 0 even when most pixels are unlit
        self.scale = config.likelihood_scale                  # Eq. 19: sum |log error| / b
        k, R = model.basis.n_bases, model.basis.n_lobes
        props = {"type": "dsbrdf", "model": model.source, "psi": " ".join(["0"] * k)}
        self.bsdf = mi.load_dict(props)
        texels.bsdf = self.bsdf
        self.params = mi.traverse(self.bsdf)
        self.k, self.R = k, R
        # the reflectance block's pixels: every n-th usable pixel, its likelihood
        # scaled up to stand for all of them
        usable = np.nonzero(keep)[0]
        n_sub = max(64, config.reflectance_pairs // max(texels.n_texels, 1))
        if usable.size > n_sub:
            rows = usable[np.linspace(0, usable.size - 1, n_sub).round().astype(np.int64)]
            self.refl = _View(texels.subset(rows), obs[rows], np.ones(rows.size, bool), usable.size / rows.size)
        else:
            self.refl = _View(texels, obs, keep, 1.0)
        self.point = point          # (centre, distance) of a point light, None: directional
        # the range of the library's kappa/gamma control values: a recovered curve
        # stays within CURVE_MARGIN of it (one image sees few theta_d; without this
        # box the unobserved, grazing end of a curve can run off to kappa = e^85)
        ctrl = np.stack([model.basis.control_values(model.library_material(n).psi) for n in model.library])
        self.curve_range = (ctrl.min(axis=0).reshape(-1) - CURVE_MARGIN, ctrl.max(axis=0).reshape(-1) + CURVE_MARGIN)
        c0 = model.basis.control_values(np.zeros(k)).reshape(-1)      # control values are linear in psi
        self.curve_map = (c0, np.stack([model.basis.control_values(e).reshape(-1) - c0 for e in np.eye(k)], axis=1))
        # prior weights scaled to the number of observed pixels (see PRIOR_PIXELS)
        n = keep.sum() / PRIOR_PIXELS
        self.w = {t: n * getattr(config, "w_" + t) for t in ("gmm", "hue", "entropy", "gradient")}
        self.entropy = EntropyPrior(self.w["entropy"])
        self.gradient = GradientPrior(self.w["gradient"])
        self._dr = dr

    def aim(self, theta, phi):
        """Light the pixels from the direction (theta, phi) (seen from the object):
        a directional light, or the point light at ``distance`` from ``centre``
        that way (its intensity then stands for W/sr, not irradiance)."""
        d = direction_from_angles(theta, phi)
        for ts in {id(self.ts): self.ts, id(self.refl.ts): self.refl.ts}.values():
            if self.point is None:
                ts.set_directions(d[None], [1.0])
            else:
                ts.set_point(np.asarray(self.point[0]) + self.point[1] * d)

    # --- reflectance -------------------------------------------------------------
    def set_reflectance(self, psi, logits):
        import mitsuba as mi
        self.params["psi"] = mi.Float(np.asarray(psi, dtype=np.float32))
        self.params["chromaticity"] = mi.Float(softmax_chroma(logits).reshape(-1).astype(np.float32))
        self.params.update()

    def prior_terms(self, psi, logits, log_map=None, bins=None) -> dict:
        """The weighted prior terms one by one, for the log: the curve penalty, GMM
        (Eq. 6), hue (Eq. 12) and, given a map, entropy (Eq. 13-15) and gradient (Eq. 16)."""
        terms = {"curve_penalty": self.curve_penalty(psi)[0]}
        if self.model.gmm is not None:
            terms["gmm"] = self.w["gmm"] * self.model.gmm.nll(psi)
        if self.model.hue_prior is not None:
            terms["hue"] = self.w["hue"] * self.model.hue_prior.nll(softmax_chroma(logits))
        if log_map is not None:
            terms["entropy"] = self.entropy(log_map, bins)[0]
            terms["gradient"] = self.gradient(log_map)[0]
        return {k: float(v) for k, v in terms.items()}

    def curve_penalty(self, psi):
        """(value, gradient, Gauss-Newton Hessian) of CURVE_PENALTY * sum of the squared
        excess of the kappa/gamma control values beyond ``curve_range``: ψ far from
        the data can put a curve's unobserved (grazing) end at kappa = e^85."""
        c0, A = self.curve_map
        c = c0 + A @ psi
        excess = np.maximum(c - self.curve_range[1], 0) - np.maximum(self.curve_range[0] - c, 0)
        active = (excess != 0).astype(np.float64)
        return (CURVE_PENALTY * float(excess @ excess), 2 * CURVE_PENALTY * A.T @ excess,
                2 * CURVE_PENALTY * (A.T * active) @ A)

    def reflectance_prior(self, psi, logits) -> float:
        """GMM (Eq. 6) + hue (Eq. 12) prior terms, and the curve penalty."""
        return sum(self.prior_terms(psi, logits).values())

    def reflectance_terms(self, psi, logits, L):
        """(value, likelihood) of likelihood + GMM + hue priors at fixed L, the
        likelihood over the reflectance block's pixels (``self.refl``), no
        gradients: the block takes its derivatives from
        :meth:`TexelSum.reflectance_jacobian`."""
        self.set_reflectance(psi, logits)
        v = self.refl
        image = v.ts.render(L)
        lik, _ = log_likelihood_terms(image[:, None, :], v.observed[:, None, :], v.keep[:, None],
                                      self.offset, self.scale)
        lik *= v.weight
        return lik + self.reflectance_prior(psi, logits), lik

    # --- illumination ------------------------------------------------------------
    def map_likelihood(self, log_map, T, seen, grad=True):
        """(value, d/d log_map or None) of the likelihood (Eq. 19) of the map at fixed reflectance."""
        L = np.where(seen[..., None], np.exp(log_map), 0.0)
        image = apply_transport(T, L)
        lik, g_img = log_likelihood_terms(image[:, None, :], self.observed[:, None, :], self.keep[:, None],
                                          self.offset, self.scale)
        if not grad:
            return lik, None
        return lik, transport_adjoint(T, g_img[:, 0, :]).reshape(log_map.shape) * L

    def illumination_terms(self, log_map, T, seen, bins):
        """(value, d/d log_map, likelihood) of likelihood + entropy + gradient priors at fixed reflectance."""
        lik, g = self.map_likelihood(log_map, T, seen)
        e, ge = self.entropy(log_map, bins)
        s, gs = self.gradient(log_map)
        return lik + e + s, g + ge + gs, lik


@dataclasses.dataclass
class _View:
    """Pixels a block works on: their TexelSum, observed values, usable flags and
    the factor that makes their likelihood stand for all usable pixels."""
    ts: TexelSum
    observed: np.ndarray
    keep: np.ndarray
    weight: float


def recover(texels: TexelSum, observed, mask, model, config=Config(), colour=True, progress=None):
    """MAP estimate for an envmap scene. Returns (State, log rows).

    Each round: the illumination block (L-BFGS-B on the log map, transport T
    from the current reflectance), then the reflectance block (Levenberg-
    Marquardt on psi, chromaticity and the map's overall log scale, over
    ``post.refl``'s pixels), then the full negative log posterior for the log.
    It starts from the best of :func:`reflectance_starts`, each given a short
    grey illumination block and a short reflectance block.
    """
    cfg = config
    post = Posterior(texels, observed, mask, model, cfg)
    H, W = cfg.map_size
    rng = np.random.default_rng(cfg.seed)
    state = State(np.zeros(post.k), chroma_logits(rng.dirichlet(np.full(3, 5.0), post.R)),
                  np.zeros((H, W, 3)))
    rows = []
    t0 = time.perf_counter()
    # start: each of reflectance_starts with the constant map that matches the
    # image's median level, refined by one grey illumination block and one
    # reflectance block; the best posterior starts the alternation
    best = None
    for p0 in reflectance_starts(model):
        post.set_reflectance(p0, state.logits)
        T = texels.transport()
        seen = ~unseen_texels(T).reshape(H, W)
        level = np.median(post.observed[post.keep]) / max(np.median(T.sum(axis=2).T[post.keep]), 1e-12)
        x = np.full((H, W, 3), np.log(max(level, 1e-12)))
        bins = post.entropy.bins_for(x)
        x = _illumination_block(post, x, T, seen, bins, True, max(cfg.illumination_iters // 2, 5))
        L = np.where(seen[..., None], np.exp(x), 0.0).reshape(-1, 3)
        psi, logits, Ls = _reflectance_block(post, p0, state.logits, L, max(cfg.block_iters // 2, 5),
                                             fit_scale=True)
        value = post.reflectance_terms(psi, logits, Ls)[0]
        rows.append({"pass": "start", "round": len(rows), "neg_log_posterior": value,
                     "seconds": time.perf_counter() - t0})
        if progress:
            progress(rows[-1])
        if best is None or value < best[0]:
            best = (value, psi, logits, x + float(np.log(Ls.max() / L.max())))
    _, state.psi, state.logits, state.log_map = best
    post.set_reflectance(state.psi, state.logits)
    T = texels.transport()
    passes = ["grey", "colour"] if colour else ["grey"]
    for pass_name in passes:
        prev = None
        for rnd in range(cfg.max_rounds):
            # illumination block (T from the current reflectance)
            seen = ~unseen_texels(T).reshape(H, W)
            bins = post.entropy.bins_for(np.where(seen[..., None], state.log_map, state.log_map[seen].min()))
            state.log_map = _illumination_block(post, state.log_map, T, seen, bins, pass_name == "grey",
                                                cfg.illumination_iters)
            L = np.where(seen[..., None], np.exp(state.log_map), 0.0).reshape(-1, 3)
            # reflectance block, with the map's overall scale
            psi, logits, Ls = _reflectance_block(post, state.psi, state.logits, L, cfg.block_iters,
                                                 fit_scale=True)
            state.psi, state.logits = psi, logits
            state.log_map = state.log_map + float(np.log(Ls.max() / L.max()))
            # the full posterior at the new point; its T serves the next illumination block
            post.set_reflectance(state.psi, state.logits)
            T = texels.transport()
            lik = post.map_likelihood(state.log_map, T, seen, grad=False)[0]
            terms = post.prior_terms(state.psi, state.logits, state.log_map, bins)
            total = lik + sum(terms.values())
            rows.append({"pass": pass_name, "round": rnd, "neg_log_posterior": total, "likelihood": lik, **terms,
                         "seconds": time.perf_counter() - t0, "unseen_texels": int((~seen).sum())})
            if progress:
                progress(rows[-1])
            if prev is not None and abs(prev - total) <= cfg.tol * abs(prev):
                break
            prev = total
    state.log_map = np.where(seen[..., None], state.log_map, BLACK)
    return state, rows


def _illumination_block(post, log_map, T, seen, bins, grey, iters):
    H, W, _ = log_map.shape
    idx = seen.reshape(-1)

    def unpack(v):
        x = np.full((H * W, 3), BLACK)
        if grey:
            x[idx] = v[:, None]
        else:
            x[idx] = v.reshape(-1, 3)
        return x.reshape(H, W, 3)

    def fun(v):
        x = unpack(v)
        val, g, _ = post.illumination_terms(x, T, seen, bins)
        g = g.reshape(-1, 3)[idx]
        return val, (g.sum(axis=1) if grey else g.reshape(-1))

    x0 = log_map.reshape(-1, 3)[idx]
    v0 = x0.mean(axis=1) if grey else x0.reshape(-1)
    res = minimize(fun, v0, jac=True, method="L-BFGS-B", options={"maxiter": iters, "maxfun": 2 * iters},
                   bounds=[(BLACK + 1, 30.0)] * v0.size)
    return unpack(res.x)


def _reflectance_block(post, psi, logits, L, iters, fit_scale=False, direction=None):
    """Levenberg-Marquardt with iteratively reweighted residuals (IRLS).

    The Laplacian likelihood sum rho(d_i)/b is minimised as a sequence of
    weighted least-squares problems, weights w_i = rho'(d_i)/(d_i b), with the
    image Jacobian from forward-mode AD; the GMM prior enters as the quadratic
    of its most responsible component, the hue prior through its gradient.
    Each step is accepted only if the full negative log posterior decreases.
    With ``fit_scale`` the light's overall log scale s is a variable too (the
    image is proportional to e^s): brightness then moves freely between the
    light and the material, which the two otherwise trade off only slowly.
    With ``direction`` = (theta, phi) of a directional light, the direction is
    refined jointly too (its two Jacobian columns by central differences), which
    resolves the light/reflectance coupling that alternation resolves slowly.
    Returns (psi, logits), or with ``fit_scale`` (psi, logits, scaled L), or with
    ``direction`` also (theta, phi).
    """
    from mi_dsbrdf.inference.likelihood import KINK
    k, R = psi.size, logits.shape[0]
    dr = post._dr
    view = post.refl

    ang = None if direction is None else np.array(direction, dtype=np.float64)

    def aim(a):
        if a is not None:
            post.aim(*a)

    def total(p, z, sc=0.0, a=None):
        aim(a)
        return post.reflectance_terms(p, z, L * np.exp(sc))[0]

    sc = 0.0
    cur = total(psi, logits)
    lam = 1.0
    for _ in range(iters):
        post.set_reflectance(psi, logits)
        dr.enable_grad(post.params["psi"])
        dr.enable_grad(post.params["chromaticity"])
        post.params.update()
        aim(ang)
        image, J = view.ts.reflectance_jacobian(L * np.exp(sc), post.params, ["psi", "chromaticity"])
        dr.disable_grad(post.params["psi"])
        dr.disable_grad(post.params["chromaticity"])
        c = softmax_chroma(logits)
        dc_dz = c[:, :, None] * (np.eye(3)[None, :, :2] - c[:, None, :2])           # (R, 3, 2)
        Jz = np.einsum("pcrl,rlk->pcrk", J[:, :, k:].reshape(J.shape[0], 3, R, 3), dc_dz).reshape(J.shape[0], 3, -1)
        extra = [image[:, :, None]] if fit_scale else []
        if ang is not None:
            for j in range(2):
                e = np.zeros(2)
                e[j] = 1e-3
                hi, lo = [(aim(ang + sgn * e), view.ts.render(L * np.exp(sc)))[1] for sgn in (1, -1)]
                extra.append(((hi - lo) / 2e-3)[:, :, None])
            aim(ang)
        J = np.concatenate([J[:, :, :k], Jz] + extra, axis=2)
        J = J[view.keep].reshape(-1, J.shape[2])
        mp = np.maximum(image[view.keep], 0) + post.offset
        d = (np.log(mp) - np.log(np.maximum(view.observed[view.keep], 0) + post.offset)).reshape(-1)
        Jd = J / mp.reshape(-1, 1)
        # IRLS weights of the Laplacian, graduated: while most residuals are large the
        # kink is widened to their median (least squares far away, L1 near the optimum)
        kink = max(KINK, float(np.median(np.abs(d))))
        w = view.weight / (np.sqrt(d * d + kink * kink) * post.scale)
        H = Jd.T @ (Jd * w[:, None])
        g = Jd.T @ (w * d)
        if post.model.gmm is not None:
            gm = post.model.gmm
            lc, _ = gm._component_logs(psi[None])
            prec = gm._prec[int(np.argmax(lc[0]))]
            H[:k, :k] += post.w["gmm"] * prec
            g[:k] += post.w["gmm"] * gm.grad(psi)
        _, g_curve, h_curve = post.curve_penalty(psi)
        H[:k, :k] += h_curve
        g[:k] += g_curve
        if post.model.hue_prior is not None:
            gh = post.w["hue"] * post.model.hue_prior.grad(c)
            g[k:k + 2 * R] += np.einsum("rl,rlk->rk", gh, dc_dz).reshape(-1)
        improved = False
        for _ in range(10):
            step = -np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-9), g)
            # chromaticity variables stay within +-CHROMA_LIMIT: a saturated softmax has no gradient left
            p_new = psi + step[:k]
            z_new = np.clip(logits + step[k:k + 2 * R].reshape(R, 2), -CHROMA_LIMIT, CHROMA_LIMIT)
            sc_new = sc + (np.clip(step[k + 2 * R], -MAX_SCALE_STEP, MAX_SCALE_STEP) if fit_scale else 0.0)
            ang_new = None if ang is None else ang + step[-2:]
            new = total(p_new, z_new, sc_new, ang_new)
            if np.isfinite(new) and new < cur:
                improved = True
                break
            lam *= 10.0
        if not improved:
            break
        gain = (cur - new) / max(abs(cur), 1e-300)
        psi, logits, sc, ang, cur = p_new, z_new, sc_new, ang_new, new
        lam = max(lam / 10.0, 1e-9)
        if gain < 1e-6:
            break
    post.set_reflectance(psi, logits)
    aim(ang)
    out = (psi, logits, L * np.exp(sc)) if fit_scale else (psi, logits)
    return out + (tuple(ang),) if ang is not None else out


# --- point / directional light (paper §5: Powell's method) -----------------------------

def direction_from_angles(theta, phi) -> np.ndarray:
    """World direction (y up, the lat-long convention of :mod:`mi_dsbrdf.inference.latlong`)."""
    st = np.sin(theta)
    return np.array([st * np.sin(phi), np.cos(theta), -st * np.cos(phi)])


def angles_from_direction(d):
    d = np.asarray(d, dtype=np.float64) / np.linalg.norm(d)
    return float(np.arccos(np.clip(d[1], -1, 1))), float(np.arctan2(d[0], -d[2]))


def _light_likelihood(post, theta, phi, log_intensity):
    post.aim(theta, phi)
    image = post.ts.render(np.full((1, 3), np.exp(log_intensity)))
    lik, _ = log_likelihood_terms(image[:, None, :], post.observed[:, None, :], post.keep[:, None],
                                  post.offset, post.scale)
    return lik


def _light_block(post, theta, phi, log_intensity, maxfev=400):
    """Powell's method on (theta, phi, log intensity) with the reflectance fixed."""
    res = minimize(lambda v: _light_likelihood(post, *v), [theta, phi, log_intensity], method="Powell",
                   options={"xtol": 1e-4, "ftol": 1e-7, "maxfev": maxfev})
    return tuple(res.x)


def _candidate_lights(post, n=64, keep=6):
    """The ``keep`` best of ``n`` directions spread over the sphere (Fibonacci
    lattice), each with the intensity that matches the image's median level under
    the current reflectance: [(likelihood, theta, phi, log intensity), ...]."""
    found = []
    i = np.arange(n) + 0.5
    thetas, phis = np.arccos(1 - 2 * i / n), np.pi * (1 + 5 ** 0.5) * i
    for th, ph in zip(thetas, phis):
        log_i = _matched_log_intensity(post, th, ph)
        if log_i is None:
            continue
        found.append((_light_likelihood(post, th, ph, log_i), th, ph % (2 * np.pi), log_i))
    if not found:
        raise ValueError("no light direction lights the observed pixels")
    return sorted(found)[:keep]


def _matched_log_intensity(post, theta, phi):
    """Log intensity that matches the median observed level of the pixels a light
    from (theta, phi) reaches under the current reflectance; None if it reaches none."""
    post.aim(theta, phi)
    lit = post.ts.render(np.ones((1, 3))).mean(axis=1)[post.keep]
    if not np.any(lit > 0):
        return None
    ratio = np.median(post.observed[post.keep].mean(axis=1)[lit > 0]) / np.median(lit[lit > 0])
    return float(np.log(ratio)) if ratio > 0 else None


def _highlight_lights(post):
    """Directions the brightest observed pixel suggests: its normal (the light of a
    matte object) and the mirror of the view direction about it (the light of a
    glossy one), as [(theta, phi), ...]."""
    lum = np.where(post.keep, post.observed.mean(axis=1), -np.inf)
    i = int(np.argmax(lum))
    si = post.ts.si
    n = np.array(si.n)[:, i].astype(np.float64)
    v = np.array(si.to_world(si.wi))[:, i].astype(np.float64)
    mirror = 2 * (n @ v) * n - v
    return [angles_from_direction(n), angles_from_direction(mirror)]


def reflectance_starts(model) -> list:
    """Starting coefficients: psi = 0 (the mean material) and the mean of every
    GMM component (diffuse, shiny, in between): the likelihood has local minima,
    and these starts cover the clusters of real materials."""
    starts = [np.zeros(model.basis.n_bases)]
    if model.gmm is not None:
        starts += [m.copy() for m in model.gmm.means]
    return starts


def recover_light(texels: TexelSum, observed, mask, model, config=Config(), progress=None,
                  known_light=None, point=None):
    """MAP estimate for a directional or point light: returns (result dict, log rows).

    The light is a direction (unit vector from the object towards the light)
    and a non-negative intensity (RGB-equal: the colour is the material's):
    irradiance for a directional light; for a point light (``point`` =
    (centre, distance): the light sits at ``distance`` from ``centre`` in that
    direction, the distance taken from the scene) the radiant intensity in W/sr.
    A wrong reflectance biases the light and the other way round,
    so the search starts globally: the best few of 64 directions under the mean
    material each get a short reflectance fit and a Powell refinement, and the
    best posterior among them starts the alternation (Powell's method for the
    light with the reflectance fixed, the reflectance block with the light
    fixed) until the posterior stops improving. ``known_light`` =
    (direction, intensity) skips the light search and block.
    """
    cfg = config
    post = Posterior(texels, observed, mask, model, cfg, point=point)
    rng = np.random.default_rng(cfg.seed)
    logits = chroma_logits(rng.dirichlet(np.full(3, 5.0), post.R))
    psi = np.zeros(post.k)
    t0 = time.perf_counter()
    rows = []
    if known_light is None:
        post.set_reflectance(psi, logits)
        best = None
        cands = [c[1:] for c in _candidate_lights(post)]
        for th, ph in _highlight_lights(post):
            li = _matched_log_intensity(post, th, ph)
            if li is not None:
                cands.append((th, ph, li))
        for th, ph, li in cands:
            post.aim(th, ph)
            p, z, Ls = _reflectance_block(post, psi, logits, np.full((1, 3), np.exp(li)),
                                          max(cfg.block_iters // 4, 5), fit_scale=True)
            li = float(np.log(Ls[0, 0]))
            post.set_reflectance(p, z)
            th, ph, li = _light_block(post, th, ph, li, maxfev=100)     # a coarse search: refined later
            post.aim(th, ph)
            value = post.reflectance_terms(p, z, np.full((1, 3), np.exp(li)))[0]
            rows.append({"pass": "light search", "round": len(rows), "neg_log_posterior": value,
                         "seconds": time.perf_counter() - t0})
            if progress:
                progress(rows[-1])
            if best is None or value < best[0]:
                best = (value, p, z, th, ph, li)
        _, psi, logits, theta, phi, log_i = best
    else:
        theta, phi = angles_from_direction(known_light[0])
        log_i = float(np.log(known_light[1]))
    prev = None
    for rnd in range(cfg.max_rounds):
        post.set_reflectance(psi, logits)
        if known_light is None:
            theta, phi, log_i = _light_block(post, theta, phi, log_i)
        L = np.full((1, 3), np.exp(log_i))
        post.aim(theta, phi)
        if rnd == 0:
            # the reflectance block from every start (psi found so far, the mean, GMM means)
            cands = [_reflectance_block(post, p0, logits, L, cfg.block_iters, fit_scale=known_light is None)
                     for p0 in [psi] + reflectance_starts(model)]
            cands = [c if len(c) == 3 else (c[0], c[1], L) for c in cands]
            psi, logits, L = min(cands, key=lambda c: post.reflectance_terms(c[0], c[1], c[2])[0])
        elif known_light is None:
            psi, logits, L, (theta, phi) = _reflectance_block(post, psi, logits, L, cfg.block_iters, fit_scale=True,
                                                              direction=(theta, phi))
        else:
            psi, logits = _reflectance_block(post, psi, logits, L, cfg.block_iters)
        log_i = float(np.log(L[0, 0]))
        total, lik = post.reflectance_terms(psi, logits, L)
        rows.append({"pass": "light", "round": rnd, "neg_log_posterior": total, "likelihood": lik,
                     **post.prior_terms(psi, logits), "seconds": time.perf_counter() - t0})
        if progress:
            progress(rows[-1])
        if prev is not None and abs(prev - total) <= cfg.tol * abs(prev):
            break
        prev = total
    result = {"psi": psi, "chromaticity": softmax_chroma(logits), "direction": direction_from_angles(theta, phi),
              "intensity": float(np.exp(log_i))}
    if point is not None:
        result["position"] = np.asarray(point[0]) + point[1] * result["direction"]
    return result, rows
