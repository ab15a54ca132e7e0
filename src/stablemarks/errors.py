"""The package's exceptions: one root, and subclasses where a caller must tell failures apart.

The CLI turns every :class:`StablemarksError` into a one-line message and exit code 1; anything
else is a bug and keeps its traceback.

Messages name the library's parameters, in backticks (```map```, ```calib```, ```mount```): a script sees the
keyword argument to pass, and the CLI shows its own flag instead (:func:`for_cli`).
"""

from __future__ import annotations


class StablemarksError(Exception):
    """Root of every error this package raises on purpose."""


class InputError(StablemarksError, ValueError):
    """A user-supplied file or value is malformed.

    The message names the file (when there is one), the field and what was expected, e.g.
    ``map.yaml: planes[2].p1: expected a list of 2 numbers [x, y] in metres, got 'abc'``.
    """


class ConfigError(InputError):
    """A configuration, scenario or map file does not validate."""


class ImageError(InputError):
    """An image cannot be read, or a stereo pair does not fit together (sizes, calibration)."""


class CalibrationError(StablemarksError):
    """Stereo calibration failed (too few boards found, degenerate views)."""


class SequenceError(InputError):
    """A recorded-sequence folder is incomplete or inconsistent."""


class GeometryError(StablemarksError, ValueError):
    """A geometric computation is undefined, e.g. a point behind the camera or zero disparity."""


def expected(what: str, got: object, *, where: str = "") -> str:
    """Format the package's standard "expected X, got Y" message.

    >>> expected("a positive number", -1.0, where="camera.f")
    'camera.f: expected a positive number, got -1.0'
    """
    prefix = f"{where}: " if where else ""
    return f"{prefix}expected {what}, got {got!r}"


def for_cli(message: str, flags: dict[str, str]) -> str:
    """``message`` with each backticked parameter name of ``flags`` replaced by its command-line flag, e.g.
    ``"pass `map` (our map YAML)"`` → ``"pass --map (our map YAML)"`` with ``{"map": "--map"}``."""
    for name, flag in flags.items():
        message = message.replace(f"`{name}`", flag)
    return message
