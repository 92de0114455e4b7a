"""The eye tracker: the gaze a frame renders with is the eye's, ``latency_ms`` late and
jittered by ``noise_deg``.

One rule for every caller: a study's ``[viewer] gaze_latency_ms`` and ``gaze_noise_deg``, a
sequence's ``[viewer] gaze_latency_ms`` and the live view's latency all go through
:class:`EyeTracker`, so a frame at time ``t`` renders the gaze the eye had at
:meth:`EyeTracker.reported_at` ``(t)``. A latency of a whole number of frames takes that
earlier frame's gaze exactly (no rounding of times on the way); any other reads the gaze
path that much earlier; before the path starts, its first gaze holds.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from .validate import check_range

__all__ = ["EyeTracker", "LATENCY_MAX_MS", "NOISE_MAX_DEG"]

#: The longest latency accepted, in milliseconds.
LATENCY_MAX_MS = 1000.0
#: The largest jitter accepted, a Gaussian's standard deviation in degrees.
NOISE_MAX_DEG = 10.0
#: A latency within this many frames of a whole number is that number of frames.
_WHOLE_FRAME_TOL = 1e-9


@dataclass(frozen=True)
class EyeTracker:
    """An eye tracker's delay from eye to photon and its jitter.

    Parameters
    ----------
    latency_ms : float, optional
        How late the rendered gaze is, in [0, 1000] milliseconds.
    noise_deg : float, optional
        The jitter on the rendered gaze: a Gaussian's standard deviation, in [0, 10]
        degrees.

    Raises
    ------
    ParameterError
        A value out of range (one line naming ``latency_ms`` or ``noise_deg``).
    """
    latency_ms: float = 0.0
    noise_deg: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "latency_ms", check_range(
            "latency_ms", self.latency_ms, 0.0, LATENCY_MAX_MS))
        object.__setattr__(self, "noise_deg", check_range(
            "noise_deg", self.noise_deg, 0.0, NOISE_MAX_DEG))

    def reported_at(self, t: float) -> float:
        """The time (seconds) whose gaze a frame at ``t`` renders: ``latency_ms`` earlier."""
        return t - self.latency_ms / 1000.0

    def late_frame(self, k: int, fps: float) -> int | None:
        """The earlier frame whose gaze frame ``k`` renders when the latency is a whole
        number of frames at ``fps`` (frame 0 before the first); None otherwise."""
        shift = self.latency_ms * fps / 1000.0
        if abs(shift - round(shift)) >= _WHOLE_FRAME_TOL:
            return None
        return max(k - round(shift), 0)

    def frame_time(self, k: int, fps: float) -> float:
        """The time (seconds) whose gaze frame ``k`` at ``fps`` renders: exactly an earlier
        frame's (:meth:`late_frame`) where the latency is whole frames, else
        :meth:`reported_at`, never before 0."""
        j = self.late_frame(k, fps)
        return j / fps if j is not None else max(self.reported_at(k / fps), 0.0)

    def frames(self, gazes: Sequence, at: Callable[[float], Any] | None, fps: float) -> list:
        """The gaze each frame renders with.

        Parameters
        ----------
        gazes : sequence
            The eye's gaze of each frame (frame ``k`` at ``k / fps`` seconds).
        at : callable or None
            The gaze at a time in seconds (the path ``gazes`` were read from); None for a
            gaze that does not move.
        fps : float
            Frames per second.

        Returns
        -------
        rendered : list
            A whole number of frames late: that earlier frame's entry of ``gazes`` itself;
            otherwise ``at`` the earlier time (the first gaze before the path starts).
        """
        if self.late_frame(0, fps) is not None:
            return [gazes[self.late_frame(k, fps)] for k in range(len(gazes))]
        if at is None:                            # a still gaze: late or not, the same
            return list(gazes)
        return [at(max(self.reported_at(k / fps), 0.0)) for k in range(len(gazes))]

    def jittered(self, gazes: Sequence, pixels_per_degree: Callable[[tuple], float],
                 size: tuple[int, int], seed: int) -> list:
        """``gazes`` jittered by a Gaussian of ``noise_deg`` degrees, kept on the film.

        Parameters
        ----------
        gazes : sequence of pair of float
            Normalised film positions, one per frame.
        pixels_per_degree : callable
            Pixels per degree at a gaze (a tuple), asked once per distinct gaze.
        size : tuple of int
            The film's ``(width, height)`` in pixels.
        seed : int
            The draw's seed: the same seed, the same jitter.

        Returns
        -------
        gazes : list of list of float
            ``gazes`` itself without noise.
        """
        if self.noise_deg <= 0.0:
            return gazes
        w, h = size
        rng = np.random.default_rng([int(seed), 0x6A5E])
        out, ppd = [], {}
        for g in gazes:
            key = tuple(g)
            if key not in ppd:                    # a fixation holds one gaze for many frames
                ppd[key] = pixels_per_degree(key)
            dx, dy = rng.normal(0.0, self.noise_deg * ppd[key], 2)
            out.append([min(max(g[0] + dx / w, 0.0), 1.0), min(max(g[1] + dy / h, 0.0), 1.0)])
        return out
