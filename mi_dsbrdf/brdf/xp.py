"""One array vocabulary for numpy (float64 reference) and Dr.Jit (kernels).

Functions written against :func:`ops` run unchanged on numpy arrays and on
Dr.Jit arrays, so a formula (half/difference angles, B-spline curves, the DSBRDF
lobe) is written once and the float64 numpy evaluation of the same code is the
reference the tests hold the Dr.Jit kernel to.
"""
from __future__ import annotations

import drjit as dr
import numpy as np


class _Numpy:
    name = "numpy"
    sqrt = staticmethod(lambda x: np.sqrt(np.maximum(x, 0.0)))
    acos = staticmethod(lambda x: np.arccos(np.clip(x, -1.0, 1.0)))
    atan2 = staticmethod(np.arctan2)
    sin = staticmethod(np.sin)
    cos = staticmethod(np.cos)
    exp = staticmethod(np.exp)
    log = staticmethod(np.log)
    abs = staticmethod(np.abs)
    floor = staticmethod(np.floor)
    select = staticmethod(np.where)
    fmax = staticmethod(np.fmax)
    fmin = staticmethod(np.fmin)
    clip = staticmethod(lambda x, lo, hi: np.clip(x, lo, hi))
    zeros_like = staticmethod(np.zeros_like)


class _DrJit:
    name = "drjit"

    def __init__(self):
        self.dr = dr
        self.sqrt = dr.safe_sqrt
        self.acos = dr.safe_acos
        self.atan2 = dr.atan2
        self.sin, self.cos, self.exp, self.log, self.abs = dr.sin, dr.cos, dr.exp, dr.log, dr.abs
        self.floor = dr.floor
        self.select = dr.select
        # fmax/fmin: NaN-suppressing like numpy's (dr.maximum propagates NaN).
        self.fmax, self.fmin = dr.fmax, dr.fmin
        self.clip = lambda x, lo, hi: dr.fmin(dr.fmax(x, lo), hi)
        self.zeros_like = dr.zeros_like


_NP = _Numpy()
_DR = None


def is_drjit(x) -> bool:
    return type(x).__module__.startswith("drjit")


def ops(*arrays):
    """The operation set for ``arrays``: Dr.Jit if any of them is a Dr.Jit array."""
    global _DR
    if any(is_drjit(a) for a in arrays):
        if _DR is None:
            _DR = _DrJit()
        return _DR
    return _NP


# --- numerically stable elementary functions ---------------------------------
# Dr.Jit has no expm1/log1p; exp(x) - 1 loses all relative precision as x -> 0
# (a lobe with tiny kappa), so both are written here once for both backends.

_EXPM1_SMALL = 0.1


def expm1(x):
    """exp(x) - 1 with full relative precision for small |x|.

    |x| < 0.1: degree-7 Taylor polynomial (truncation < 3e-12 relative);
    otherwise exp(x) - 1 (relative error <= ~1e-6 in float32 since |exp(x) - 1| >= 0.095).
    Each branch sees only inputs of its own range, so neither produces an
    inf/NaN whose zero-weighted gradient would poison the other (x = -inf -> -1).
    """
    o = ops(x)
    small = o.abs(x) < _EXPM1_SMALL
    xs = o.select(small, x, 0.0)
    poly = xs * (1.0 + xs * (1 / 2 + xs * (1 / 6 + xs * (1 / 24 + xs * (1 / 120 + xs * (1 / 720 + xs * (1 / 5040)))))))
    xl = o.select(small, 1.0, x)
    return o.select(small, poly, o.exp(xl) - 1.0)


def log1p(x):
    """log(1 + x) for x > -1 with full relative precision for small |x|.

    |x| < 0.1: degree-9 series (truncation < 1e-10 relative); otherwise log(1 + x).
    """
    o = ops(x)
    small = o.abs(x) < 0.1
    xs = o.select(small, x, 0.0)
    poly = 1.0 / 9.0  # Horner form of x - x^2/2 + x^3/3 - ... + x^9/9
    for k in range(8, 0, -1):
        poly = 1.0 / k - xs * poly
    poly = xs * poly
    xl = o.select(small, 1.0, x)
    return o.select(small, poly, o.log(1.0 + xl))
