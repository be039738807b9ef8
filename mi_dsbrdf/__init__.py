"""mi-dsbrdf: reflectance (DSBRDF) and illumination recovery in Mitsuba 3.

Importing the package
  1. points Dr.Jit at a libLLVM >= 16 (and raises BackendError if there is none),
  2. selects the ``llvm_ad_rgb`` variant when none is set,
  3. registers the ``dsbrdf`` and ``merl`` BSDF plugins for the active variant,
     and again whenever ``mi.set_variant`` switches variant.
"""
from mi_dsbrdf.backend import select_libllvm as _select_libllvm

_select_libllvm()

from mi_dsbrdf import backend as _backend  # noqa: E402

_backend.ensure_variant()
_backend.register_plugins()
_backend.install_variant_callback()

from mi_dsbrdf.brdf.dsbrdf import Material  # noqa: E402
from mi_dsbrdf.config import PRESETS, Config  # noqa: E402
from mi_dsbrdf.errors import (BackendError, ConfigError, InputError, MaterialError,  # noqa: E402
                              MeasuredFileError, MiDsbrdfError, ModelError, SceneError, VariantError)
from mi_dsbrdf.model.library import load_material  # noqa: E402
from mi_dsbrdf.app.recover import recover  # noqa: E402
from mi_dsbrdf.app.result import Result  # noqa: E402
from mi_dsbrdf.app.batch import recover_many  # noqa: E402

__version__ = "0.1.0"
__all__ = ["recover", "recover_many", "Result", "Material", "load_material", "Config", "PRESETS",
           "MiDsbrdfError", "BackendError", "VariantError",
           "MaterialError", "MeasuredFileError", "ModelError", "ConfigError", "InputError", "SceneError"]
