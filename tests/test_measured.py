"""Measured BRDFs: MERL .binary reader/writer, neural-fit tabulation, merl plugin."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_dsbrdf import MeasuredFileError
from mi_dsbrdf.brdf.angles import from_half_diff, half_diff
from mi_dsbrdf.brdf.measured import (FILE_BYTES, SCALE, SHAPE, MeasuredBRDF, eval_nbrdf, grid_angles,
                                load_nbrdf_weights, nbrdf_names)


def synthetic_table(seed=0):
    """A smooth, anisotropic-in-phi_d table with a few unmeasured cells."""
    th, td, pd = np.meshgrid(*grid_angles(), indexing="ij")
    base = np.exp(-th * 8) * 5 + 0.1 + 0.05 * np.cos(2 * pd) * np.sin(td)
    table = np.stack([base, base * 0.8, base * 0.5], -1)
    measured = np.ones(SHAPE, bool)
    measured[np.random.default_rng(seed).integers(0, 90, 20), 80:, 0] = False
    return MeasuredBRDF(table, measured, name="synthetic")


def test_binary_round_trip_channel_scales_and_unmeasured(tmp_path):
    m = synthetic_table()
    path = tmp_path / "synthetic.binary"
    m.to_binary(path)
    assert path.stat().st_size == FILE_BYTES
    raw = np.fromfile(path, dtype="<f8", offset=12).reshape((3,) + SHAPE)
    np.testing.assert_allclose(raw[1, 5, 6, 7] * SCALE[1], m.table[5, 6, 7, 1], rtol=1e-6)  # channel-major
    assert np.all(raw[:, ~m.measured] < 0)
    back = MeasuredBRDF.from_binary(path)
    np.testing.assert_array_equal(back.measured, m.measured)
    np.testing.assert_allclose(back.table, m.table, rtol=1e-6)
    assert back.name == "synthetic"


@pytest.mark.parametrize("corrupt,message", [
    (lambda b: b[: len(b) // 2], "truncated"),
    (lambda b: b[:8], "truncated"),
    (lambda b: b + b"extra", "trailing data"),
    (lambda b: np.array([90, 90, 90], "<i4").tobytes() + b[12:], "dimensions"),
])
def test_malformed_binary(corrupt, message, tmp_path):
    good = tmp_path / "good.binary"
    synthetic_table().to_binary(good)
    bad = tmp_path / "bad.binary"
    bad.write_bytes(corrupt(good.read_bytes()))
    with pytest.raises(MeasuredFileError, match=message):
        MeasuredBRDF.from_binary(bad)
    with pytest.raises(MeasuredFileError, match="does not exist"):
        MeasuredBRDF.from_binary(tmp_path / "missing.binary")


def test_lookup_nearest_is_exact_on_grid_and_linear_interpolates():
    m = synthetic_table()
    th, td, pd = grid_angles()
    i, j, k = np.array([0, 10, 89]), np.array([3, 45, 80]), np.array([0, 90, 179])
    np.testing.assert_allclose(m.lookup(th[i], td[j], pd[k], "nearest"), m.table[i, j, k], rtol=1e-6)
    np.testing.assert_allclose(m.lookup(th[i], td[j], pd[k], "linear"), m.table[i, j, k], rtol=1e-5)
    mid = m.lookup([th[10]], [0.5 * (td[3] + td[4])], [pd[7]])
    np.testing.assert_allclose(mid[0], 0.5 * (m.table[10, 3, 7] + m.table[10, 4, 7]), rtol=1e-5)
    # phi_d folds with period pi
    np.testing.assert_allclose(m.lookup([0.3], [0.4], [0.2 - np.pi]), m.lookup([0.3], [0.4], [0.2]), rtol=1e-9)


def test_merl_plugin_matches_table_lookup(tmp_path):
    m = synthetic_table()
    path = tmp_path / "synthetic.binary"
    m.to_binary(path)
    rng = np.random.default_rng(2)
    n = 2000
    wi, wo = from_half_diff(rng.uniform(0, 1.2, n), rng.uniform(0, 1.2, n), rng.uniform(0, np.pi, n), phi_h=0.3)
    wi32, wo32 = np.stack(wi).astype(np.float32), np.stack(wo).astype(np.float32)
    above = (wi32[2] > 0) & (wo32[2] > 0)
    for interp in ("linear", "nearest"):
        bsdf = mi.load_dict({"type": "merl", "filename": str(path), "interpolation": interp})
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = mi.Vector3f(*wi32)
        got = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*wo32))).T
        w64 = [v.astype(np.float64) for v in (wi32, wo32)]
        th, _, td, pd = half_diff(tuple(w64[0]), tuple(w64[1]))
        ref = m.lookup(th, td, pd, interp) * w64[1][2][:, None]
        ok = above & (np.abs(ref).sum(1) > 0)
        close = np.isclose(got[ok], ref[ok], rtol=2e-3).all(1)
        # nearest lookups may fall into the neighbouring cell at float32 cell borders
        assert close.mean() > (0.999 if interp == "linear" else 0.98)
        assert np.all(got[~above] == 0)


def test_merl_plugin_bad_parameters(tmp_path):
    with pytest.raises(RuntimeError, match="needs either filename"):
        mi.load_dict({"type": "merl"})
    with pytest.raises(RuntimeError, match="does not exist"):
        mi.load_dict({"type": "merl", "filename": str(tmp_path / "none.binary")})


def test_nbrdf_tabulation_matches_network(nbrdf_file):
    names = nbrdf_names(nbrdf_file)
    assert len(names) == 100 and "gold-metallic-paint" in names
    m = MeasuredBRDF.from_nbrdf(nbrdf_file, "gold-metallic-paint")
    assert m.table.shape == SHAPE + (3,) and np.all(np.isfinite(m.table)) and m.table.min() >= 0
    th, td, pd = grid_angles()
    w = load_nbrdf_weights(nbrdf_file, "gold-metallic-paint")
    ref = eval_nbrdf(w, th[[0, 20, 60]], td[[5, 40, 85]], pd[[0, 90, 170]])
    np.testing.assert_allclose(m.table[[0, 20, 60], [5, 40, 85], [0, 90, 170]], ref, rtol=1e-6)
    # a glossy paint: the specular peak is far above the off-specular value
    assert m.table[0, 10].mean() > 10 * m.table[60, 10].mean()
    with pytest.raises(MeasuredFileError, match="did you mean gold-metallic-paint"):
        MeasuredBRDF.from_nbrdf(nbrdf_file, "gold-metalic-paint")
