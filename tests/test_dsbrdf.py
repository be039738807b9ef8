"""The DSBRDF model: float64 reference vs Dr.Jit kernel, stability, files, bad input."""
import json

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_dsbrdf import Material, MaterialError, load_material
from mi_dsbrdf.brdf.angles import from_half_diff, half_diff, log_cos_h
from mi_dsbrdf.brdf.dsbrdf import lobe_rgb

GAMMAS = [1.0, 10.0, 100.0, 1e3, 1e4]
KAPPAS = [1e-6, 1e-3, 0.1, 1.0, 10.0, 40.0, 60.0]
TH = np.array([0.0, 1e-4, 1e-3, 0.01, 0.05, 0.2, 0.5, 1.0, 1.4, np.pi / 2])
TD = np.array([0.0, 0.3, 0.8, 1.2, 1.5, np.pi / 2])
CHROMA = [0.5, 0.3, 0.2]


def constant_material(kappa, gamma):
    return Material.from_curves([[kappa] * 6], [[gamma] * 6], [CHROMA])


def varying_material():
    return Material.from_curves([[0.5, 0.6, 0.8, 1.0, 2.0, 4.0], [20, 25, 30, 40, 50, 60]],
                                [[1.0, 1.2, 1.5, 2.0, 2.5, 3.0], [5e3, 4e3, 2e3, 1e3, 500, 300]],
                                [[0.6, 0.3, 0.1], [1 / 3, 1 / 3, 1 / 3]])


def rel_err(got, ref):
    """|got - ref| relative to |ref|, floored at 1e-7 of the material's peak."""
    floor = 1e-7 * np.max(np.abs(ref)) + 1e-30
    return np.abs(got - ref) / (np.abs(ref) + floor)


def kernel_dr(material, log_cos_h, theta_d, grad=False):
    """Evaluate lobe_rgb in Dr.Jit (float32) with the material's parameters."""
    lk, lg, ch = (mi.Float(a.reshape(-1)) for a in (material.log_kappa, material.log_gamma, material.chromaticity))
    if grad:
        for p in (lk, lg, ch):
            dr.enable_grad(p)
    R = material.n_lobes
    def sc(a, w):
        return [[dr.gather(mi.Float, a, r * w + j) for j in range(w)] for r in range(R)]
    rgb = lobe_rgb(mi.Float(log_cos_h), mi.Float(theta_d), sc(lk, 6), sc(lg, 6), sc(ch, 3), material.knots)
    return rgb, (lk, lg, ch)


def test_reference_matches_formula():
    m = constant_material(3.0, 50.0)
    th, td = np.array([0.0, 0.1, 0.4]), np.array([0.2, 0.5, 1.0])
    expected = np.outer(np.expm1(3.0 * np.cos(th) ** 50), CHROMA)
    np.testing.assert_allclose(m.eval(th, td), expected, rtol=1e-12)
    kappa, gamma = varying_material().curves(np.array([0.0, np.pi / 2]))
    np.testing.assert_allclose(kappa[:, 1], [20, 60], rtol=1e-12)   # clamped spline hits end controls
    np.testing.assert_allclose(gamma[:, 1], [5e3, 300], rtol=1e-12)


def test_kernel_matches_float64_reference_on_extreme_grid():
    """gamma 1..1e4, kappa 1e-6..60, theta_h and theta_d including 0 and 90 deg."""
    T, D = (a.reshape(-1) for a in np.meshgrid(TH, TD, indexing="ij"))
    worst = {}
    for kappa in KAPPAS:
        for gamma in GAMMAS:
            m = constant_material(kappa, gamma)
            ref = m.eval(T, D)
            rgb, _ = kernel_dr(m, log_cos_h(np.cos(T), np.sin(T) ** 2).astype(np.float32), D.astype(np.float32))
            got = np.stack([np.array(c) for c in rgb], -1)
            assert np.all(np.isfinite(got))
            worst[(kappa, gamma)] = rel_err(got, ref).max()
    print("\nlargest relative error of the float32 kernel (rows kappa, cols gamma):")
    for kappa in KAPPAS:
        print("  kappa %-6g " % kappa + " ".join("%9.2e" % worst[(kappa, g)] for g in GAMMAS))
    # Error grows with the conditioning of exp at large kappa (one float32 ulp of
    # log kappa becomes kappa ulps of the value): bounded, never blowing up.
    assert max(worst.values()) < 2e-4
    # tiny kappa: exp(x) - 1 would be off by ~5 % at kappa = 1e-6; the stable expm1 is not
    assert max(worst[(k, g)] for k in KAPPAS[:3] for g in GAMMAS) < 5e-5


def plugin_for(material, tmp_path):
    path = tmp_path / "m.json"
    material.save(path)
    return mi.load_dict({"type": "dsbrdf", "filename": str(path)})


def directions(th, td, seed=0):
    """float32 direction pairs for angle grids (random phi_h, phi_d), and the
    float64 angles of the rounded directions."""
    rng = np.random.default_rng(seed)
    T, D = (a.reshape(-1) for a in np.meshgrid(th, td, indexing="ij"))
    wi, wo = from_half_diff(T, D, rng.uniform(0, np.pi, T.size), phi_h=0.7)
    wi32, wo32 = (np.stack(v).astype(np.float32) for v in (wi, wo))
    wi64, wo64 = (v.astype(np.float64) / np.linalg.norm(v.astype(np.float64), axis=0) for v in (wi32, wo32))
    t_h, _, t_d, _ = half_diff(tuple(wi64), tuple(wo64))
    return wi32, wo32, t_h, t_d, wo64[2]


def bsdf_query(bsdf, wi32, wo32):
    si = dr.zeros(mi.SurfaceInteraction3f, wi32.shape[1])
    si.wi = mi.Vector3f(*wi32)
    wo = mi.Vector3f(*wo32)
    ctx = mi.BSDFContext()
    return si, wo, ctx


def test_plugin_eval_matches_reference_with_horizon(tmp_path):
    for m in (varying_material(), constant_material(60.0, 1e4), constant_material(1e-6, 1.0)):
        bsdf = plugin_for(m, tmp_path)
        wi32, wo32, t_h, t_d, cos_o = directions(np.linspace(0, np.pi / 2, 40), np.linspace(0, np.pi / 2, 40))
        si, wo, ctx = bsdf_query(bsdf, wi32, wo32)
        got = np.array(bsdf.eval(ctx, si, wo)).T
        above = (wi32[2] > 0) & (wo32[2] > 0)
        assert np.all(got[~above] == 0), "directions below the horizon must give 0"
        ref = m.eval(t_h, t_d) * cos_o[:, None]
        err = rel_err(got[above], ref[above]).max()
        print("plugin eval, max kappa %g: largest relative error %.2e" % (np.exp(m.log_kappa.max()), err))
        assert err < 5e-4


@pytest.mark.parametrize("kappa,gamma", [(1e-6, 1.0), (60.0, 1e4), (40.0, 1.0), (1e-3, 1e4)])
def test_gradients_sample_and_pdf_finite_at_extremes(kappa, gamma, tmp_path):
    m = constant_material(kappa, gamma)
    T, D = (a.reshape(-1) for a in np.meshgrid(TH, TD, indexing="ij"))
    rgb, params = kernel_dr(m, log_cos_h(np.cos(T), np.sin(T) ** 2).astype(np.float32), D.astype(np.float32), grad=True)
    dr.backward(dr.sum(rgb[0] + rgb[1] + rgb[2]))
    for p in params:
        assert np.all(np.isfinite(np.array(dr.grad(p))))
    bsdf = plugin_for(m, tmp_path)
    n = 4096
    rng = np.random.default_rng(1)
    ct = np.concatenate([[1.0, 1e-4, 1e-7], rng.uniform(0, 1, n - 3)])
    phi = rng.uniform(0, 2 * np.pi, n)
    st = np.sqrt(1 - ct ** 2)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(st * np.cos(phi), st * np.sin(phi), ct)
    bs, w = bsdf.sample(mi.BSDFContext(), si, mi.Float(rng.uniform(0, 1, n)),
                        mi.Point2f(rng.uniform(0, 1, n), rng.uniform(0, 1, n)))
    assert np.all(np.isfinite(np.array(w))) and np.all(np.isfinite(np.array(bs.pdf)))
    pdf = bsdf.pdf(mi.BSDFContext(), si, bs.wo)
    assert np.all(np.isfinite(np.array(pdf)))


@pytest.mark.parametrize("gamma", [1e4, 1e6])
def test_direction_gradients_finite_at_the_sharpest_peak(gamma):
    """kappa at its bound, gamma up to its bound: d eval / d theta_o stays finite from
    the mirror direction out to 3 deg (e^kappa * kappa * gamma overflows float32 in
    a naive chain rule: NaN within 0.26 deg at kappa 85), and the
    derivative is exact where the formula's conditioning allows."""
    bsdf = mi.load_dict({"type": "dsbrdf", "lobes": 1, "kappa_0": "60", "gamma_0": "%g" % gamma,
                         "chromaticity_0": "0.25 0.25 0.5"})
    ti = np.radians(30.0)
    offsets = np.radians(np.concatenate([[0.0], np.logspace(-4, 0.5, 40)]))
    theta = mi.Float(ti + offsets)
    dr.enable_grad(theta)
    si = dr.zeros(mi.SurfaceInteraction3f, offsets.size)
    si.wi = mi.Vector3f(float(np.sin(ti)), 0.0, float(np.cos(ti)))
    value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(-dr.sin(theta), 0, dr.cos(theta)))
    dr.backward(value.z)
    grad, v = np.array(dr.grad(theta)), np.array(value.z)
    assert np.all(np.isfinite(grad)) and np.all(np.isfinite(v)) and v[0] > 1e24
    # against the float64 derivative of Eq. 4 * cos theta_o by central differences, where the lobe is not flat
    m = Material.from_curves([[60.0] * 6], [[gamma] * 6], [[0.25, 0.25, 0.5]])

    def f(t):
        return m.eval(np.abs(t - ti) / 2, np.full(t.shape, (t + ti) / 2))[:, 2] * np.cos(t)
    t, h = ti + offsets, 1e-7
    ref = (f(t + h) - f(t - h)) / (2 * h)
    slope = np.abs(ref) > 1e-3 * np.abs(ref).max()
    np.testing.assert_allclose(grad[slope], ref[slope], rtol=0.05)


def test_material_beyond_the_kappa_bound_is_refused():
    with pytest.raises(MaterialError, match="kappa must be <= 60"):
        Material.from_curves([[80.0] * 6], [[1e4] * 6], [[0.25, 0.25, 0.5]])


def test_material_file_round_trip_and_load_material(tmp_path):
    m = varying_material()
    p = tmp_path / "material.json"
    m.save(p)
    m2 = load_material(str(p))
    th, td = np.random.default_rng(0).uniform(0, np.pi / 2, (2, 100))
    np.testing.assert_array_equal(m.eval(th, td), m2.eval(th, td))
    assert m2.eval(th, td).shape == (100, 3) and m2.eval(th, td).dtype == np.float64


@pytest.mark.parametrize("mutate,message", [
    (lambda d: d.update(log_kappa=[[0.0] * 5]), "log_kappa must have 6 values"),
    (lambda d: d.update(chromaticity=[[0.5, 0.5, 0.5], [0.2, 0.3, 0.5]]), "must sum to 1"),
    (lambda d: d.update(chromaticity=[[1.2, -0.2, 0.0], [0.2, 0.3, 0.5]]), "non-negative"),
    (lambda d: d.update(log_kappa=[[5.0] * 6, [0.0] * 6]), "kappa must be <= 60"),
    (lambda d: d.update(log_gamma=[[0.0] * 6]), "one row per lobe"),
    (lambda d: d.pop("log_gamma"), "lacks log_gamma"),
    (lambda d: d.update(format="something-else"), "not a mi-dsbrdf material"),
    (lambda d: d.update(knots=[0, 1, 2]), "knot vector"),
    (lambda d: d.update(log_kappa=[[1e6] * 6, [0.0] * 6]), r"kappa must be <= 60.*exp\(1e\+06\)"),
    (lambda d: d.update(log_gamma=[[1e6] * 6, [0.0] * 6]), r"gamma control values .*exp\(1e\+06\)"),
    (lambda d: d.update(lobes=7), '"lobes": 7 but .* have 2 rows'),
    (lambda d: d.update(lobes="2"), '"lobes": \'2\''),
])
def test_malformed_material_file(mutate, message, tmp_path):
    d = varying_material().to_dict()
    mutate(d)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    with pytest.raises(MaterialError, match=message):
        load_material(str(p))


def test_unreadable_and_unknown_materials(tmp_path):
    p = tmp_path / "broken.json"
    p.write_text("{ not json")
    with pytest.raises(MaterialError, match="unreadable"):
        load_material(str(p))
    with pytest.raises(MaterialError, match="does not exist"):
        load_material(str(tmp_path / "missing.json"))
    with pytest.raises(MaterialError, match="unknown material 'no-such-material'"):
        load_material("no-such-material")


@pytest.mark.parametrize("props,message", [
    ({"kappa_0": "-1", "gamma_0": "2"}, "kappa control values must be > 0"),
    ({"kappa_0": "1", "gamma_0": "-3"}, "gamma control values must be > 0"),
    ({"kappa_0": "1 2 3", "gamma_0": "2"}, "kappa_0 needs 6 values"),
    ({"kappa_0": "1", "gamma_0": "2", "chromaticity_0": "0.5 0.5 0.5"}, "must sum to 1"),
    ({"lobes": 2, "kappa_0": "1", "gamma_0": "2"}, "missing parameter kappa_1"),
    ({"kappa_0": "1", "gamma_0": "2", "kappa_3": "1", "gamma_3": "1"}, "1 to 3 lobes"),
    ({"material": "no-such-material"}, "unknown material"),
    ({"filename": "x.json", "kappa_0": "1"}, "give one of"),
])
def test_bad_xml_parameters(props, message):
    with pytest.raises(RuntimeError, match=message):
        mi.load_dict(dict(type="dsbrdf", **props))


def test_explicit_xml_equals_file(tmp_path):
    m = varying_material()
    p = tmp_path / "m.json"
    m.save(p)
    explicit = {"type": "dsbrdf", "lobes": 2}
    for r in range(2):
        explicit["kappa_%d" % r] = " ".join("%.17g" % v for v in np.exp(m.log_kappa[r]))
        explicit["gamma_%d" % r] = " ".join("%.17g" % v for v in np.exp(m.log_gamma[r]))
        explicit["chromaticity_%d" % r] = " ".join("%.17g" % v for v in m.chromaticity[r])
    a = mi.load_dict(explicit)
    b = mi.load_dict({"type": "dsbrdf", "filename": str(p)})
    wi32, wo32, *_ = directions(np.linspace(0, 1.2, 10), np.linspace(0, 1.2, 10))
    si, wo, ctx = bsdf_query(a, wi32, wo32)
    np.testing.assert_allclose(np.array(a.eval(ctx, si, wo)), np.array(b.eval(ctx, si, wo)), rtol=1e-6)


@pytest.mark.parametrize("kappa, gamma", [(1e-3, 2e-4), (0.5, 1.0), (2.5, 12.0), (30.0, 7.0), (59.0, 1e4)])
def test_lobe_energy_matches_quadrature_and_finite_differences(kappa, gamma):
    """log int_0^1 (exp[kappa u^gamma] - 1) du by its series, against scipy's quadrature
    (in u = e^-t, which spreads a sharp lobe), and its derivatives."""
    from scipy.integrate import quad
    from mi_dsbrdf.brdf.dsbrdf import log_lobe_energy
    lk, lg = np.log(kappa), np.log(gamma)
    le, d_k, d_g = log_lobe_energy(lk, lg)
    top = np.expm1(kappa)                     # u = e^-t; split where the lobe has decayed
    f = lambda t: np.expm1(kappa * np.exp(-gamma * t)) / top * np.exp(-t)  # noqa: E731
    edges = sorted({0.0, min(40 / gamma, 50.0), 50.0, np.inf})
    q = sum(quad(f, a, b, limit=400, epsabs=0, epsrel=1e-11)[0] for a, b in zip(edges[:-1], edges[1:]))
    assert le == pytest.approx(np.log(q) + np.log(top), rel=1e-8, abs=1e-8)
    h = 1e-5
    assert d_k == pytest.approx((log_lobe_energy(lk + h, lg)[0] - log_lobe_energy(lk - h, lg)[0]) / (2 * h), rel=1e-5)
    assert d_g == pytest.approx((log_lobe_energy(lk, lg + h)[0] - log_lobe_energy(lk, lg - h)[0]) / (2 * h),
                                rel=1e-4, abs=1e-9)


def test_lobe_energy_sees_the_clamp_and_orders_lobes_by_brightness():
    from mi_dsbrdf.brdf.dsbrdf import LOG_KAPPA_MAX, log_lobe_energy
    le, d_k, _ = log_lobe_energy(np.array([LOG_KAPPA_MAX + 1.0]), np.array([2.0]))
    assert le[0] == pytest.approx(log_lobe_energy(LOG_KAPPA_MAX, 2.0)[0]) and d_k[0] == 0   # clamped as a material is
    # same peak (kappa), broader lobe: brighter; same width, higher peak: brighter
    assert log_lobe_energy(np.log(10.0), np.log(5.0))[0] > log_lobe_energy(np.log(10.0), np.log(500.0))[0]
    assert log_lobe_energy(np.log(12.0), np.log(50.0))[0] > log_lobe_energy(np.log(10.0), np.log(50.0))[0]
