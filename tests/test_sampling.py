"""Importance sampling: chi-square tests (mitsuba.chi2) and unbiased weights."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

from mi_dsbrdf import Material
from mi_dsbrdf.brdf.measured import MeasuredBRDF
from mi_dsbrdf.brdf.sampling import dsbrdf_weights, mixture_pdf, mixture_sample

GLOSSY = Material.from_curves([[0.5] * 6, [3.0, 3.0, 3.5, 4.0, 6.0, 9.0]],
                              [[1.5] * 6, [400, 350, 300, 250, 200, 150]],
                              [[0.5, 0.3, 0.2], [1 / 3, 1 / 3, 1 / 3]])
# For the chi-square tests: a lobe a few degrees wide. mitsuba.chi2 integrates the
# pdf on its own grid (res=81, 2.2 deg cells), which cannot resolve GLOSSY's 1.6 deg
# lobe; GLOSSY's sampler is checked by brute-force quadrature below instead.
SHINY = Material.from_curves([[0.5] * 6, [2.0, 2.0, 2.5, 3.0, 4.0, 6.0]],
                             [[1.5] * 6, [80, 70, 60, 50, 40, 30]],
                             [[0.5, 0.3, 0.2], [1 / 3, 1 / 3, 1 / 3]])
DIFFUSE = Material.from_curves([[0.3] * 6], [[1.0] * 6], [[0.4, 0.35, 0.25]])
MIRROR = Material.from_curves([[0.2] * 6, [60.0] * 6], [[1.0] * 6, [1e4] * 6],
                              [[1 / 3] * 3, [1 / 3] * 3])


def wi_at(theta_deg):
    t = np.radians(theta_deg)
    return [float(np.sin(t)), 0.0, float(np.cos(t))]


@pytest.mark.parametrize("material", [SHINY, DIFFUSE], ids=["shiny", "diffuse"])
@pytest.mark.parametrize("theta_i", [0.0, 40.0, 75.0])
def test_chi2_dsbrdf(material, theta_i, tmp_path):
    path = tmp_path / "m.json"
    material.save(path)
    sample_func, pdf_func = BSDFAdapter("dsbrdf", '<string name="filename" value="%s"/>' % path,
                                        wi=wi_at(theta_i))
    chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                         sample_dim=3, sample_count=400_000, res=81)
    assert chi2.run(), chi2.messages


def test_chi2_merl_table(tmp_path):
    """The merl plugin's sampler, on a table written as a MERL .binary file."""
    table = MeasuredBRDF.from_function(lambda th, td, pd: SHINY.eval(th, td), name="shiny")
    path = tmp_path / "glossy.binary"
    table.to_binary(path)
    sample_func, pdf_func = BSDFAdapter("merl", '<string name="filename" value="%s"/>' % path, wi=wi_at(30.0))
    chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                         sample_dim=3, sample_count=400_000, res=81)
    assert chi2.run(), chi2.messages


def hemisphere_quadrature(n_theta=400, n_phi=800):
    """float64 midpoint grid over the upper hemisphere: directions (3, N), dw (N,)."""
    t = (np.arange(n_theta) + 0.5) / n_theta * np.pi / 2
    p = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    T, P = np.meshgrid(t, p, indexing="ij")
    dw = np.sin(T) * (np.pi / 2 / n_theta) * (2 * np.pi / n_phi)
    return np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)]).reshape(3, -1), dw.reshape(-1)


@pytest.mark.parametrize("material", [GLOSSY, SHINY, DIFFUSE], ids=["glossy", "shiny", "diffuse"])
def test_sample_weights_are_unbiased_against_quadrature(material, tmp_path):
    """E[f cos / pdf] over sampled directions equals the albedo from brute-force quadrature."""
    path = tmp_path / "m.json"
    material.save(path)
    bsdf = mi.load_dict({"type": "dsbrdf", "filename": str(path)})
    wi = np.array(wi_at(35.0))
    dirs, dw = hemisphere_quadrature()
    from mi_dsbrdf.brdf.angles import half_diff
    th, _, td, _ = half_diff(tuple(np.repeat(wi[:, None], dirs.shape[1], 1)), tuple(dirs))
    albedo_ref = (material.eval(th, td) * (dirs[2] * dw)[:, None]).sum(0)

    n = 2_000_000
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*map(float, wi))
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(7, n)
    _, weight = bsdf.sample(mi.BSDFContext(), si, sampler.next_1d(), sampler.next_2d())
    w = np.array(weight).T
    mean, err = w.mean(0), w.std(0) / np.sqrt(n)
    assert np.all(np.abs(mean - albedo_ref) < 5 * err + 2e-3 * albedo_ref), (mean, albedo_ref, err)


def test_mixture_pdf_integrates_to_one_and_matches_samples_numpy():
    """The numpy evaluation of the shared sampler: pdf normalised, samples valid."""
    kappa, gamma = [np.array([0.5]), np.array([30.0])], [np.array([1.0]), np.array([2000.0])]
    wc, w, n = dsbrdf_weights(kappa, gamma)
    wi = tuple(np.array([v]) for v in wi_at(20.0))
    dirs, dw = hemisphere_quadrature(1200, 1200)
    pdf = mixture_pdf(tuple(np.repeat(c, dirs.shape[1]) for c in wi), tuple(dirs), wc, w, n)
    # the lobe part loses the mass of half vectors that reflect below the horizon
    assert 0.9 < np.sum(pdf * dw) <= 1.0 + 1e-3
    rng = np.random.default_rng(0)
    m = 100_000
    wo, valid = mixture_sample(tuple(np.repeat(c, m) for c in wi), rng.uniform(size=m),
                               rng.uniform(size=m), rng.uniform(size=m), wc, w, n)
    assert valid.mean() > 0.9
    assert np.allclose(np.linalg.norm(np.stack(wo)[:, valid], axis=0), 1.0, atol=1e-9)


def test_mirror_like_sampling_finite_and_concentrated(tmp_path):
    path = tmp_path / "m.json"
    MIRROR.save(path)
    bsdf = mi.load_dict({"type": "dsbrdf", "filename": str(path)})
    n = 100_000
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*wi_at(30.0))
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(1, n)
    bs, weight = bsdf.sample(mi.BSDFContext(), si, sampler.next_1d(), sampler.next_2d())
    w = np.array(weight)
    assert np.all(np.isfinite(w)) and np.all(np.isfinite(np.array(bs.pdf)))
    wo = np.array(bs.wo).T
    mirror = np.array([-np.sin(np.radians(30)), 0, np.cos(np.radians(30))])
    close = (wo @ mirror) > np.cos(np.radians(2.0))
    assert close.mean() > 0.5   # most samples land in the mirror lobe
