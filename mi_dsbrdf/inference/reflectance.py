"""The reflectance block: psi and chromaticity with the light fixed (paper §5).

Levenberg-Marquardt (:func:`mi_dsbrdf.lm.levenberg_marquardt`) with iteratively
reweighted residuals (IRLS): the Laplacian likelihood sum rho(d_i)/b is
minimised as a sequence of weighted least-squares problems, weights
w_i = rho'(d_i)/(d_i b), with the exact image Jacobian of
:meth:`~mi_dsbrdf.inference.lobes.LobeSum.jacobian` (by the spline control
values, chained to psi through the basis).
The GMM prior enters as the quadratic of its most responsible component, the
hue and chromaticity priors through their gradient, the curve penalty exactly. A step is kept only
if the full negative log posterior falls.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from mi_dsbrdf.brdf.chromaticity import chroma_logits, softmax_chroma, softmax_jacobian
from mi_dsbrdf.brdf.dsbrdf import passed_through
from mi_dsbrdf.lm import Damping, levenberg_marquardt

#: bound of the chromaticity variables (softmax logits): c >= ~e^-6 / 2
CHROMA_LIMIT = 6.0
#: largest change of the light's log scale in one step
MAX_SCALE_STEP = 5.0
#: step of the central differences of the image by the light's direction (radians)
DIRECTION_STEP = 1e-3
#: damping of the block's steps: start strongly damped (far starts overshoot)
DAMPING = Damping(initial=1.0, increase=10.0, decrease=10.0, tries=10, minimum=1e-9, floor=1e-9)
#: how far the sharper lobes' starting chromaticity is from the image's towards grey
#: (highlights of dielectrics are the light's colour; of metals, the body's)
START_GREY_MIX = 0.5


@dataclasses.dataclass(frozen=True)
class ReflectanceStep:
    """What a reflectance block returns: psi (k,), chromaticity variables (R, 2),
    the light L (T, 3) times the fitted overall scale (L itself without
    ``fit_scale``) and the light's (theta, phi) (None unless refined)."""
    psi: np.ndarray
    logits: np.ndarray
    L: np.ndarray
    direction: tuple = None


def reflectance_starts(model) -> list:
    """Starting coefficients: psi = 0 (the mean material) and the mean of every
    GMM component (diffuse, shiny, in between): the likelihood has local minima,
    and these starts cover the clusters of real materials."""
    starts = [np.zeros(model.basis.n_bases)]
    if model.gmm is not None:
        starts += [m.copy() for m in model.gmm.means]
    return starts


def image_chroma_logits(observed, keep, n_lobes) -> np.ndarray:
    """(R, 2) chromaticity variables of the start: the broad lobe (lobe 0) takes
    the chromaticity of the usable pixels' mean colour, the sharper lobes that
    colour mixed with grey by START_GREY_MIX. A grey image starts (and, with the
    hue prior, stays) grey (a random start gives a grey object coloured lobes)."""
    mean = np.maximum(np.asarray(observed, dtype=np.float64)[np.asarray(keep, bool)].mean(axis=0), 0.0)
    c = mean / mean.sum() if mean.sum() > 0 else np.full(3, 1 / 3)
    chroma = np.repeat(((1 - START_GREY_MIX) * c + START_GREY_MIX / 3)[None], n_lobes, axis=0)
    chroma[0] = c
    return chroma_logits(chroma, floor=1e-3)


def psi_jacobian(basis, psi, controls_jacobian) -> np.ndarray:
    """(k, 3, P) d radiance / d psi from d radiance / d control values (R, 2, 6, 3, P)
    (:class:`~mi_dsbrdf.inference.lobes.LobeJacobian`): control values = mean +
    bases psi (Eq. 2-3), then clamped, and a clamped one does not move."""
    ctrl = basis.control_values(psi)
    free = np.stack(passed_through(ctrl[:, 0], ctrl[:, 1]), axis=1)             # (R, 2, 6)
    shape = controls_jacobian.shape[3:]
    n = int(np.prod(controls_jacobian.shape[:3]))
    return ((basis.bases * free).reshape(basis.n_bases, n) @ controls_jacobian.reshape(n, -1)).reshape(
        (basis.n_bases,) + shape)


def material_columns(post, jac, psi, logits, fit_chroma) -> list:
    """d radiance / d (psi, chromaticity variables): [(k, 3, P)] + [(2R, 3, P)]
    with ``fit_chroma``, from a :class:`~mi_dsbrdf.inference.lobes.LobeJacobian`."""
    columns = [psi_jacobian(post.model.basis, psi, jac.controls)]
    if fit_chroma:
        R = logits.shape[0]
        dc_dz = softmax_jacobian(softmax_chroma(logits))                         # (R, 3, 2)
        # channel c depends on chromaticity (r, c) only
        columns.append(np.einsum("rcp,rck->rkcp", jac.chromaticity, dc_dz).reshape(2 * R, 3, -1))
    return columns


def log_residuals(post, columns, image) -> tuple:
    """(J / model (n, M), d (M,)) over the reflectance block's usable pixels,
    channel-major: the Jacobian of the log pixel values (n variables) and the
    residuals d = log(model + e) - log(observed + e) of Eq. 19."""
    view = post.refl
    keep = view.keep
    J = columns[:, :, keep].reshape(columns.shape[0], -1)                    # (n, 3 x kept pixels)
    mp = (np.maximum(image[keep], 0) + post.offset).T.reshape(-1)
    d = np.log(mp) - np.log(np.maximum(view.observed[keep], 0) + post.offset).T.reshape(-1)
    return J / mp, d


def prior_derivatives(post, psi, logits, fit_chroma) -> list:
    """[(gradient (n,), Gauss-Newton Hessian (n, n))] of each reflectance prior in
    (psi, chromaticity variables if ``fit_chroma``): the GMM (Eq. 6, its most
    responsible component), the curve penalty, and the hue and chromaticity
    priors (gradient only; :func:`chroma_prior_hessian` gives their curvature).
    Summed in this order by the caller."""
    k, R = psi.size, logits.shape[0]
    n = k + (2 * R if fit_chroma else 0)

    def padded(g, h=None):
        G, H = np.zeros(n), np.zeros((n, n))
        G[:g.size] = g
        if h is not None:
            H[:k, :k] = h
        return G, H
    terms = []
    if post.model.gmm is not None:
        terms.append(padded(*post.gmm_prior(psi)[1:]))
    terms.append(padded(*post.curve_penalty(psi)[1:]))
    if fit_chroma:
        terms.append(padded(np.concatenate([np.zeros(k), chroma_prior_gradient(post, logits)])))
    return terms


def chroma_prior_gradient(post, logits) -> np.ndarray:
    """(2R,) d/d chromaticity variables of the weighted hue and chromaticity priors."""
    c = softmax_chroma(logits)
    return np.einsum("rl,rlk->rk", post.chroma_prior_grad(c), softmax_jacobian(c)).reshape(-1)


def chroma_prior_hessian(post, logits, step=1e-4) -> np.ndarray:
    """(2R, 2R) Hessian of the hue and chromaticity priors in the chromaticity
    variables, by central differences of their gradient (symmetrised)."""
    z = np.asarray(logits, dtype=np.float64).reshape(-1)
    H = np.empty((z.size, z.size))
    for i in range(z.size):
        e = np.zeros(z.size)
        e[i] = step
        H[:, i] = (chroma_prior_gradient(post, (z + e).reshape(-1, 2))
                   - chroma_prior_gradient(post, (z - e).reshape(-1, 2))) / (2 * step)
    return 0.5 * (H + H.T)


def reflectance_block(post, psi, logits, L, iters, fit_scale=False, direction=None,
                      fit_chroma=True) -> ReflectanceStep:
    """Minimise the posterior over psi and the chromaticity variables at fixed light.

    Parameters
    ----------
    post : :class:`~mi_dsbrdf.inference.objective.Posterior` (with ``direction``,
        its light is left at the result)
    psi : (k,) start; logits : (R, 2) start; L : (T, 3) light (map texels or one light)
    iters : at most this many Jacobians
    fit_scale : the light's overall log scale s is a variable too (the image is
        proportional to e^s): brightness then moves freely between the light and
        the material, which the two otherwise trade off only slowly
    direction : (theta, phi) of a directional or point light, refined jointly
        (its two Jacobian columns by central differences), which resolves the
        light/reflectance coupling that alternation resolves slowly
    fit_chroma : the chromaticity variables are variables (else kept at ``logits``)
    """
    k, R = psi.size, logits.shape[0]
    n_chroma = 2 * R if fit_chroma else 0
    n_scale = 1 if fit_scale else 0
    n_dir = 0 if direction is None else 2
    fixed_logits = np.asarray(logits, dtype=np.float64)

    def unpack(x):
        ang = None if direction is None else x[k + n_chroma + n_scale:]
        z = x[k:k + n_chroma].reshape(R, 2) if fit_chroma else fixed_logits
        return x[:k], z, (x[k + n_chroma] if fit_scale else 0.0), ang

    def aim(ang):
        if ang is not None:
            post.aim(*ang)

    def cost(x):
        p, z, sc, ang = unpack(x)
        aim(ang)
        return post.reflectance_terms(p, z, L * np.exp(sc))[0]

    def linearise(x):
        p, z, sc, ang = unpack(x)
        Ls = L * np.exp(sc)
        material = post.material(p, z)
        aim(ang)
        jac = post.refl.lobes.jacobian(material, Ls)
        columns = material_columns(post, jac, p, z, fit_chroma)
        if fit_scale:
            columns.append(jac.image.T[None])
        if ang is not None:
            for j in range(2):
                e = np.zeros(2)
                e[j] = DIRECTION_STEP
                hi, lo = [(aim(ang + sgn * e), post.refl.lobes.render(material, Ls))[1] for sgn in (1, -1)]
                columns.append(((hi - lo) / (2 * DIRECTION_STEP)).T[None])
            aim(ang)
        Jd, d = log_residuals(post, np.concatenate(columns, axis=0), jac.image)
        # IRLS weights of the Laplacian, graduated: while most residuals are large the
        # kink is widened to their median (least squares far away, L1 near the optimum)
        kink = max(post.kink, float(np.median(np.abs(d))))
        w = post.refl.weight / (np.sqrt(d * d + kink * kink) * post.scale)
        H = (Jd * w) @ Jd.T
        g = Jd @ (w * d)
        n = k + n_chroma
        for g_prior, H_prior in prior_derivatives(post, p, z, fit_chroma):
            g[:n] += g_prior
            H[:n, :n] += H_prior
        return g, H

    def propose(x, step):
        # chromaticity variables stay within +-CHROMA_LIMIT: a saturated softmax has no gradient left
        new = x + step
        new[k:k + n_chroma] = np.clip(new[k:k + n_chroma], -CHROMA_LIMIT, CHROMA_LIMIT)
        if fit_scale:
            new[k + n_chroma] = x[k + n_chroma] + np.clip(step[k + n_chroma], -MAX_SCALE_STEP, MAX_SCALE_STEP)
        return new

    x0 = np.concatenate([psi, fixed_logits.reshape(-1) if fit_chroma else [], np.zeros(n_scale),
                         np.zeros(n_dir) if direction is None else np.asarray(direction, dtype=np.float64)])
    # the start's cost at the light the caller set (the same direction when refined)
    res = levenberg_marquardt(linearise, cost, x0, propose=propose, max_iter=iters, damping=DAMPING,
                              cost0=post.reflectance_terms(psi, logits, L)[0])
    p, z, sc, ang = unpack(res.x)
    aim(ang)
    return ReflectanceStep(p, z, L * np.exp(sc), None if ang is None else tuple(ang))
