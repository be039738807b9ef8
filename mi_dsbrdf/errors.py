"""Exception types: every bad input the package detects raises one of these,
with a message that names the problem and, where there is one, the fix."""


class MiDsbrdfError(Exception):
    """Base class of the package's errors."""


class BackendError(MiDsbrdfError, ImportError):
    """No usable Dr.Jit backend (e.g. libLLVM older than 16)."""


class VariantError(MiDsbrdfError, RuntimeError):
    """The active Mitsuba variant cannot run the package's plugins."""


class MaterialError(MiDsbrdfError, ValueError):
    """A DSBRDF material (parameters, file or name) is invalid."""


class MeasuredFileError(MiDsbrdfError, ValueError):
    """A measured-BRDF file (MERL .binary, neural fit) is missing or malformed."""


class ModelError(MiDsbrdfError, ValueError):
    """A reflectance-model file (bases, priors, library) is missing or malformed."""
