"""Mitsuba plugin classes (installed as ``mi_dsbrdf.plugins``).

Only Mitsuba glue lives here: each plugin reads its XML properties, holds its
parameters as Dr.Jit arrays and calls the library (:mod:`mi_dsbrdf.brdf.dsbrdf`,
:mod:`mi_dsbrdf.brdf.measured`, :mod:`mi_dsbrdf.brdf.sampling`) to evaluate and sample.

A Python subclass of ``mi.BSDF`` binds to the variant active when its class
statement runs, so the plugin modules are (re)loaded once per variant.
"""
import importlib

_MODULES = {"dsbrdf": ("dsbrdf", "DSBRDF"), "merl": ("merl", "MeasuredBSDF")}
_cache: dict = {}


def bsdf_classes(variant: str) -> dict:
    """``{plugin name: BSDF class}`` bound to ``variant`` (the active one)."""
    if variant not in _cache:
        classes = {}
        for name, (module, cls) in _MODULES.items():
            mod = importlib.import_module(__name__ + "." + module)
            if getattr(mod, "_VARIANT", variant) != variant:
                mod = importlib.reload(mod)
            mod._VARIANT = variant
            classes[name] = getattr(mod, cls)
        _cache[variant] = classes
    return _cache[variant]
