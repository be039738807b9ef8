"""Every exception type of the package.

Each bad input the package detects raises one of these, with a message that
names the problem and, where there is one, the fix. The command line prints
them (and file-system errors, ``OSError``) as one line; anything else is a bug
and keeps its traceback.
"""


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


class ConfigError(MiDsbrdfError, ValueError):
    """An inference setting (:class:`~mi_dsbrdf.config.Config`) is out of range.

    ``field``: the Config field the message begins with (None for other
    messages), so that the command line can name the option instead."""

    def __init__(self, message, field=None):
        super().__init__(message)
        self.field = field


class InputError(MiDsbrdfError, ValueError):
    """Bad user input (image, mask, output folder, scene file): the message says what and where."""


class SceneError(MiDsbrdfError, ValueError):
    """A scene that inference cannot handle (no dsbrdf object, several lights, ...)."""


__all__ = ["MiDsbrdfError", "BackendError", "VariantError", "MaterialError", "MeasuredFileError", "ModelError",
           "ConfigError", "InputError", "SceneError"]
