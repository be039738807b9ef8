"""Measured isotropic BRDFs on the MERL grid — the package's single MERL reader.

A :class:`MeasuredBRDF` is a table of RGB values (1/sr) at

    theta_h[i] = (i / 90)^2 pi/2   (i < 90, square-root mapped: dense near the peak)
    theta_d[j] = j / 90 pi/2       (j < 90)
    phi_d[k]   = k / 180 pi        (k < 180; phi_d folded into [0, pi) by reciprocity)

filled either from a real MERL ``.binary`` file (three int32 dims 90, 90, 180,
then 3 x 1,458,000 doubles, channel-major, scaled by 1/1500, 1.15/1500,
1.66/1500; negative = not measured) or by tabulating a neural fit of a MERL
material (Sztrajman et al. 2021; ``merl_nbrdf_weights.npz``), which stands in
for the measurements where the raw files are not available.

Lookups (:func:`lookup_indices` + gathers) are written once for numpy and Dr.Jit;
the ``merl`` plugin uses the same index arithmetic as :meth:`MeasuredBRDF.lookup`.
"""
from __future__ import annotations

import difflib
import math
import os

import numpy as np

from mi_dsbrdf.brdf.angles import fold_phi_d
from mi_dsbrdf.brdf.xp import ops
from mi_dsbrdf.errors import MeasuredFileError

N_THETA_H, N_THETA_D, N_PHI_D = 90, 90, 180
SHAPE = (N_THETA_H, N_THETA_D, N_PHI_D)
SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
FILE_BYTES = 12 + 8 * 3 * N_THETA_H * N_THETA_D * N_PHI_D


def grid_angles():
    """(theta_h (90,), theta_d (90,), phi_d (180,)) float64 sample angles in radians."""
    i = np.arange(N_THETA_H)
    return ((i / N_THETA_H) ** 2 * (math.pi / 2), np.arange(N_THETA_D) / N_THETA_D * (math.pi / 2),
            np.arange(N_PHI_D) / N_PHI_D * math.pi)


def lookup_indices(theta_h, theta_d, phi_d, linear=True):
    """Flat table indices and weights for a lookup at the given angles.

    ``phi_d`` may be any angle (it is folded). Returns a list of
    ``(flat_index, weight)`` pairs: 8 for trilinear interpolation between
    samples, 1 for nearest (MERL's reference ``floor`` rule).
    """
    o = ops(theta_h, theta_d, phi_d)
    uh = o.sqrt(o.clip(theta_h, 0.0, math.pi / 2) / (math.pi / 2)) * N_THETA_H
    ud = o.clip(theta_d, 0.0, math.pi / 2) / (math.pi / 2) * N_THETA_D
    up = fold_phi_d(phi_d) / math.pi * N_PHI_D
    axes = []
    for u, n, wrap in ((uh, N_THETA_H, False), (ud, N_THETA_D, False), (up, N_PHI_D, True)):
        i0 = o.clip(o.floor(u), 0.0, n - 1.0)
        if not linear:
            axes.append([(i0, 1.0)])
            continue
        frac = o.clip(u - i0, 0.0, 1.0)
        i1 = o.select(i0 + 1.0 >= n, 0.0 if wrap else n - 1.0, i0 + 1.0)
        axes.append([(i0, 1.0 - frac), (i1, frac)])
    out = []
    for ih, wh in axes[0]:
        for jd, wd in axes[1]:
            for kp, wp in axes[2]:
                out.append(((ih * N_THETA_D + jd) * N_PHI_D + kp, wh * wd * wp))
    return out


class MeasuredBRDF:
    """An isotropic measured BRDF on the MERL grid.

    Attributes
    ----------
    table : (90, 90, 180, 3) float32 array, BRDF values in 1/sr (0 where unmeasured)
    measured : (90, 90, 180) bool array, False where the source had no value
    name : str
    """

    def __init__(self, table, measured=None, name=None):
        table = np.asarray(table, dtype=np.float32)
        if table.shape != SHAPE + (3,):
            raise MeasuredFileError("a measured BRDF table has shape %s, got %s" % (SHAPE + (3,), table.shape))
        if not np.all(np.isfinite(table)):
            raise MeasuredFileError("measured BRDF %s has non-finite values" % (name or ""))
        self.measured = np.all(table >= 0, axis=-1) if measured is None else np.asarray(measured, bool)
        if not self.measured.any():
            raise MeasuredFileError("measured BRDF %s has no measured value (every cell is negative: unmeasured)"
                                    % (name or ""))
        self.table = np.where(self.measured[..., None], np.maximum(table, 0), 0).astype(np.float32)
        self.name = name

    # --- sources -------------------------------------------------------------
    @classmethod
    def from_binary(cls, path):
        """Read a MERL ``.binary`` file; MeasuredFileError if truncated or malformed."""
        path = os.fspath(path)
        try:
            size = os.path.getsize(path)
            with open(path, "rb") as f:
                raw = f.read()
        except FileNotFoundError:
            raise MeasuredFileError("MERL file %s does not exist" % path) from None
        except OSError as e:
            raise MeasuredFileError("MERL file %s is unreadable: %s" % (path, e)) from None
        if size < 12:
            raise MeasuredFileError("MERL file %s is truncated: %d bytes, expected %d" % (path, size, FILE_BYTES))
        dims = tuple(int(v) for v in np.frombuffer(raw[:12], dtype="<i4"))
        if dims != SHAPE:
            raise MeasuredFileError("MERL file %s has dimensions %s, expected %s (not a MERL BRDF?)"
                                    % (path, dims, SHAPE))
        if size != FILE_BYTES:
            raise MeasuredFileError("MERL file %s has %d bytes, expected %d (%s)" % (
                path, size, FILE_BYTES, "truncated" if size < FILE_BYTES else "trailing data"))
        data = np.frombuffer(raw[12:], dtype="<f8").reshape((3,) + SHAPE)
        if not np.all(np.isfinite(data)):
            raise MeasuredFileError("MERL file %s holds non-finite values" % path)
        measured = np.all(data >= 0, axis=0)
        table = np.moveaxis(data, 0, -1) * SCALE
        return cls(table, measured, name=os.path.splitext(os.path.basename(path))[0])

    def to_binary(self, path) -> None:
        """Write the table as a MERL ``.binary`` file (unmeasured cells as -1)."""
        data = np.moveaxis(self.table.astype(np.float64) / SCALE, -1, 0)
        data = np.where(self.measured[None], data, -1.0)
        with open(path, "wb") as f:
            f.write(np.array(SHAPE, dtype="<i4").tobytes())
            f.write(np.ascontiguousarray(data, dtype="<f8").tobytes())

    @classmethod
    def from_nbrdf(cls, npz_path, name):
        """Tabulate the neural fit of MERL material ``name`` on the MERL grid."""
        weights = load_nbrdf_weights(npz_path, name)
        return cls.from_function(lambda th, td, pd: eval_nbrdf(weights, th, td, pd), name=name)

    @classmethod
    def from_function(cls, brdf, name=None):
        """Tabulate ``brdf(theta_h, theta_d, phi_d) -> (N, 3)`` (e.g. a DSBRDF)."""
        th, td, pd = grid_angles()
        TH, TD, PD = np.meshgrid(th, td, pd, indexing="ij")
        return cls(np.asarray(brdf(TH.reshape(-1), TD.reshape(-1), PD.reshape(-1))).reshape(SHAPE + (3,)), name=name)

    # --- queries -------------------------------------------------------------
    def lookup(self, theta_h, theta_d, phi_d, interpolation="linear") -> np.ndarray:
        """(N, 3) float64 values at angles in radians; ``interpolation`` 'linear' or 'nearest'."""
        flat = self.table.reshape(-1, 3).astype(np.float64)
        th, td, pd = (np.asarray(a, dtype=np.float64).reshape(-1) for a in (theta_h, theta_d, phi_d))
        out = np.zeros(th.shape + (3,))
        for idx, w in lookup_indices(th, td, pd, linear=is_linear(interpolation)):
            out += flat[idx.astype(np.int64)] * np.reshape(w, (-1, 1))
        return out

    def sampling_lobes(self, w_cos=0.15):
        """Power-cosine lobes for importance sampling this table.

        From the luminance profile over theta_h near the specular configuration
        (theta_d < 30 deg, mean over phi_d): a sharp lobe whose exponent puts half
        its height at the profile's half maximum above the diffuse floor, and a
        broader one (exponent / 10) for the shoulder. Returns ``(w_cos, weights,
        exponents)`` (Python floats) for :mod:`mi_dsbrdf.brdf.sampling`.
        """
        th, _, _ = grid_angles()
        lum = self.table[:, :30].astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])
        profile = lum.mean(axis=(1, 2))
        floor, peak = float(profile.min()), float(profile[0])
        if not peak > 1.5 * floor + 1e-12:
            return 1.0, [], []
        half = np.nonzero(profile - floor < 0.5 * (peak - floor))[0]
        theta_half = th[half[0]] if half.size else th[-1]
        n = float(np.clip(math.log(2) / -math.log(math.cos(max(theta_half, 1e-3))), 1.0, 1e6))
        e_lobe = (peak - floor) * 2 * math.pi / (n + 1)
        e_diffuse = floor * math.pi
        w_lobes = (1 - w_cos) * e_lobe / (e_lobe + e_diffuse)
        w_c = 1.0 - w_lobes
        return w_c, [0.7 * w_lobes, 0.3 * w_lobes], [n, max(n / 10, 1.0)]

    def bivariate(self) -> np.ndarray:
        """(90, 90, 3) table over (theta_h, theta_d), averaged over measured phi_d."""
        n = self.measured.sum(axis=2)[..., None]
        return self.table.sum(axis=2) / np.maximum(n, 1)


def is_linear(interpolation) -> bool:
    """True for 'linear', False for 'nearest'; MeasuredFileError otherwise."""
    if interpolation not in ("linear", "nearest"):
        raise MeasuredFileError("interpolation must be 'linear' or 'nearest', got %r" % (interpolation,))
    return interpolation == "linear"


def nbrdf_names(npz_path) -> list:
    with _open_npz(npz_path) as f:
        return [str(n) for n in f["names"]]


def load_nbrdf_weights(npz_path, name) -> dict:
    with _open_npz(npz_path) as f:
        names = [str(n) for n in f["names"]] if "names" in f.files else []
        if name not in names:
            close = difflib.get_close_matches(name, names, n=3)
            raise MeasuredFileError("no material %r in %s%s" % (
                name, npz_path, ("; did you mean %s?" % ", ".join(close)) if close else ""))
        try:
            w = {k: np.asarray(f["%s/%s" % (name, k)], dtype=np.float32) for k in ("W1", "b1", "W2", "b2", "W3", "b3")}
        except KeyError as e:
            raise MeasuredFileError("%s lacks the array %s" % (npz_path, e)) from None
    shapes = {"W1": (6, None), "W2": (None, None), "W3": (None, 3)}
    for k, (rows, cols) in shapes.items():
        if w[k].ndim != 2 or (rows and w[k].shape[0] != rows) or (cols and w[k].shape[1] != cols):
            raise MeasuredFileError("%s: %s/%s has shape %s" % (npz_path, name, k, w[k].shape))
    return w


def eval_nbrdf(w, theta_h, theta_d, phi_d, chunk=262144) -> np.ndarray:
    """(N, 3) float64 RGB of a neural fit at the given angles (phi_h = 0).

    Input row (h, d) in half/difference coordinates; two ReLU layers; output
    max(exp(.) - 1, 0), in 1/sr (the published evaluation).
    """
    th, td, pd = (np.asarray(a, dtype=np.float64).reshape(-1) for a in (theta_h, theta_d, phi_d))
    x = np.stack([np.sin(th), np.zeros_like(th), np.cos(th),
                  np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)], axis=-1).astype(np.float32)
    out = np.empty((x.shape[0], 3), dtype=np.float64)
    for s in range(0, x.shape[0], chunk):
        a = np.maximum(x[s:s + chunk] @ w["W1"] + w["b1"], 0)
        a = np.maximum(a @ w["W2"] + w["b2"], 0)
        out[s:s + chunk] = np.maximum(np.expm1((a @ w["W3"] + w["b3"]).astype(np.float64)), 0)
    return out


def _open_npz(path):
    try:
        return np.load(os.fspath(path), allow_pickle=False)
    except FileNotFoundError:
        raise MeasuredFileError("neural-fit file %s does not exist" % path) from None
    except (OSError, ValueError) as e:
        raise MeasuredFileError("neural-fit file %s is unreadable: %s" % (path, e)) from None
