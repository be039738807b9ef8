"""Where materials come from: files, the shipped library, XML parameters.

``load_material(path_or_name)`` is the stable entry point: a ``material.json``
path, or the name of a material of the shipped library (the DSBRDF fits of the
MERL materials, built by the reflectance-model build).
"""
from __future__ import annotations

import os

import numpy as np

from mi_dsbrdf.brdf.curves import N_CONTROL
from mi_dsbrdf.brdf.dsbrdf import MAX_LOBES, Material
from mi_dsbrdf.errors import MaterialError
from mi_dsbrdf.model import model_file as model_data


def default_material() -> Material:
    """The material of a bare ``<bsdf type="dsbrdf"/>``.

    With a shipped reflectance model this is the model's mean material (all
    coefficients zero); without one, a neutral two-lobe grey material (a broad,
    nearly Lambertian lobe and a glossy one).
    """
    model = model_data.shipped_model()
    if model is not None:
        return model.mean_material()
    return Material.from_curves(kappa=[[0.4] * N_CONTROL, [1.5] * N_CONTROL],
                                gamma=[[1.0] * N_CONTROL, [60.0] * N_CONTROL],
                                chromaticity=[[1 / 3] * 3, [1 / 3] * 3], name="default")


def library_names() -> list:
    """Names of the materials in the shipped library (sorted)."""
    model = model_data.shipped_model()
    return sorted(model.library) if model is not None else []


def load_material(path_or_name) -> Material:
    """A :class:`Material` from a ``material.json`` path or a library name."""
    s = os.fspath(path_or_name)
    if os.path.exists(s) or s.endswith(".json") or os.sep in s:
        return Material.load(s)
    model = model_data.shipped_model()
    if model is None or s not in model.library:
        names = library_names()
        hint = ("known names: %s" % ", ".join(names)) if names else "no material library is installed yet"
        raise MaterialError("unknown material %r (not a file either); %s" % (s, hint))
    return model.library_material(s)


def _floats(value, what, n=None, broadcast=True) -> np.ndarray:
    """Parse a float, or a string of floats separated by spaces/commas; with
    ``broadcast`` a single value stands for n equal ones (a constant curve)."""
    if isinstance(value, (int, float)):
        vals = np.array([float(value)])
    else:
        try:
            vals = np.array([float(v) for v in str(value).replace(",", " ").split()])
        except ValueError:
            raise MaterialError("%s must be numbers, got %r" % (what, value)) from None
    if broadcast and n is not None and vals.size == 1 and n > 1:
        vals = np.full(n, vals[0])
    if n is not None and vals.size != n:
        raise MaterialError("%s needs %d values, got %d" % (what, n, vals.size))
    return vals


def material_from_params(params: dict):
    """The material described by ``dsbrdf`` plugin parameters.

    One of (checked in this order, mixing them is an error):
      * ``filename``: a ``material.json``;
      * ``material``: a library name;
      * ``psi`` (k floats) and per-lobe ``chromaticity_<r>``: a point of the
        learned basis (``model``: path of a model file, default the shipped one);
      * ``kappa_<r>``, ``gamma_<r>`` (6 positive control values, or one for a
        constant curve) and ``chromaticity_<r>`` (3 values summing to one) for
        r < ``lobes``;
      * nothing: :func:`default_material`.
    Returns ``(material, basis)`` with ``basis`` a CurveBasis or None.
    """
    p = dict(params)
    sources = [k for k in ("filename", "material", "psi") if k in p]
    explicit = sorted(k for k in p if k.startswith(("kappa_", "gamma_")))
    if len(sources) > 1 or (sources and explicit):
        raise MaterialError("give one of filename, material, psi or explicit kappa_/gamma_ curves; got %s"
                            % ", ".join(sources + explicit))
    if "filename" in p:
        return Material.load(p["filename"]), None
    if "material" in p:
        return load_material(p["material"]), None
    if "psi" in p:
        model = model_data.load_model(p["model"]) if "model" in p else model_data.shipped_model()
        if model is None:
            raise MaterialError("psi was given but no reflectance model is installed; pass model=<file>")
        basis = model.basis
        psi = _floats(p["psi"], "psi", basis.n_bases, broadcast=False)
        chroma = _chromaticities(p, basis.n_lobes)
        return Material.from_basis(basis, psi, chroma), basis
    if not explicit:
        if "lobes" in p:
            raise MaterialError("lobes=%s was given without kappa_<r>/gamma_<r> curves" % p["lobes"])
        return default_material(), None
    lobes = int(p.get("lobes", 1 + max(int(k.split("_")[1]) for k in explicit)))
    if not 1 <= lobes <= MAX_LOBES:
        raise MaterialError("a material has 1 to %d lobes, got %d" % (MAX_LOBES, lobes))
    kappa = np.stack([_floats(_need(p, "kappa_%d" % r), "kappa_%d" % r, N_CONTROL) for r in range(lobes)])
    gamma = np.stack([_floats(_need(p, "gamma_%d" % r), "gamma_%d" % r, N_CONTROL) for r in range(lobes)])
    extra = [k for k in explicit if int(k.split("_")[1]) >= lobes]
    if extra:
        raise MaterialError("lobes=%d but %s given" % (lobes, ", ".join(extra)))
    return Material.from_curves(kappa, gamma, _chromaticities(p, lobes)), None


def _chromaticities(p, lobes) -> np.ndarray:
    return np.stack([_floats(p.get("chromaticity_%d" % r, "0.333333333 0.333333333 0.333333334"),
                             "chromaticity_%d" % r, 3, broadcast=False) for r in range(lobes)])


def _need(p, key):
    if key not in p:
        raise MaterialError("missing parameter %s" % key)
    return p[key]
