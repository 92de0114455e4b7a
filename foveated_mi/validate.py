"""Argument validation shared by every pass, the integrator, the CLI and the configs.

Every failure is one line naming the input, its value and what is allowed, e.g.::

    theta = -1.0 is invalid: expected a finite number > 0
"""
from __future__ import annotations

import difflib
import math
from typing import Any, Iterable


class ParameterError(ValueError):
    """Bad user input. The message is a single line: name, value, what is allowed."""

    def __init__(self, name: str, value: Any, allowed: str):
        self.name, self.value, self.allowed = name, value, allowed
        super().__init__(f"{name} = {value!r} is invalid: expected {allowed}")


def _as_float(name: str, value: Any, allowed: str) -> float:
    if isinstance(value, bool):
        raise ParameterError(name, value, allowed)
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ParameterError(name, value, allowed) from None


def check_finite(name: str, value: Any) -> float:
    """A finite number: :func:`check_range` without bounds.

    Parameters
    ----------
    name, value : str, object
        The input's name, for the error message, and its value (a ``bool`` is refused).

    Returns
    -------
    value : float
        ``value`` as a float.

    Raises
    ------
    ParameterError
        If ``value`` is not a finite number.
    """
    return check_range(name, value)


def _bounds(*parts: str | None) -> str:
    """`` >= lo and <= hi`` from the bounds given (empty without any)."""
    given = [p for p in parts if p]
    return " " + " and ".join(given) if given else ""


def check_range(name: str, value: Any, lo: float | None = None, hi: float | None = None,
                lo_open: bool = False, hi_open: bool = False) -> float:
    """A finite float inside [lo, hi] (or open ends).

    Parameters
    ----------
    name, value : str, object
        As for :func:`check_finite`.
    lo, hi : float or None, optional
        The bounds (None: unbounded on that side).
    lo_open, hi_open : bool, optional
        Exclude that bound itself.

    Returns
    -------
    value : float
        ``value`` as a float, inside the bounds.

    Raises
    ------
    ParameterError
        If ``value`` is not a finite number within the bounds.
    """
    allowed = "a finite number" + _bounds(f"{'>' if lo_open else '>='} {lo:g}" if lo is not None
                                          else None,
                                          f"{'<' if hi_open else '<='} {hi:g}" if hi is not None
                                          else None)
    v = _as_float(name, value, allowed)
    ok = math.isfinite(v)
    if ok and lo is not None:
        ok = v > lo if lo_open else v >= lo
    if ok and hi is not None:
        ok = v < hi if hi_open else v <= hi
    if not ok:
        raise ParameterError(name, value, allowed)
    return v


def check_int(name: str, value: Any, lo: int | None = None, hi: int | None = None) -> int:
    """An integer inside [lo, hi].

    Parameters
    ----------
    name : str
        As for :func:`check_finite`.
    value : object
        An ``int``, or anything ``int()`` converts (a float only when it is integral; a
        ``bool`` is refused).
    lo, hi : int or None, optional
        The bounds, inclusive (None: unbounded on that side).

    Returns
    -------
    value : int
        ``value`` as an int.

    Raises
    ------
    ParameterError
        If ``value`` is not an integer within the bounds.
    """
    allowed = "an integer" + _bounds(f">= {lo}" if lo is not None else None,
                                     f"<= {hi}" if hi is not None else None)
    if isinstance(value, bool):
        raise ParameterError(name, value, allowed)
    try:
        v = int(value)
    except (TypeError, ValueError, OverflowError):
        raise ParameterError(name, value, allowed) from None
    if isinstance(value, float) and value != v:
        raise ParameterError(name, value, allowed)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ParameterError(name, value, allowed)
    return v


def check_choice(name: str, value: Any, choices: Iterable[str]) -> str:
    """One of the allowed strings.

    Parameters
    ----------
    name, value : str, object
        As for :func:`check_finite` (any type; only a listed string passes).
    choices : iterable of str
        The allowed values (listed in the error message).

    Returns
    -------
    value : str
        ``value`` itself.

    Raises
    ------
    ParameterError
        If ``value`` is not one of ``choices``.
    """
    choices = list(choices)
    if not isinstance(value, str) or value not in choices:
        raise ParameterError(name, value, "one of " + ", ".join(repr(c) for c in choices))
    return value


def unknown_name(name: Any, names: Iterable[str], what: str, see: str | None = None) -> str:
    """What is allowed in place of the unknown ``name``, short enough for one line.

    ``what`` and the closest of ``names`` (:func:`difflib.get_close_matches`); when none is
    close, where the names are listed (``see``), else the names themselves.

    Parameters
    ----------
    name : object
        The unknown name.
    names : iterable of str
        The known names.
    what : str
        What is allowed, in words (e.g. ``"a known key"``).
    see : str or None, optional
        Where the names are listed (None: list them).

    Returns
    -------
    allowed : str
        The ``allowed`` text of a :class:`ParameterError`.
    """
    names = list(names)
    close = difflib.get_close_matches(str(name), names, n=1)
    if close:
        return f"{what} (did you mean {close[0]!r}?)"
    if see is not None:
        return f"{what} (none is close; see {see})"
    return f"{what} (allowed here: {', '.join(names)})"


def check_point2(name: str, value: Any, bound: float = 1e6) -> tuple[float, float]:
    """Two finite numbers of magnitude <= ``bound``.

    A gaze may lie outside [0, 1]^2 (the viewer looks off-screen); the bound keeps
    ``gaze * width`` finite in float32.

    Parameters
    ----------
    name : str
        As for :func:`check_finite`.
    value : iterable
        The two numbers ``(x, y)``.
    bound : float, optional
        Largest magnitude allowed.

    Returns
    -------
    x, y : float
        The two numbers.

    Raises
    ------
    ParameterError
        If ``value`` is not two finite numbers within ``bound``.
    """
    allowed = f"two finite numbers (x, y) with |x|, |y| <= {bound:g}"
    try:
        x, y = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ParameterError(name, value, allowed) from None
    if not (math.isfinite(x) and math.isfinite(y)) or abs(x) > bound or abs(y) > bound:
        raise ParameterError(name, value, allowed)
    return x, y


def check_bool(name: str, value: Any) -> bool:
    """A real ``bool`` (not 0/1, not a string).

    Parameters
    ----------
    name, value : str, object
        As for :func:`check_finite`, but of any type (only a ``bool`` passes).

    Returns
    -------
    value : bool
        ``value`` itself.

    Raises
    ------
    ParameterError
        If ``value`` is not a ``bool``.
    """
    if isinstance(value, bool):
        return value
    raise ParameterError(name, value, "true or false")


def check_sigma(name: str, value: Any) -> float:
    """A filter's sigma: a number > 0, where ``inf`` disables that weight.

    Parameters
    ----------
    name, value : str, object
        As for :func:`check_finite` (``inf`` passes).

    Returns
    -------
    sigma : float
        ``value`` as a float (possibly ``inf``).

    Raises
    ------
    ParameterError
        If ``value`` is not a number > 0.
    """
    allowed = "a number > 0, or inf to disable this weight"
    if isinstance(value, bool):
        raise ParameterError(name, value, allowed)
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(name, value, allowed) from None
    if not (v > 0) or math.isnan(v):
        raise ParameterError(name, value, allowed)
    return v


class TableContext:
    """Checks of a configuration file's tables: every error names the file and the dotted
    key of the bad value (one line)."""

    def __init__(self, source: str):
        self.source = source

    def error(self, key: str, value: Any, allowed: str) -> ParameterError:
        e = ParameterError(f"{self.source}: {key}", value, allowed)
        e.key = key
        return e

    def rename(self, e: ParameterError, prefix: str | None = None) -> ParameterError:
        """Re-issue an error raised by a path or integrator check under the file's name."""
        key = e.name if prefix is None or e.name.startswith(prefix) else f"{prefix}.{e.name}"
        return self.error(key, e.value, e.allowed)

    def table(self, key: str, value: Any) -> dict:
        if not isinstance(value, dict):
            raise self.error(key, value, "a table")
        return value

    def known(self, key: str, table: dict, allowed: tuple[str, ...] | list[str],
              see: str | None = None) -> None:
        """Every key of ``table`` is one of ``allowed``; an unknown one names the closest
        allowed key, else ``see`` (where they are listed), else all of them."""
        for k, v in table.items():
            if k not in allowed:
                name = f"{key}.{k}" if key else k
                raise self.error(name, v, unknown_name(k, allowed, "a known key", see))

    def integer(self, key: str, value: Any, lo: int, hi: int | None = None) -> int:
        allowed = f"an integer >= {lo}" + (f" and <= {hi}" if hi is not None else "")
        if isinstance(value, bool) or not isinstance(value, int) or value < lo or \
                (hi is not None and value > hi):
            raise self.error(key, value, allowed)
        return value

    def number(self, key: str, value: Any, lo: float, lo_open: bool = False) -> float:
        allowed = f"a finite number {'>' if lo_open else '>='} {lo:g}"
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not math.isfinite(value) or value < lo or (lo_open and value == lo):
            raise self.error(key, value, allowed)
        return float(value)

    def boolean(self, key: str, value: Any) -> bool:
        if not isinstance(value, bool):
            raise self.error(key, value, "true or false")
        return value

    def string(self, key: str, value: Any, choices: tuple[str, ...] | None = None) -> str:
        if choices is not None:
            if not isinstance(value, str) or value not in choices:
                raise self.error(key, value, "one of " + ", ".join(repr(c) for c in choices))
        elif not isinstance(value, str):
            raise self.error(key, value, "a string")
        return value


def one_line(e: BaseException) -> str:
    """An exception in one line: its type and its text with every run of white space one space
    (a worker's or a task's failure, as a study reports it)."""
    text = " ".join(str(e).split())
    return f"{type(e).__name__}: {text}" if text else type(e).__name__
