"""The messages a page may send over its socket: a fixed set of types, each validated.

A message is one JSON object with a ``type`` and that type's fields, nothing else. Nothing a
page sends is ever run as code: :func:`parse` returns plain values or raises a one-line
:class:`~foveated_mi.validate.ParameterError`, which the server sends back to the page as
``foveated-mi: error: <name> = <value> is invalid: expected ...``, the command line's text.

========================  ===============================================================
``gaze``                  ``x``, ``y`` (normalised film position, in [-1, 2]), ``seq``
                          (the page's counter, echoed in the frames rendered with it)
``lock``                  ``on``: hold the gaze where it is while the mouse moves on
``move``                  ``forward``, ``right``, ``up`` (in camera distances, each in
                          [-1, 1]), ``yaw``, ``pitch`` (degrees, each in [-90, 90]); any subset
``home``                  back to the scene's camera (a jump: the history is dropped)
``settings``              any of ``preset``, ``ray_budget``, ``spp``, ``denoiser``, ``fps``
                          (the frame-rate target, 0: off)
``view``                  any of ``overlays`` (a list of :data:`OVERLAYS`), ``split`` (one of
                          :data:`SPLITS`), ``latency_ms`` (in [0, 1000])
``gaze_source``           ``source`` (one of :data:`SOURCES`); with ``csv``: ``csv`` (the file's
                          text, at most 1 MiB) and ``name``
``record``                ``on``: start or stop recording the frames' poses
``ack``                   ``frame``: the page has shown this frame (flow control)
========================  ===============================================================
"""
from __future__ import annotations

import json
import math
from typing import Any

from .. import tracker as _tracker
from ..validate import ParameterError, check_bool, check_int, check_range

__all__ = ["parse", "MESSAGE_TYPES", "OVERLAYS", "SPLITS", "SOURCES", "SETTINGS",
           "MAX_MESSAGE_BYTES", "MAX_CSV_BYTES", "error_text"]

#: Overlays drawn into the frame by the server (the page draws the eccentricity rings).
OVERLAYS = ("map", "history", "traced")
#: What the split view shows beside the foveated frame.
SPLITS = ("off", "uniform", "still")
#: Where the gaze comes from.
SOURCES = ("mouse", "saccades", "csv")
#: Controls that rebuild the renderer.
SETTINGS = ("preset", "ray_budget", "spp", "denoiser", "fps")
MAX_CSV_BYTES = 1 << 20
MAX_MESSAGE_BYTES = MAX_CSV_BYTES + 4096
LATENCY_MAX_MS = _tracker.LATENCY_MAX_MS     # the eye tracker's range
SPP_MAX = 64


def error_text(e: ParameterError) -> str:
    """The one line the command line prints for ``e``."""
    return f"foveated-mi: error: {e}"


def _fields(msg: dict, kind: str, allowed: tuple[str, ...], required: tuple[str, ...] = ()):
    for key in msg:
        if key != "type" and key not in allowed:
            raise ParameterError(f"{kind}.{key}", msg[key],
                                 "no such field (allowed: " + (", ".join(allowed) or "none")
                                 + ")")
    for key in required:
        if key not in msg:
            raise ParameterError(f"{kind}.{key}", None, "a value (required)")


def _number(name: str, value: Any, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(name, value, f"a finite number >= {lo:g} and <= {hi:g}")
    return check_range(name, value, lo, hi)


def _gaze(msg: dict) -> dict:
    _fields(msg, "gaze", ("x", "y", "seq"), ("x", "y"))
    return {"x": _number("gaze.x", msg["x"], -1.0, 2.0),
            "y": _number("gaze.y", msg["y"], -1.0, 2.0),
            "seq": check_int("gaze.seq", msg.get("seq", 0), 0, 2 ** 53)}


def _lock(msg: dict) -> dict:
    _fields(msg, "lock", ("on",), ("on",))
    return {"on": check_bool("lock.on", msg["on"])}


def _move(msg: dict) -> dict:
    keys = ("forward", "right", "up", "yaw", "pitch")
    _fields(msg, "move", keys)
    out = {}
    for k in keys:
        lim = 1.0 if k in ("forward", "right", "up") else 90.0
        out[k] = _number(f"move.{k}", msg.get(k, 0.0), -lim, lim)
    return out


def _home(msg: dict) -> dict:
    _fields(msg, "home", ())
    return {}


def _settings(msg: dict) -> dict:
    """Types only; the values are checked as the command line checks them
    (:meth:`foveated_mi.live.renderer.LiveRenderer.check_settings`)."""
    _fields(msg, "settings", SETTINGS)
    out = {k: msg[k] for k in SETTINGS if k in msg}
    if not out:
        raise ParameterError("settings", {}, "at least one of " + ", ".join(SETTINGS))
    for k in ("preset", "denoiser"):
        if k in out and not isinstance(out[k], str):
            raise ParameterError(k, out[k], "a string")
    # Numbers, as `--ray-budget` and `--fps` read them (float); the ranges are the options'.
    for k, allowed in (("ray_budget", "a finite number > 0 and <= 1"),
                       ("fps", "a finite number >= 0 and <= 1e+06")):
        if k not in out:
            continue
        v = out[k]
        if isinstance(v, str):
            try:
                v = float(v)
            except ValueError:
                raise ParameterError(k, v, allowed) from None
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ParameterError(k, v, allowed)
        out[k] = float(v)
    if "spp" in out:
        v = out["spp"]
        if isinstance(v, str):
            try:
                v = int(v)
            except ValueError:
                pass
        out["spp"] = check_int("--spp", v, 1, SPP_MAX)
    return out


def _view(msg: dict) -> dict:
    _fields(msg, "view", ("overlays", "split", "latency_ms"))
    out: dict[str, Any] = {}
    if "overlays" in msg:
        v = msg["overlays"]
        if not isinstance(v, list) or len(v) > len(OVERLAYS) or \
                any(not isinstance(o, str) or o not in OVERLAYS for o in v):
            raise ParameterError("view.overlays", v, "a list of " + ", ".join(
                repr(o) for o in OVERLAYS))
        out["overlays"] = tuple(o for o in OVERLAYS if o in v)
    if "split" in msg:
        if msg["split"] not in SPLITS:
            raise ParameterError("split", msg["split"], "one of " + ", ".join(
                repr(s) for s in SPLITS))
        out["split"] = msg["split"]
    if "latency_ms" in msg:
        out["latency_ms"] = _number("latency_ms", msg["latency_ms"], 0.0, LATENCY_MAX_MS)
    return out


def _gaze_source(msg: dict) -> dict:
    _fields(msg, "gaze_source", ("source", "csv", "name"), ("source",))
    if msg["source"] not in SOURCES:
        raise ParameterError("gaze_source", msg["source"], "one of " + ", ".join(
            repr(s) for s in SOURCES))
    out = {"source": msg["source"]}
    if msg["source"] == "csv":
        text, name = msg.get("csv"), msg.get("name", "gaze.csv")
        if not isinstance(text, str) or len(text.encode()) > MAX_CSV_BYTES:
            raise ParameterError("gaze_source.csv", None if text is None else "<text>",
                                 f"the text of a t,x,y CSV file of at most {MAX_CSV_BYTES} bytes")
        if not isinstance(name, str) or not name or len(name) > 200:
            raise ParameterError("gaze_source.name", name, "a file name of 1 to 200 characters")
        # A name for messages only: no path, no control characters.
        out["csv"] = text
        out["name"] = "".join(c for c in name.replace("\\", "/").split("/")[-1]
                              if c.isprintable()) or "gaze.csv"
    elif "csv" in msg or "name" in msg:
        raise ParameterError("gaze_source.csv", "<text>", "no CSV unless source = 'csv'")
    return out


def _record(msg: dict) -> dict:
    _fields(msg, "record", ("on",), ("on",))
    return {"on": check_bool("record.on", msg["on"])}


def _ack(msg: dict) -> dict:
    _fields(msg, "ack", ("frame",), ("frame",))
    return {"frame": check_int("ack.frame", msg["frame"], 0, 2 ** 53)}


_PARSERS = {"gaze": _gaze, "lock": _lock, "move": _move, "home": _home,
            "settings": _settings, "view": _view, "gaze_source": _gaze_source,
            "record": _record, "ack": _ack}
#: Every message type a page may send.
MESSAGE_TYPES = tuple(_PARSERS)


def parse(data: str | bytes) -> tuple[str, dict]:
    """``(type, fields)`` of one message, validated; raises :class:`ParameterError`."""
    if isinstance(data, (bytes, bytearray)):
        raise ParameterError("message", "<binary>", "a JSON text message")
    if len(data) > MAX_MESSAGE_BYTES:
        raise ParameterError("message", f"<{len(data)} characters>",
                             f"at most {MAX_MESSAGE_BYTES} characters")
    try:
        msg = json.loads(data, parse_constant=lambda c: math.nan)
    except (ValueError, RecursionError):
        raise ParameterError("message", data[:40], "a JSON object") from None
    if not isinstance(msg, dict):
        raise ParameterError("message", data[:40], "a JSON object")
    kind = msg.get("type")
    if kind not in _PARSERS:
        raise ParameterError("type", kind, "one of " + ", ".join(repr(t) for t in MESSAGE_TYPES))
    return kind, _PARSERS[kind](msg)
