"""The material's posterior (Laplace approximation at the MAP): its covariance,
samples and bands, their files, and the band's score against a truth."""
import numpy as np
import pytest

from mi_dsbrdf.brdf.dsbrdf import LOBE_PARAMETERS, Material
from mi_dsbrdf.config import Config
from mi_dsbrdf.errors import MaterialError
from mi_dsbrdf.evaluation.metrics import band_scores
from mi_dsbrdf.inference import recover_envmap
from mi_dsbrdf.inference.objective import Posterior
from mi_dsbrdf.inference.uncertainty import laplace
from mi_dsbrdf.model import model_file as model_data
from mi_dsbrdf.model.samples import samples_from_function
from test_inference import sky_case

TRUTH = "gold-metallic-paint"


@pytest.fixture(scope="module")
def recovered():
    model, ts, img = sky_case()
    cfg = Config(map_size=(8, 16), max_rounds=2, block_iters=6, illumination_iters=20)
    return model, ts, img, cfg, recover_envmap(ts, img, ts.mask, model, cfg)


def test_a_recovered_material_carries_a_covariance_of_its_parameters(recovered, tmp_path):
    """The recovery's material has a covariance factor over (log kappa, log gamma
    controls, chromaticity variables); the covariance is symmetric positive
    semi-definite; a higher temperature scales it; material.json keeps it."""
    model, _, _, _, res = recovered
    m = res.material
    R = m.n_lobes
    # a column per variable, and one per other mode the search found (here the second route's answer)
    assert len(res.laplace.alternatives) == 1 and res.laplace.alternatives[0][1] >= 0
    assert m.covariance_factor.shape == (LOBE_PARAMETERS * R, model.basis.n_bases + 2 * R + 1)
    C = m.covariance
    assert np.allclose(C, C.T) and np.linalg.eigvalsh(C).min() > -1e-12 * np.abs(C).max()
    assert np.allclose(res.laplace.factor(4.0), 2.0 * res.laplace.factor(1.0))
    m.save(tmp_path / "m.json")
    back = Material.load(tmp_path / "m.json")
    assert np.allclose(back.covariance_factor, m.covariance_factor)
    assert np.allclose(back.with_observed(None).covariance, C)        # carried through with_observed


def test_samples_and_bands_come_from_the_covariance(recovered):
    """Samples scatter around the MAP as the covariance says (parameters' sample
    covariance), the 90 % band holds the MAP's values and widens with the
    temperature; a material without a covariance says so in one line."""
    _, _, _, _, res = recovered
    assert np.allclose(res.material.covariance_factor, res.laplace.factor())     # the shipped temperature
    m = res.material.with_covariance(res.laplace.factor(1.0))        # untempered: narrow, no clamp reached
    draws = m.sample(400, seed=1)
    theta = np.array([d.parameters() for d in draws])
    free = np.diag(m.covariance) > 1e-10
    sd = np.sqrt(np.diag(m.covariance))[free]
    # unclamped parameters: sample mean within 4 standard errors, spread within 20 %
    assert np.all(np.abs(theta.mean(axis=0)[free] - m.parameters()[free]) < 4 * sd / np.sqrt(400) + 1e-9)
    assert np.allclose(theta.std(axis=0)[free], sd, rtol=0.2)
    th, td = np.meshgrid(np.linspace(0, 1.5, 12), np.linspace(0, 1.5, 12))
    lo, hi = m.band(th.ravel(), td.ravel())
    value = m.eval(th.ravel(), td.ravel())
    assert lo.shape == hi.shape == value.shape == (144, 3)
    assert np.mean((lo <= value) & (value <= hi)) > 0.95
    wide = m.with_covariance(res.laplace.factor(100.0)).band(th.ravel(), td.ravel())
    assert np.median(np.log(wide[1] / wide[0])) > 3 * np.median(np.log(hi / lo))
    with pytest.raises(MaterialError, match="no posterior covariance"):
        model_data.shipped_model().library_material(TRUTH).band(th.ravel(), td.ravel())
    with pytest.raises(MaterialError, match="covariance_factor"):
        Material.from_dict({**m.to_dict(), "covariance_factor": [[1.0, 2.0]]})


def test_the_likelihood_hessian_is_the_fisher_information_of_plain_differences(recovered):
    """Plain reference: the Laplace likelihood Hessian equals weight J J^T / (b b_hat),
    J the central differences of the log pixel values in psi, b_hat the mean |residual|."""
    model, ts, img, cfg, res = recovered
    post = Posterior(ts.with_map_size((8, 16)), img, ts.mask, model, cfg)
    L = res.illumination.reshape(-1, 3) / 1.0
    lp = laplace(post, res.psi, np.log(res.chromaticity[:, :2] / res.chromaticity[:, 2:]), L, fit_chroma=False)
    view = post.refl

    def log_image(psi):
        image = view.lobes.render(post.material(psi, np.log(res.chromaticity[:, :2] / res.chromaticity[:, 2:])), L)
        return np.log(np.maximum(image[view.keep], 0) + post.offset).T.reshape(-1)
    k, h = res.psi.size, 3e-3       # the render is float32: a step well above its rounding
    J = np.stack([(log_image(res.psi + h * e) - log_image(res.psi - h * e)) / (2 * h) for e in np.eye(k)])
    d = log_image(res.psi) - np.log(np.maximum(view.observed[view.keep], 0) + post.offset).T.reshape(-1)
    fisher = view.weight * (J @ J.T) / (post.scale * max(np.mean(np.abs(d)), post.kink))
    assert np.linalg.norm(lp.likelihood - fisher) < 0.01 * np.linalg.norm(fisher)


def test_band_scores_count_the_cells_whose_truth_lies_in_the_band():
    """A narrow band holds a truth equal to the material's values in every cell and
    a truth twice as bright in none; the scale divides the truth."""
    m = model_data.shipped_model().library_material(TRUTH)
    narrow = m.with_covariance(np.full((LOBE_PARAMETERS * m.n_lobes, 1), 1e-4))
    samples = samples_from_function(lambda th, td, pd: m.eval(th, td))
    where = samples.theta_d < 0.5
    exact = band_scores(narrow, samples, where, 1.0, n=64)
    assert exact["coverage_observed"] == exact["coverage_unobserved"] == 1.0
    assert 0 < exact["width_observed"] < 0.01
    assert band_scores(narrow, samples, where, 0.5, n=64)["coverage_observed"] == 0.0
    assert np.isnan(band_scores(narrow, samples, np.ones(len(samples), bool), 1.0, n=8)["coverage_unobserved"])


def test_the_maps_spread_is_the_diagonal_of_plain_differences(recovered):
    """Plain reference: the map's spread is (likelihood + gradient prior)^-1/2 on the
    diagonal, the likelihood's part from central differences of the log pixels in
    each texel's log value, the gradient prior's from its majoriser's quadratic of a
    unit bump; texels no pixel sees are 0."""
    from mi_dsbrdf.inference.uncertainty import MAP_TEMPERATURE, illumination_spread
    from mi_dsbrdf.inference.transport import apply_transport
    model, ts, img, cfg, res = recovered
    post = Posterior(ts.with_map_size((8, 16)), img, ts.mask, model, cfg)
    log_map = np.log(np.where(res.seen[..., None], res.illumination / res.illumination[res.seen].mean(), 1.0))
    T = post.transport(res.psi, np.log(res.chromaticity[:, :2] / res.chromaticity[:, 2:]))
    spread = illumination_spread(post, log_map, T, res.seen, temperature=1.0)
    assert np.allclose(illumination_spread(post, log_map, T, res.seen), spread * np.sqrt(MAP_TEMPERATURE))
    assert spread.shape == log_map.shape and np.all(spread[~res.seen] == 0) and np.all(spread[res.seen] > 0)
    keep = post.keep

    def log_image(x):
        image = apply_transport(T, np.where(res.seen[..., None], np.exp(x), 0.0).reshape(-1, 3))
        return np.log(np.maximum(image[keep], 0) + post.offset)
    d = log_image(log_map) - np.log(np.maximum(post.observed[keep], 0) + post.offset)
    b_hat = max(np.mean(np.abs(d)), post.kink)
    c = post.gradient.majoriser_weights(log_map)
    for i, j in np.argwhere(res.seen)[::7]:
        e = np.zeros_like(log_map)
        e[i, j, 0] = 1e-3
        J = (log_image(log_map + e)[:, 0] - log_image(log_map - e)[:, 0]) / 2e-3
        dphi, dth, _ = post.gradient.differences(e / 1e-3)
        prior = (c * (dphi[..., 0] ** 2 + dth[..., 0] ** 2)).sum()
        plain = 1 / np.sqrt(post.weight * (J @ J) / (post.scale * b_hat) + prior)
        assert spread[i, j, 0] == pytest.approx(plain, rel=0.02)


def test_material_png_draws_the_brdf_with_its_band_where_the_material_has_one(recovered, tmp_path):
    """brdf_slices draws a recovered material (band, unseen directions) and a library
    material (neither) alike, as a PNG of the figure's size."""
    import mitsuba as mi

    from mi_dsbrdf.app.outputs import brdf_slices
    from mi_dsbrdf.brdf.observed import DirectionWeights
    res = recovered[-1]
    seen = DirectionWeights(np.pad(np.ones((10, 45)), ((0, 35), (0, 0))))      # theta_h below ~14 deg seen
    for name, m in (("recovered", res.material.with_observed(seen)),
                    ("library", model_data.shipped_model().library_material(TRUTH))):
        brdf_slices(m, tmp_path / ("%s.png" % name))
        assert np.array(mi.Bitmap(str(tmp_path / ("%s.png" % name)))).shape[:2] == (320, 900)


def test_other_modes_widen_the_covariance_by_their_tempered_weight(recovered):
    """A mode found besides the MAP adds its offset's outer product, weighted by the
    tempered posterior exp(-energy / t) / (1 + exp(-energy / t)), to the covariance:
    nothing at a high energy, half of it at zero."""
    import dataclasses
    lp = recovered[-1].laplace
    delta = np.linspace(-1.0, 1.0, lp.to_parameters.shape[0])
    base = lp.factor(10.0) @ lp.factor(10.0).T
    for energy, weight in ((0.0, 0.5), (10.0, np.exp(-1) / (1 + np.exp(-1))), (1e4, 0.0)):
        F = dataclasses.replace(lp, alternatives=((delta, energy),)).factor(10.0)
        assert np.allclose(F @ F.T, base + weight * np.outer(delta, delta))


def test_a_highlight_the_posterior_doubts_is_flagged_and_a_sure_one_is_not():
    """highlight_doubt is the share of posterior samples without a highlight, for a
    MAP with one; Recovery.flags names it in one line from HIGHLIGHT_DOUBT on."""
    from mi_dsbrdf.brdf.dsbrdf import NO_HIGHLIGHT
    from mi_dsbrdf.inference.result import Recovery
    from mi_dsbrdf.inference.uncertainty import HIGHLIGHT_DOUBT, highlight_doubt
    model = model_data.shipped_model()
    gold = model.library_material(TRUTH)
    n = LOBE_PARAMETERS * gold.n_lobes

    def recovery(material):
        return Recovery(material=material, psi=np.zeros(1), chromaticity=material.chromaticity,
                        highlight_doubt=highlight_doubt(material))

    sure = recovery(gold.with_covariance(np.sqrt(1e-3) * np.eye(n)))
    assert sure.highlight_doubt == 0.0 and sure.flags == []
    # lobes of gamma 1: a highlight just above NO_HIGHLIGHT, which a wide posterior doubts
    weak = Material(gold.log_kappa, np.zeros_like(gold.log_gamma), gold.chromaticity)
    assert NO_HIGHLIGHT <= weak.highlight_ratio() < 2 * NO_HIGHLIGHT
    doubted = recovery(weak.with_covariance(np.sqrt(0.3) * np.eye(n)))
    assert HIGHLIGHT_DOUBT <= doubted.highlight_doubt < 1.0
    assert len(doubted.flags) == 1 and "highlight" in doubted.flags[0] and "\n" not in doubted.flags[0]
    assert "on the object's upper left" in doubted.highlight_flag("upper left")
    assert recovery(weak.with_covariance(np.sqrt(1e-4) * np.eye(n))).flags == []
    # a MAP without a highlight has nothing to doubt
    fabric = model.library_material("white-fabric")
    assert recovery(fabric.with_covariance(np.sqrt(0.3) * np.eye(n))).highlight_doubt is None
    with pytest.raises(MaterialError):
        weak.no_highlight_probability()


def test_the_place_a_highlight_lights_is_named_from_the_objects_centre():
    """brightest_place: the centroid of the pixels within half of the largest excess,
    from the centre of the used pixels' bounding box: "centre" near it, else the
    nearest of eight directions (row 0 at the top)."""
    from mi_dsbrdf.app.recover import brightest_place
    yy, xx = np.mgrid[0:30, 0:30]
    used = (yy - 15) ** 2 + (xx - 15) ** 2 < 12 ** 2

    def spot(y, x):
        return np.exp(-((yy - y) ** 2 + (xx - x) ** 2) / 4.0)
    assert brightest_place(spot(8, 8), used) == "upper left"
    assert brightest_place(spot(24, 15), used) == "lower"
    assert brightest_place(spot(15, 25), used) == "right"
    assert brightest_place(spot(22, 22), used) == "lower right"
    assert brightest_place(spot(16, 14), used) == "centre"
    assert brightest_place(spot(15, 15) - spot(8, 8), used) == "centre"     # only the excess counts
