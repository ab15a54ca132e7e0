"""The package's exceptions: one root, and subclasses where a caller must tell failures apart.

The CLI turns every :class:`StablemarksError` into a one-line message and exit code 1; anything
else is a bug and keeps its traceback.

Messages name the library's parameters, in backticks (```map```, ```calib```, ```mount```): a script sees the
keyword argument to pass, and the CLI shows its own flag instead (:func:`for_cli`).
"""

from __future__ import annotations

MAX_MESSAGE = 2000
"""Longest message of a :class:`StablemarksError` [characters]; longer ones lose their middle to ``…``."""

MAX_LINE = 300
"""Longest error line the CLI prints [characters], its ``stablemarks CMD: error:`` prefix included."""

MAX_GOT = 100
"""Longest ``got ...`` part of :func:`expected` [characters]."""


def one_line(text: str, limit: int | None = MAX_MESSAGE) -> str:
    """``text`` as one printable line: control characters and line breaks escaped (``\\n``, ``\\x1b``,
    ``\\u2028``, ...), at most ``limit`` characters (None: no limit): a longer text keeps its first two thirds
    and its end, with ``…`` between (the file and field come first, what was expected and found last).

    >>> one_line("a\\nb\\tc")
    'a\\\\nb\\\\tc'
    """
    text = str(text)
    if not text.isprintable():
        text = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
    if limit is not None and len(text) > limit:
        head = (limit - 1) * 2 // 3
        text = text[:head] + "…" + text[len(text) - (limit - 1 - head):]
    return text


class StablemarksError(Exception):
    """Root of every error this package raises on purpose.

    Its message is always one printable line of at most :data:`MAX_MESSAGE` characters (:func:`one_line`):
    whatever a file put into it (a key with a line break, a huge value) is escaped and shortened. The CLI
    prints it in at most :data:`MAX_LINE` characters.
    """

    def __init__(self, *args: object) -> None:
        if args and isinstance(args[0], str):
            args = (one_line(args[0]), *args[1:])
        super().__init__(*args)


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
    return f"{prefix}expected {what}, got {short_repr(got)}"


def short_repr(value: object, limit: int = MAX_GOT) -> str:
    """``repr(value)`` cut to ``limit`` characters (``…`` in the middle), safe for any value: a huge
    integer, a deep or recursive structure.

    >>> short_repr(10**400)[:12], len(short_repr(10**400))
    ('100000000000', 100)
    """
    try:
        text = repr(value)
    except (ValueError, RecursionError):  # an int too long for repr(), a structure too deep
        text = f"<{type(value).__name__}>"
    if len(text) > limit:
        head = limit * 2 // 3
        text = text[: head] + "…" + text[len(text) - (limit - head - 1):]
    return text


def for_cli(message: str, flags: dict[str, str]) -> str:
    """``message`` with each backticked parameter name of ``flags`` replaced by its command-line flag, e.g.
    ``"pass `map` (our map YAML)"`` → ``"pass --map (our map YAML)"`` with ``{"map": "--map"}``."""
    for name, flag in flags.items():
        message = message.replace(f"`{name}`", flag)
    return message
