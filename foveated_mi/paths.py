"""Camera and gaze paths of a frame sequence, evaluated at a time ``t`` in seconds.

Every path has ``at(t)`` and ``at_frame(index, fps) = at(index / fps)``. Before the first and
after the last keyframe a path holds its end value.

Camera (:class:`CameraPath`): keyframes ``{"t", "origin", "target", "up", "fov", "yaw"}``
interpolated component-wise (``up`` re-normalised) with

* ``"linear"``: :math:`p(t) = (1 - s) p_i + s p_{i+1}`, :math:`s = (t - t_i)/(t_{i+1} - t_i)`;
* ``"catmull_rom"``: cubic Hermite segments with finite-difference (Catmull-Rom) tangents
  for non-uniform keyframe times, :math:`m_k = (p_{k+1} - p_{k-1}) / (t_{k+1} - t_{k-1})`,
  one-sided differences at the ends of a shot (Catmull & Rom 1974; the "finite
  difference" tangents of cubic Hermite splines). The path passes through every keyframe
  and its velocity is continuous inside a shot;
* ``"step"``: the value of the last keyframe at or before ``t`` (every keyframe is a cut).

A **cut** (the camera jumps, the runner should drop the temporal history) is a segment whose
second keyframe has ``"cut": true``, or whose two keyframes are less than ``cut_threshold``
seconds apart (default 1 ms; two keyframes at the same time are always a cut), or any
segment under ``"step"``. From the cut's time on, the second keyframe's value holds.

``yaw`` (degrees, default 0) turns the view about the keyframe's ``up`` axis, positive to the
right, after interpolation: a head turning at a constant rate is two keyframes with linear
interpolation, whatever the scene's own camera (which fills ``origin``, ``target``, ``up``).
A keyframe that leaves out ``target`` looks at the scene camera's target: a built-in scene's
is what its camera looks at, an XML scene's is one unit ahead of its camera (the file names
no distance), so a keyframe that moves an XML scene's camera far should give ``target`` too.
:meth:`CameraPath.cut_between` tells whether a cut lies in ``(t0, t1]``.

Gaze, in normalised film coordinates (origin top-left, x right, y down; values outside
[0, 1] mean the viewer looks off-screen): :class:`FixedGaze`, :class:`GazeKeyframes` (the
same three interpolations), :class:`Saccades` (fixations of ``dwell`` seconds joined by
saccades of ``duration`` seconds with a minimum-jerk profile, Flash & Hogan 1985, a fair
model of the bell-shaped velocity of a saccade) and :class:`GazeCSV` (``t,x,y`` samples as an
eye tracker writes them, linearly interpolated).
"""
from __future__ import annotations

import math
import os
from typing import Any, Sequence

import numpy as np

from .validate import ParameterError, check_choice, check_finite, check_range

__all__ = ["INTERPOLATIONS", "CameraPath", "GazePath", "FixedGaze", "GazeKeyframes",
           "Saccades", "GazeCSV", "BinocularGazeCSV", "off_centre_targets", "lens_centre"]

INTERPOLATIONS = ("linear", "catmull_rom", "step")
_CAMERA_KEYS = ("origin", "target", "up", "fov")


# ---------------------------------------------------------------------------------------------
# Piecewise interpolation shared by camera and gaze keyframes
# ---------------------------------------------------------------------------------------------

class _Keyframes:
    """Values ``v[k]`` (K, D) at non-decreasing times ``t[k]`` with cuts before some keys.

    ``cut[k]`` (k >= 1) means no interpolation from key k-1 to key k: the value jumps at
    ``t[k]``. Tangents for Catmull-Rom never reach across a cut.
    """

    def __init__(self, times: np.ndarray, values: np.ndarray, cut: np.ndarray,
                 interpolation: str):
        self.t, self.v = times, values
        self.cut = cut.copy()
        self.cut[0] = False
        if interpolation == "step":
            self.cut[1:] = True
        self.interpolation = interpolation
        self.m = self._tangents() if interpolation == "catmull_rom" else None

    def _tangents(self) -> np.ndarray:
        t, v, cut = self.t, self.v, self.cut
        k_count = len(t)
        m = np.zeros_like(v)
        for k in range(k_count):
            has_prev = k > 0 and not cut[k]
            has_next = k + 1 < k_count and not cut[k + 1]
            if has_prev and has_next:
                m[k] = (v[k + 1] - v[k - 1]) / (t[k + 1] - t[k - 1])
            elif has_next:
                m[k] = (v[k + 1] - v[k]) / (t[k + 1] - t[k])
            elif has_prev:
                m[k] = (v[k] - v[k - 1]) / (t[k] - t[k - 1])
        return m

    def cut_times(self) -> list[float]:
        return [float(self.t[k]) for k in range(1, len(self.t)) if self.cut[k]]

    def __call__(self, time: float) -> np.ndarray:
        t, v = self.t, self.v
        k = int(np.searchsorted(t, time, side="right"))   # keys at or before ``time``
        if k == 0:
            return v[0].copy()
        if k == len(t):
            return v[-1].copy()
        i, j = k - 1, k
        if self.cut[j]:
            return v[i].copy()
        dt = t[j] - t[i]
        s = (time - t[i]) / dt
        if self.interpolation == "linear":
            return (1.0 - s) * v[i] + s * v[j]
        # Cubic Hermite basis.
        s2, s3 = s * s, s * s * s
        h00 = 2 * s3 - 3 * s2 + 1
        h10 = s3 - 2 * s2 + s
        h01 = -2 * s3 + 3 * s2
        h11 = s3 - s2
        return h00 * v[i] + h10 * dt * self.m[i] + h01 * v[j] + h11 * dt * self.m[j]


def _rotate(d: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """``d`` rotated by ``angle`` (radians, right-handed) about the unit ``axis`` (Rodrigues)."""
    c, s = math.cos(angle), math.sin(angle)
    return d * c + np.cross(axis, d) * s + axis * float(np.dot(axis, d)) * (1.0 - c)


def _check_time(name: str, value: Any) -> float:
    return check_finite(name, value)


def _check_times(name: str, times: list[float]) -> None:
    for k in range(1, len(times)):
        if times[k] < times[k - 1]:
            raise ParameterError(f"{name}[{k}].t", times[k],
                                 f"a time >= {times[k - 1]:g} (keyframes in time order)")


def _check_vec(name: str, value: Any, n: int) -> list[float]:
    allowed = f"{n} finite numbers"
    if isinstance(value, (str, bytes, dict)):
        raise ParameterError(name, value, allowed)
    try:
        v = [float(c) for c in value]
    except (TypeError, ValueError):
        raise ParameterError(name, value, allowed) from None
    if len(v) != n or not all(math.isfinite(c) for c in v):
        raise ParameterError(name, value, allowed)
    return v


def _check_bool(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ParameterError(name, value, "true or false")
    return value


class _Path:
    """Base of camera and gaze paths: ``at(t)`` and ``at_frame(index, fps)``."""

    def at(self, t: float):  # pragma: no cover - abstract
        raise NotImplementedError

    def at_frame(self, index: int, fps: float):
        """Value at frame ``index`` of a sequence at ``fps`` frames per second."""
        fps = check_range("fps", fps, 0.0, None, lo_open=True)
        return self.at(index / fps)


# ---------------------------------------------------------------------------------------------
# Camera
# ---------------------------------------------------------------------------------------------

class CameraPath(_Path):
    """Camera keyframes, interpolated (see the module docs).

    ``keyframes``: a list of dicts with ``t`` (seconds) and any of ``origin``, ``target``,
    ``up`` (3 numbers each), ``fov`` (degrees along x) and ``cut`` (bool); keys left out are
    taken from ``defaults`` (a camera dict, e.g. :func:`foveated_mi.scenes.scene_camera`),
    and are required when there are no defaults. ``name`` prefixes error messages.
    """

    def __init__(self, keyframes: Sequence[dict], interpolation: str = "linear", *,
                 defaults: dict | None = None, cut_threshold: float = 1e-3,
                 name: str = "camera"):
        self.name = name
        self.interpolation = check_choice(f"{name}.interpolation", interpolation,
                                          INTERPOLATIONS)
        self.cut_threshold = check_range(f"{name}.cut_threshold", cut_threshold, 0.0)
        kname = f"{name}.keyframes"
        if isinstance(keyframes, (str, bytes, dict)) or not hasattr(keyframes, "__len__") \
                or len(keyframes) == 0:
            raise ParameterError(kname, keyframes, "a non-empty list of keyframe tables")
        if defaults is not None:
            from .scenes import check_camera
            defaults = check_camera(defaults, f"{name}.defaults")
        self.keyframes: list[dict] = []
        for k, kf in enumerate(keyframes):
            self.keyframes.append(self._check_keyframe(f"{kname}[{k}]", kf, defaults))
        times = [kf["t"] for kf in self.keyframes]
        _check_times(kname, times)
        t = np.array(times, dtype=np.float64)
        values = np.array([kf["origin"] + kf["target"] + kf["up"] + [kf["fov"], kf["yaw"]]
                           for kf in self.keyframes], dtype=np.float64)
        cut = np.array([False] + [self.keyframes[k]["cut"]
                                  or t[k] - t[k - 1] < max(self.cut_threshold, 1e-12)
                                  for k in range(1, len(t))], dtype=bool)
        self._keys = _Keyframes(t, values, cut, self.interpolation)

    @staticmethod
    def _check_keyframe(name: str, kf: Any, defaults: dict | None) -> dict:
        if not isinstance(kf, dict):
            raise ParameterError(name, kf, "a table with t, origin, target, up, fov, yaw")
        allowed = ("t", "cut", "yaw") + _CAMERA_KEYS
        for key in kf:
            if key not in allowed:
                raise ParameterError(f"{name}.{key}", kf[key],
                                     "a keyframe key among " + ", ".join(allowed))
        if "t" not in kf:
            raise ParameterError(f"{name}.t", None, "a time in seconds (required)")
        out: dict[str, Any] = {"t": _check_time(f"{name}.t", kf["t"]),
                               "cut": _check_bool(f"{name}.cut", kf.get("cut", False)),
                               "yaw": check_range(f"{name}.yaw", kf.get("yaw", 0.0), -3600.0,
                                                  3600.0)}
        for key in _CAMERA_KEYS:
            if key in kf:
                value = kf[key]
            elif defaults is not None:
                value = defaults[key]
            else:
                raise ParameterError(f"{name}.{key}", None,
                                     "a value (required: the scene's camera is unknown)")
            if key == "fov":
                out[key] = check_range(f"{name}.fov", value, 0.0, 180.0, lo_open=True,
                                       hi_open=True)
            else:
                out[key] = _check_vec(f"{name}.{key}", value, 3)
        from .scenes import check_camera
        check_camera({k: out[k] for k in _CAMERA_KEYS}, name)
        return out

    @classmethod
    def static(cls, camera: dict, name: str = "camera") -> "CameraPath":
        """A camera that never moves."""
        return cls([{"t": 0.0, **{k: camera[k] for k in _CAMERA_KEYS if k in camera}}],
                   name=name)

    @property
    def duration(self) -> float:
        """Time of the last keyframe."""
        return float(self._keys.t[-1])

    @property
    def cut_times(self) -> list[float]:
        """Times at which the camera jumps."""
        return self._keys.cut_times()

    def cut_between(self, t0: float, t1: float) -> bool:
        """Whether a cut lies in the half-open interval ``(t0, t1]``."""
        return any(t0 < c <= t1 for c in self.cut_times)

    def at(self, t: float) -> dict[str, Any]:
        """``dict(origin, target, up, fov)`` at time ``t`` (lists of floats, fov a float)."""
        t = _check_time("t", t)
        v = self._keys(t)
        origin, target, up = v[0:3], v[3:6], v[6:9]
        n = float(np.linalg.norm(up))
        if n > 0:
            up = up / n
        if v[10] != 0.0:          # the head turned right by yaw about its up axis
            target = origin + _rotate(target - origin, up, -math.radians(v[10]))
        return dict(origin=[float(c) for c in origin], target=[float(c) for c in target],
                    up=[float(c) for c in up], fov=float(v[9]))


# ---------------------------------------------------------------------------------------------
# Gaze
# ---------------------------------------------------------------------------------------------

class GazePath(_Path):
    """Base class of gaze paths: ``at(t) -> (x, y)`` in normalised film coordinates."""

    def at(self, t: float) -> tuple[float, float]:  # pragma: no cover - abstract
        raise NotImplementedError


class FixedGaze(GazePath):
    """The viewer looks at ``(x, y)`` all the time."""

    def __init__(self, x: float = 0.5, y: float = 0.5, *, name: str = "gaze"):
        self.x = check_finite(f"{name}.x", x)
        self.y = check_finite(f"{name}.y", y)

    def at(self, t: float) -> tuple[float, float]:
        _check_time("t", t)
        return (self.x, self.y)


class GazeKeyframes(GazePath):
    """Gaze keyframes ``{"t", "x", "y"}`` (or ``[t, x, y]``), interpolated like the camera."""

    def __init__(self, keyframes: Sequence[Any], interpolation: str = "linear", *,
                 name: str = "gaze"):
        self.interpolation = check_choice(f"{name}.interpolation", interpolation,
                                          INTERPOLATIONS)
        kname = f"{name}.keyframes"
        if isinstance(keyframes, (str, bytes, dict)) or not hasattr(keyframes, "__len__") \
                or len(keyframes) == 0:
            raise ParameterError(kname, keyframes, "a non-empty list of {t, x, y} keyframes")
        rows = []
        for k, kf in enumerate(keyframes):
            kn = f"{kname}[{k}]"
            if isinstance(kf, dict):
                for key in kf:
                    if key not in ("t", "x", "y"):
                        raise ParameterError(f"{kn}.{key}", kf[key], "one of the keys t, x, y")
                for key in ("t", "x", "y"):
                    if key not in kf:
                        raise ParameterError(f"{kn}.{key}", None, "a finite number (required)")
                rows.append([check_finite(f"{kn}.{key}", kf[key]) for key in ("t", "x", "y")])
            else:
                rows.append(_check_vec(kn, kf, 3))
        times = [r[0] for r in rows]
        _check_times(kname, times)
        t = np.array(times, dtype=np.float64)
        cut = np.concatenate([[False], np.diff(t) <= 0.0])
        self._keys = _Keyframes(t, np.array([r[1:] for r in rows], dtype=np.float64), cut,
                                self.interpolation)

    def at(self, t: float) -> tuple[float, float]:
        v = self._keys(_check_time("t", t))
        return (float(v[0]), float(v[1]))


def _minimum_jerk(s: float) -> float:
    """Position profile 10 s^3 - 15 s^4 + 6 s^5 of a minimum-jerk movement (Flash & Hogan)."""
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


class Saccades(GazePath):
    """Fixations on ``targets`` in turn, ``dwell`` seconds each, joined by saccades.

    Fixation ``k`` covers ``[k P, k P + dwell)`` with period ``P = dwell + duration``; the
    saccade to the next target takes ``duration`` seconds (0: an instant jump) along a
    straight line with the minimum-jerk profile. After the last target the gaze returns to
    the first (``loop=True``) or stays (``loop=False``). Real saccades last 20-100 ms and
    fixations 200-400 ms (Rayner 1998), hence the defaults.
    """

    def __init__(self, targets: Sequence[Any], dwell: float = 0.3, duration: float = 0.05,
                 loop: bool = True, *, name: str = "gaze"):
        if isinstance(targets, (str, bytes, dict)) or not hasattr(targets, "__len__") \
                or len(targets) == 0:
            raise ParameterError(f"{name}.targets", targets, "a non-empty list of [x, y] points")
        self.targets = [tuple(_check_vec(f"{name}.targets[{k}]", p, 2))
                        for k, p in enumerate(targets)]
        self.dwell = check_range(f"{name}.dwell", dwell, 0.0, None, lo_open=True)
        self.duration = check_range(f"{name}.duration", duration, 0.0)
        self.loop = _check_bool(f"{name}.loop", loop)

    @property
    def period(self) -> float:
        return self.dwell + self.duration

    def phase(self, t: float) -> tuple[str, int]:
        """``("fixation", k)`` while fixating target ``k``, ``("saccade", k)`` on the way
        from target ``k`` to the next."""
        t = max(_check_time("t", t), 0.0)
        n = len(self.targets)
        k = int(t // self.period)
        if not self.loop and k >= n - 1:
            return ("fixation", n - 1)
        k_target = k % n
        if t - k * self.period < self.dwell:
            return ("fixation", k_target)
        return ("saccade", k_target)

    def at(self, t: float) -> tuple[float, float]:
        t = max(_check_time("t", t), 0.0)
        state, k = self.phase(t)
        a = self.targets[k]
        if state == "fixation":
            return (float(a[0]), float(a[1]))
        b = self.targets[(k + 1) % len(self.targets)]
        s = (t - (t // self.period) * self.period - self.dwell) / self.duration
        w = _minimum_jerk(min(max(s, 0.0), 1.0))
        return (float(a[0] + w * (b[0] - a[0])), float(a[1] + w * (b[1] - a[1])))


def off_centre_targets(eccentricity_deg: Any, count: Any, seed: Any, camera: dict,
                       size: Sequence[int], *, name: str = "gaze") -> list[tuple[float, float]]:
    """Saccade targets off the lens centre: ``count`` fixations at eccentricities drawn
    uniformly in ``eccentricity_deg`` and directions uniform around the optical axis,
    seeded, as normalised film positions of a pinhole ``camera`` (clamped inside the film).

    A direction at eccentricity ``e`` and angle ``phi`` from the axis meets the image plane
    ``tan(e)`` from the axis; the film spans ``2 tan(fov / 2)`` across (the camera's
    horizontal field of view) and ``height / width`` of that down, with the axis at
    ``0.5 - principal_point`` (an off-axis frustum's, as a headset eye has).

    Parameters
    ----------
    eccentricity_deg : pair of float
        ``[lo, hi]`` degrees from the lens centre, ``0 <= lo <= hi < 90``.
    count : int
        The number of fixations (>= 1).
    seed : int
        Seed of the draw (NumPy), in [0, 2^32).
    camera : dict
        The pinhole camera: ``fov`` (degrees along x) and optionally ``principal_point``.
    size : pair of int
        The film's ``(width, height)``.
    name : str, optional
        The path's name, for error messages (``{name}.off_centre_deg``, ...).

    Returns
    -------
    targets : list of tuple of float
        ``count`` film positions (x right, y down, origin top-left).
    """
    from .validate import check_int
    allowed = "[lo, hi] degrees from the lens centre with 0 <= lo <= hi < 90"
    try:
        rng_deg = _check_vec(f"{name}.off_centre_deg", eccentricity_deg, 2)
    except ParameterError:
        raise ParameterError(f"{name}.off_centre_deg", eccentricity_deg, allowed) from None
    if not 0.0 <= rng_deg[0] <= rng_deg[1] < 90.0:
        raise ParameterError(f"{name}.off_centre_deg", eccentricity_deg, allowed)
    count = check_int(f"{name}.count", count, 1, 100000)
    seed = check_int(f"{name}.seed", seed, 0, 2**32 - 1)
    tx = math.tan(math.radians(float(camera["fov"])) / 2.0) * 2.0      # film width, tangents
    ty = tx * size[1] / size[0]                                        # square pixels
    px, py = camera.get("principal_point", (0.0, 0.0))
    rng = np.random.default_rng(seed)
    ecc = np.radians(rng.uniform(rng_deg[0], rng_deg[1], count))
    phi = rng.uniform(0.0, 2.0 * math.pi, count)
    r = np.tan(ecc)
    x = np.clip(0.5 - px + r * np.cos(phi) / tx, 0.0, 1.0)
    y = np.clip(0.5 - py + r * np.sin(phi) / ty, 0.0, 1.0)
    return [(float(a), float(b)) for a, b in zip(x, y)]


def lens_centre(sensor) -> tuple[float, float]:
    """Where a pinhole sensor's optical axis meets its film, as a normalised film position:
    the gaze of fixed foveation (a headset without an eye tracker puts its density there).
    The film's centre for a centred frustum; an off-axis one's axis
    (:attr:`foveated_mi.stereo.Frustum.axis`), measured from the sensor's own rays.

    Parameters
    ----------
    sensor : mi.Sensor
        A ``perspective`` sensor.

    Returns
    -------
    centre : tuple of float
        ``(x, y)``, origin top-left.
    """
    from .stereo import frustum_of
    return frustum_of(sensor).axis


class GazeCSV(GazePath):
    """Gaze samples from a CSV file of ``t,x,y`` lines (seconds, normalised film coordinates).

    An optional header line (any first line that is not three numbers) is skipped, as are
    blank lines and lines starting with ``#``. Timestamps must increase strictly; every value
    must be finite (an eye tracker's lost samples must be removed, not written as NaN).
    ``relative=True`` subtracts the first timestamp (for trackers writing absolute times).
    Between samples the gaze is interpolated (``"linear"``, or ``"step"`` for the raw
    samples); before the first and after the last it holds.
    """

    ALLOWED_LINE = "a line 't,x,y' of three comma-separated finite numbers"
    #: What the file must be, for the error of a missing one.
    FILE = "an existing CSV file of t,x,y lines"

    def __init__(self, path: str | os.PathLike, interpolation: str = "linear", *,
                 relative: bool = False, name: str = "gaze"):
        self.interpolation = check_choice(f"{name}.interpolation", interpolation,
                                          ("linear", "step"))
        self.relative = _check_bool(f"{name}.relative", relative)
        if not isinstance(path, (str, os.PathLike)) or not os.path.isfile(path):
            raise ParameterError(f"{name}.path", path if isinstance(path, str) else str(path),
                                 self.FILE)
        self.path = os.fspath(path)
        rows, lines = self._read()
        t = np.array([r[0] for r in rows], dtype=np.float64)
        if self.relative:
            t = t - t[0]
        self.times = t
        self.samples = np.array([r[1:] for r in rows], dtype=np.float64)
        self.lines = lines
        self._keys = _Keyframes(t, self.samples, np.zeros(len(t), dtype=bool),
                                self.interpolation)

    def _read(self) -> tuple[list[list[float]], list[int]]:
        rows: list[list[float]] = []
        lines: list[int] = []
        first_content = True
        last_line = 0
        try:
            with open(self.path, encoding="utf-8-sig") as f:
                text = f.read()
        except (OSError, UnicodeDecodeError) as e:
            raise ParameterError(self.path, type(e).__name__,
                                 "a readable UTF-8 CSV file of t,x,y lines") from None
        for lineno, raw in enumerate(text.splitlines(), start=1):
            last_line = lineno
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            where = f"{self.path}:{lineno}"
            fields = [p.strip() for p in line.split(",")]
            values = []
            for p in fields:
                try:
                    values.append(float(p))
                except ValueError:
                    values = None
                    break
            if values is None or len(fields) != 3:
                if first_content and values is None:
                    first_content = False        # a header line
                    continue
                raise ParameterError(where, line, self.ALLOWED_LINE)
            first_content = False
            if not all(math.isfinite(v) for v in values):
                raise ParameterError(where, line, "finite numbers t,x,y (no NaN or inf)")
            if rows and values[0] <= rows[-1][0]:
                raise ParameterError(where, line, f"a timestamp > {rows[-1][0]:g} "
                                     f"(line {lines[-1]}): timestamps must increase")
            rows.append(values)
            lines.append(lineno)
        if not rows:
            raise ParameterError(f"{self.path}:{max(last_line, 1)}", text[:40] if text else "",
                                 "at least one " + self.ALLOWED_LINE + " (the file has no "
                                 "samples)")
        return rows, lines

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def at(self, t: float) -> tuple[float, float]:
        v = self._keys(_check_time("t", t))
        return (float(v[0]), float(v[1]))


class BinocularGazeCSV(GazeCSV):
    """Each eye's gaze from a CSV file whose header names the columns ``t``, ``left_x``,
    ``left_y``, ``right_x`` and ``right_y`` (any order; other columns are ignored): seconds,
    and each eye's gaze in normalised coordinates of that eye's film.

    :meth:`eyes_at` gives both eyes' gazes; :meth:`at`, their mean (the gaze of a single
    view between the eyes, for a study of one eye). Timestamps, finiteness, ``relative`` and
    the interpolation are as :class:`GazeCSV`'s.
    """

    COLUMNS = ("t", "left_x", "left_y", "right_x", "right_y")
    FILE = "an existing CSV file with columns " + ",".join(COLUMNS)

    def _read(self) -> tuple[list[list[float]], list[int]]:
        import csv
        try:
            with open(self.path, encoding="utf-8-sig", newline="") as f:
                lines = [(n, row) for n, row in enumerate(csv.reader(f), start=1)
                         if row and not row[0].strip().startswith("#")]
        except (OSError, UnicodeDecodeError, csv.Error) as e:
            raise ParameterError(self.path, type(e).__name__, "a readable UTF-8 CSV file with "
                                 "columns " + ",".join(self.COLUMNS)) from None
        header = [c.strip() for c in lines[0][1]] if lines else []
        missing = [c for c in self.COLUMNS if c not in header]
        if missing:
            raise ParameterError(f"{self.path}:{lines[0][0] if lines else 1}",
                                 ",".join(header)[:60], "a header naming the columns "
                                 + ",".join(self.COLUMNS) + " (a binocular gaze: each eye's)")
        index = [header.index(c) for c in self.COLUMNS]
        rows, numbers = [], []
        for n, row in lines[1:]:
            try:
                values = [float(row[i]) for i in index]
            except (ValueError, IndexError):
                values = None
            if values is None or not all(math.isfinite(x) for x in values):
                raise ParameterError(f"{self.path}:{n}", ",".join(row), "finite numbers in "
                                     "the columns " + ",".join(self.COLUMNS))
            if rows and values[0] <= rows[-1][0]:
                raise ParameterError(f"{self.path}:{n}", ",".join(row), f"a timestamp > "
                                     f"{rows[-1][0]:g}: timestamps must increase")
            rows.append(values)
            numbers.append(n)
        if not rows:
            raise ParameterError(self.path, "no samples", "at least one line of "
                                 + ",".join(self.COLUMNS))
        return rows, numbers

    def eyes_at(self, t: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """Both eyes' gazes at ``t`` seconds: ``((left_x, left_y), (right_x, right_y))``."""
        v = self._keys(_check_time("t", t))
        return (float(v[0]), float(v[1])), (float(v[2]), float(v[3]))

    def at(self, t: float) -> tuple[float, float]:
        (lx, ly), (rx, ry) = self.eyes_at(t)
        return 0.5 * (lx + rx), 0.5 * (ly + ry)
