"""Posterior terms: likelihood (Eq. 19) and illumination priors (Eq. 13-16), against finite differences."""
import numpy as np
import pytest

from mi_dsbrdf.inference.likelihood import log_likelihood_terms
from mi_dsbrdf.inference.illumination_priors import EntropyPrior, GradientPrior, LightColourPrior


def finite_differences(f, x, h=1e-6):
    g = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        e = np.zeros_like(x)
        e[idx] = h
        g[idx] = (f(x + e) - f(x - e)) / (2 * h)
    return g


def test_likelihood_gradient_and_stability():
    rng = np.random.default_rng(0)
    obs = rng.uniform(0, 2, (4, 5, 3))
    obs[0, 0] = 0.0                                   # black pixel
    model = obs * rng.uniform(0.5, 1.5, obs.shape)
    model[0, 0] = 0.01                                # the model lights the black pixel a little
    mask = np.ones((4, 5), bool)
    mask[3, 4] = False                                # e.g. saturated
    v, g = log_likelihood_terms(model, obs, mask, offset=1e-3)
    fd = finite_differences(lambda m: log_likelihood_terms(m, obs, mask, 1e-3)[0], model)
    np.testing.assert_allclose(g, fd, rtol=1e-4, atol=1e-6)
    # a wider kink than likelihood.KINK: its own gradient, and a smaller cost (residuals below it count less)
    vk, gk = log_likelihood_terms(model, obs, mask, 1e-3, kink=0.05)
    fd = finite_differences(lambda m: log_likelihood_terms(m, obs, mask, 1e-3, kink=0.05)[0], model)
    np.testing.assert_allclose(gk, fd, rtol=1e-4, atol=1e-6)
    assert vk < v
    assert np.all(g[3, 4] == 0)
    assert log_likelihood_terms(model, obs, mask, 1e-3, grad=False) == (v, None)
    # exact fit: zero, and the kink is smooth (finite, zero gradient)
    v0, g0 = log_likelihood_terms(obs, obs, mask, 1e-3)
    assert v0 == 0.0 and np.all(g0 == 0)
    # zero, negative and huge model values stay finite
    for m in (np.zeros_like(obs), -obs, obs * 1e30):
        v, g = log_likelihood_terms(m, obs, mask, 1e-3)
        assert np.isfinite(v) and np.all(np.isfinite(g))


def lat_long_map(seed=1, H=8, W=16):
    rng = np.random.default_rng(seed)
    return rng.normal(0, 1, (H, W, 3))


@pytest.mark.parametrize("prior", [EntropyPrior(weight=2.0, n_bins=32), GradientPrior(weight=0.5, alpha=0.6),
                                   LightColourPrior(weight=2.0, temperature_sigma=0.3, tint_sigma=0.05)])
def test_illumination_prior_gradients_match_finite_differences(prior):
    x = lat_long_map()
    if isinstance(prior, EntropyPrior):
        bins = prior.bins_for(x)
        f = lambda y: prior(y, bins)[0]  # noqa: E731
        v, g = prior(x, bins)
    else:
        f = lambda y: prior(y)[0]  # noqa: E731
        v, g = prior(x)
    assert np.isfinite(v) and np.all(np.isfinite(g))
    np.testing.assert_allclose(g, finite_differences(f, x), rtol=1e-4, atol=1e-8)


def test_gradient_prior_is_lat_long_aware():
    p = GradientPrior()
    x = lat_long_map()
    # rotating the map about the vertical axis (a wrap in phi) changes nothing
    assert p(np.roll(x, 5, axis=1))[0] == pytest.approx(p(x)[0], rel=1e-12)
    # a constant map costs the floor eps^alpha, whatever its level
    assert p(np.full_like(x, 3.0))[0] == pytest.approx(p.eps ** p.alpha)
    # the same step costs less in a polar row (small solid angle) than at the equator
    pole, eq = np.zeros_like(x), np.zeros_like(x)
    pole[0, :8] = 1.0
    eq[4, :8] = 1.0
    assert p(pole)[0] < p(eq)[0]
    with pytest.raises(ValueError, match="alpha"):
        GradientPrior(alpha=1.5)


def test_entropy_prior_prefers_peaky_illumination_and_ignores_scale():
    e = EntropyPrior()
    rng = np.random.default_rng(2)
    spread = rng.uniform(-3, 3, (16, 32, 1)).repeat(3, axis=2)          # log radiance spread out
    peaky = np.zeros((16, 32, 3))
    peaky[2:4, 5:7] = 6.0                                               # sky + a sun
    assert e(peaky)[0] < e(spread)[0]
    assert e(spread + 2.0)[0] == pytest.approx(e(spread)[0], rel=1e-9)  # log-scale invariance


def test_entropy_bins_span_the_seen_texels_only():
    """Unseen texels (at BLACK, log -30) do not stretch the entropy prior's bins:
    they span the seen texels' range as if the unseen ones held the darkest seen value."""
    from mi_dsbrdf.inference.envmap import BLACK
    prior = EntropyPrior()
    x = np.log(np.linspace(0.5, 4.0, 8 * 16)).reshape(8, 16, 1).repeat(3, axis=2)     # grey
    seen = np.ones((8, 16), bool)
    seen[:2] = False
    with_black = np.where(seen[..., None], x, BLACK)
    centres, sigma = prior.bins_for(with_black, seen)
    lum = x[..., 0][seen]
    np.testing.assert_allclose(sigma, (lum.max() - lum.min()) / prior.n_bins * prior.bandwidth_bins)
    np.testing.assert_allclose(centres[[0, -1]], [lum.min() - 3 * sigma, lum.max() + 3 * sigma])
    assert prior.bins_for(with_black)[0][0] < BLACK        # what the black texels would have done


def test_light_colour_prior_prices_the_maps_mean_colour_only():
    p = LightColourPrior(weight=1.0, temperature_sigma=0.26, tint_sigma=0.05)
    rng = np.random.default_rng(3)
    grey = rng.normal(0, 2, (8, 16, 1)).repeat(3, axis=2)            # any white map, any structure
    assert p(grey)[0] == pytest.approx(0.0, abs=1e-12)
    orange = grey + np.log([1.0, 0.66, 0.47])                        # grace's colour, about
    assert p(orange)[0] > 1.0
    assert p(orange + 4.0)[0] == pytest.approx(p(orange)[0], rel=1e-9)     # the light's level is free
    # a white map whose sun is orange: only the mean counts, and the mean is a little orange
    sun = grey.copy()
    sun[2, 3] += np.log([1.0, 0.66, 0.47]) + 5.0
    assert 0 < p(sun)[0] < p(orange)[0]
    # a green light as far from white as the orange one is far less probable
    green = grey + np.log([0.66, 1.0, 0.66])
    assert np.linalg.norm(p.colour(green) - p.colour(grey)) < np.linalg.norm(p.colour(orange) - p.colour(grey))
    assert p(green)[0] > 5 * p(orange)[0]
    with pytest.raises(ValueError, match="tint_sigma"):
        LightColourPrior(tint_sigma=0.0)


def test_posterior_illumination_terms_gradient_matches_finite_differences():
    """The sum the illumination block minimises (likelihood + entropy + gradient
    priors through the transport), against central differences in log L."""
    from mi_dsbrdf.config import Config
    from mi_dsbrdf.inference.objective import Posterior
    from mi_dsbrdf.model import model_file as model_data
    from mi_dsbrdf.inference.forward import TexelSum
    from mi_dsbrdf.inference.latlong import procedural_sky
    from mi_dsbrdf.app.scenes import sphere_scene
    s = sphere_scene({"type": "dsbrdf", "material": "gold-metallic-paint"}, 12)
    ts = TexelSum(s, s.shapes()[0], (4, 8))
    observed = np.zeros((144, 3))
    observed[ts.pixels] = ts.render(procedural_sky(4, 8))
    post = Posterior(ts, observed.reshape(12, 12, 3), ts.mask, model_data.shipped_model(),
                               Config(map_size=(4, 8)))
    T = post.transport(np.zeros(post.k), np.zeros((post.R, 2)))
    seen = ~post.view.unseen.reshape(4, 8)
    x = np.log(procedural_sky(4, 8).astype(np.float64)) + np.random.default_rng(1).normal(0, 0.3, (4, 8, 3))
    bins = post.entropy.bins_for(x)
    v, g, lik = post.illumination_terms(x, T, seen, bins)
    assert np.isfinite(v) and v > lik > 0
    for idx in [(1, 2, 0), (2, 5, 2), (0, 0, 1)]:
        if not seen[idx[:2]]:
            continue
        # a step of 1e-3 in log L: at 1e-4 the float32 transport's rounding (about 1e-7 of
        # each pixel) is 0.25 % of the difference with some BLAS builds
        e = np.zeros_like(x)
        e[idx] = 1e-3
        fd = (post.illumination_terms(x + e, T, seen, bins)[0]
              - post.illumination_terms(x - e, T, seen, bins)[0]) / 2e-3
        np.testing.assert_allclose(g[idx], fd, rtol=2e-3, atol=1e-3)


def test_prior_weights_follow_the_observed_pixel_count():
    """The likelihood sums over pixels, so the priors are weighted by observed pixels /
    PRIOR_PIXELS: half the pixels masked out halves every prior term, and the Config
    weights apply as given at PRIOR_PIXELS."""
    from mi_dsbrdf.config import PRIOR_PIXELS, Config
    from mi_dsbrdf.inference.objective import Posterior
    from mi_dsbrdf.model import model_file as model_data
    from mi_dsbrdf.inference.forward import TexelSum
    from mi_dsbrdf.app.scenes import sphere_scene
    s = sphere_scene({"type": "dsbrdf", "material": "gold-metallic-paint"}, 12)
    ts = TexelSum(s, s.shapes()[0], (4, 8))
    observed = np.ones((12, 12, 3))
    model = model_data.shipped_model()
    cfg = Config(map_size=(4, 8), w_gmm=2.0, w_entropy=3.0)
    half = ts.mask.copy()
    half[:6] = False
    full_post = Posterior(ts, observed, ts.mask, model, cfg)
    half_post = Posterior(ts, observed, half, model, cfg)
    n_full, n_half = int(ts.mask.sum()), int(half.sum())
    assert 0 < n_half < n_full
    assert full_post.w["gmm"] == pytest.approx(2.0 * n_full / PRIOR_PIXELS)
    assert full_post.w["entropy"] == pytest.approx(3.0 * n_full / PRIOR_PIXELS)
    psi = np.linspace(-1, 1, model.basis.n_bases)
    logits = np.zeros((model.basis.n_lobes, 2))
    x = np.random.default_rng(0).normal(0, 1, (4, 8, 3))
    a = full_post.prior_terms(psi, logits, x, full_post.entropy.bins_for(x))
    b = half_post.prior_terms(psi, logits, x, half_post.entropy.bins_for(x))
    for term in ("gmm", "hue", "entropy", "gradient"):
        assert b[term] == pytest.approx(a[term] * n_half / n_full, rel=1e-9)


def test_the_chromaticity_start_is_the_image_colour():
    from mi_dsbrdf.brdf.chromaticity import softmax_chroma
    from mi_dsbrdf.inference.reflectance import START_GREY_MIX, image_chroma_logits
    keep = np.ones(50, bool)
    grey = softmax_chroma(image_chroma_logits(np.full((50, 3), 0.4), keep, 3))
    np.testing.assert_allclose(grey, 1 / 3, atol=1e-9)          # a grey image starts with grey lobes
    img = np.tile([0.6, 0.3, 0.1], (50, 1))
    img[keep.size // 2:] = [9.0, 9.0, 9.0]                       # ignored pixels (a white patch)
    keep[keep.size // 2:] = False
    c = softmax_chroma(image_chroma_logits(img, keep, 3))
    np.testing.assert_allclose(c[0], [0.6, 0.3, 0.1], atol=1e-9)  # the broad lobe: the image's colour
    sharper = (1 - START_GREY_MIX) * np.array([0.6, 0.3, 0.1]) + START_GREY_MIX / 3
    np.testing.assert_allclose(c[1:], np.tile(sharper, (2, 1)), atol=1e-9)



def test_a_large_image_is_fitted_on_an_evenly_spread_subset_standing_for_all_pixels():
    """Config.map_pairs: above it the posterior keeps map_pairs / texels pixels, its
    likelihood (and gradient) scaled to stand for all usable pixels, the priors
    weighted by all of them; below it nothing changes."""
    from mi_dsbrdf.config import Config
    from mi_dsbrdf.inference.objective import Posterior
    from mi_dsbrdf.model import model_file as model_data
    from mi_dsbrdf.inference.forward import TexelSum
    from mi_dsbrdf.inference.latlong import procedural_sky
    from mi_dsbrdf.app.scenes import sphere_scene
    s = sphere_scene({"type": "dsbrdf", "material": "gold-metallic-paint"}, 24)
    ts = TexelSum(s, s.shapes()[0], (4, 8))
    observed = np.zeros((24 * 24, 3))
    observed[ts.pixels] = ts.render(procedural_sky(4, 8))
    observed = observed.reshape(24, 24, 3)
    model = model_data.shipped_model()
    n = int(ts.mask.sum())
    full = Posterior(ts, observed, ts.mask, model, Config(map_size=(4, 8)))
    sub = Posterior(ts, observed, ts.mask, model, Config(map_size=(4, 8), map_pairs=32 * 4 * 8 * 4))
    assert full.view.n_pixels == n and full.weight == 1.0
    assert sub.view.n_pixels == 128 < n and sub.weight == pytest.approx(n / 128)
    assert sub.w == full.w                                        # the priors: all usable pixels
    assert sub.refl.weight == pytest.approx(n / sub.refl.observed.shape[0])
    psi, logits = np.zeros(model.basis.n_bases), np.zeros((model.basis.n_lobes, 2))
    x = np.log(procedural_sky(4, 8).astype(np.float64)) + np.random.default_rng(2).normal(0, 0.5, (4, 8, 3))
    seen = ~full.view.unseen.reshape(4, 8)
    a = full.map_likelihood(x, full.transport(psi, logits), seen)
    b = sub.map_likelihood(x, sub.transport(psi, logits), seen)
    assert b[0] == pytest.approx(a[0], rel=0.1)                   # an estimate of the whole sum
    np.testing.assert_allclose(b[1].sum(axis=(0, 1)), a[1].sum(axis=(0, 1)), rtol=0.15)


def test_gradient_prior_eps_sets_the_stiffness_of_flat_regions():
    """Config.gradient_eps reaches the posterior's gradient prior, and the prior's
    curvature at a flat map grows as eps^(alpha - 2): at eps = 0.01 a texel of a flat
    sky is 10^1.5 times stiffer than at eps = 0.1 (what slows the illumination block)."""
    from mi_dsbrdf.config import Config
    from mi_dsbrdf.inference.objective import Posterior
    from mi_dsbrdf.model import model_file as model_data
    from mi_dsbrdf.inference.forward import TexelSum
    from mi_dsbrdf.app.scenes import sphere_scene
    s = sphere_scene({"type": "dsbrdf"}, 12)
    ts = TexelSum(s, s.shapes()[0], (4, 8))
    post = Posterior(ts, np.ones((12, 12, 3)), ts.mask, model_data.shipped_model(),
                     Config(map_size=(4, 8), gradient_eps=0.1, gradient_alpha=0.3))
    assert (post.gradient.eps, post.gradient.alpha) == (0.1, 0.3)
    x = np.zeros((8, 16, 3))
    e = np.zeros_like(x)
    e[4, 7, 0] = 1e-4

    def curvature(prior):
        return (prior(x + e)[0] - 2 * prior(x)[0] + prior(x - e)[0]) / 1e-8

    stiff, soft = curvature(GradientPrior(eps=0.01)), curvature(GradientPrior(eps=0.1))
    assert stiff / soft == pytest.approx(10 ** 1.5, rel=0.05)


def test_curve_penalty_bounds_each_lobes_energy_and_spares_the_library():
    """The curve penalty: zero at every material of the priors' data (the library's
    FPCA scores, ``model.prior_psi``); positive for a psi whose lobe is brighter
    than any of theirs at a control point (a box per control value alone lets a
    large kappa meet a small gamma); its gradient and Gauss-Newton Hessian against
    central differences there."""
    from mi_dsbrdf.brdf.dsbrdf import log_lobe_energy
    from mi_dsbrdf.config import Config
    from mi_dsbrdf.inference.objective import ENERGY_MARGIN, Posterior
    from mi_dsbrdf.model import model_file as model_data
    from mi_dsbrdf.inference.forward import TexelSum
    from mi_dsbrdf.app.scenes import sphere_scene
    s = sphere_scene({"type": "dsbrdf", "material": "gold-metallic-paint"}, 12)
    ts = TexelSum(s, s.shapes()[0], (4, 8))
    model = model_data.shipped_model()
    post = Posterior(ts, np.ones((12, 12, 3)), ts.mask, model, Config(map_size=(4, 8)))
    for psi in model.prior_psi:
        assert post.curve_penalty(psi)[0] == 0.0
    # the brightest sharpest lobe at grazing theta_d, pushed brighter along psi
    ctrl = np.stack([model.basis.control_values(p) for p in model.prior_psi])
    r, j = post.R - 1, 5
    i = int(np.argmax(log_lobe_energy(ctrl[:, r, 0, j], ctrl[:, r, 1, j])[0]))
    psi0 = model.prior_psi[i]
    A = post.curve_map[1].reshape(post.R, 2, 6, post.k)
    d_k = log_lobe_energy(ctrl[i, r, 0, j], ctrl[i, r, 1, j])[1]
    direction = A[r, 0, j] * d_k                                      # raises that lobe's energy there
    psi = psi0 + (ENERGY_MARGIN + 0.3) / (direction @ direction) * direction
    c = model.basis.control_values(psi)
    assert log_lobe_energy(c[r, 0, j], c[r, 1, j])[0] > post.energy_max[r, j]
    v, g, H = post.curve_penalty(psi)
    assert v > 0
    h = 1e-6
    fd = np.array([(post.curve_penalty(psi + h * e)[0] - post.curve_penalty(psi - h * e)[0]) / (2 * h)
                   for e in np.eye(post.k)])
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6)
    assert np.all(np.linalg.eigvalsh(H) > -1e-9) and g @ direction > 0     # descent lowers the energy
