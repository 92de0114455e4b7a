"""Mitsuba integrator plugins of foveated_mi."""
from __future__ import annotations

import threading

import mitsuba as mi

from ..validate import ParameterError

# The last ParameterError the foveated constructor raised. Mitsuba's loader turns it into a
# RuntimeError whose text holds a Python traceback; the loader's caller takes it back from
# here to report it in one line. Not thread-local: Mitsuba builds plugins on its own threads.
_last_error: ParameterError | None = None
_lock = threading.Lock()


def _foveated(props: "mi.Properties"):
    from .foveated import FoveatedIntegrator
    global _last_error
    try:
        return FoveatedIntegrator(props)
    except ParameterError as e:
        with _lock:
            _last_error = e
        raise


def take_plugin_error(text: str) -> ParameterError | None:
    """The ParameterError behind Mitsuba's loader error ``text``, if the foveated constructor
    raised it (``None`` otherwise); the slot is emptied either way."""
    if not isinstance(text, str):
        raise TypeError(f"text must be a str, not {type(text).__name__}")
    global _last_error
    with _lock:
        e, _last_error = _last_error, None
    # Only an error whose message Mitsuba quotes: an older one left by another load is not it.
    return e if e is not None and str(e) in text else None


def register() -> None:
    """Register ``foveated`` for the active variant (Mitsuba registers per variant)."""
    mi.register_integrator("foveated", _foveated)


__all__ = ["register", "take_plugin_error"]
