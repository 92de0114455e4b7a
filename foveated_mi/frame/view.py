"""Views: what one integrator keeps per view of the scene (an eye of a headset, a camera).

A scene may hold several sensors; the foveated integrator renders each as a view of its own.
:class:`View` holds what a view carries from frame to frame: its gaze, its planner (the
history, the frame count, the G-buffer and sampling caches) and its last frame (the outputs,
and the primal frame a gradient pass differentiates). Views never read each other's state, so
two views rendered by one integrator, frames alternating, each give what an integrator of its
own would give, bit for bit (``tests/test_views.py``), unless one is told to reuse the
other's samples (its planner's ``partner``: the second eye of
:class:`foveated_mi.stereo.Stereo`). The recordings of the replayed passes
(:mod:`.trace`, :mod:`.formation`) are shared: they key on the configuration and the film
size, never on a view.

A render with ``sensor = i`` (or the scene's ``i``-th sensor object, as ``mi.render`` passes
it) is view ``i``; a sensor that is not one of the scene's is view 0. The integrator's
``gaze`` option is the gaze of every view that has none of its own (view 0 by default):
``integrator.views[1].gaze = (x, y)`` gives view 1 its own.
"""
from __future__ import annotations

from typing import Any

import mitsuba as mi

from ..validate import ParameterError, check_int, check_point2
from .outputs import FrameOutputs
from .plan import Planner
from .reproject import History


class Hidden:
    """A value out of reach of Dr.Jit's traversal of the integrator. The scene holds its
    integrator, and a frozen function that takes the scene (the trace pass) traverses a
    Python plugin's attributes, dataclasses included: a view's last frame would become that
    function's input."""
    __slots__ = ("value",)

    def __init__(self, value=None):
        self.value = value


class View:
    """One view's state across frames (module docstring)."""

    def __init__(self, index: int):
        self.index = index
        self.planner = Planner()                 #: history, frame count, caches
        self._gaze: tuple[float, float] | None = None
        self._held: tuple[float, float] | None = None   # the gaze frames render (a hold)
        self._landing = False         # the last frame's gaze left the hold: a saccade
        self._last = Hidden()                    # the last primal frame (gradient pass)
        self.outputs = FrameOutputs({}, {}, {})  #: the last frame's buffers and stats

    @property
    def gaze(self) -> tuple[float, float] | None:
        """This view's own gaze (normalised film position), or None: the integrator's
        ``gaze`` option."""
        return self._gaze

    @gaze.setter
    def gaze(self, value) -> None:
        self._gaze = None if value is None else check_point2(f"views[{self.index}].gaze", value)

    @property
    def primal(self):
        """The last primal frame (:class:`~.gradient.PrimalFrame`), or None."""
        return self._last.value

    @primal.setter
    def primal(self, frame) -> None:
        self._last.value = frame

    def held_gaze(self, gaze, hold_px: float, width: int, height: int,
                  commit: bool = True) -> tuple[float, float]:
        """The gaze this view's frame renders under ``gaze_hold_deg``: the one it rendered
        last while ``gaze`` (the tracker's) lies within ``hold_px`` film pixels of it, else
        ``gaze``, which is then held. A tracker's jitter then moves neither the samples nor
        the disc, so a fixation is a still view; a saccade moves them at once, and the
        frame after it renders its landing (a gaze within the hold of the saccade's last
        one) rather than holding a point of its flight.

        Parameters
        ----------
        gaze : tuple of float
            The tracked gaze, a normalised film position.
        hold_px : float
            The hold's radius in film pixels (0: every gaze is rendered as it comes).
        width, height : int
            The film's size.
        commit : bool, optional
            Hold what it returns (False: the gaze a frame would render, the hold unchanged).

        Returns
        -------
        gaze : tuple of float
            The gaze to render.
        """
        g, h = (float(gaze[0]), float(gaze[1])), self._held
        inside = h is not None and \
            ((g[0] - h[0]) * width) ** 2 + ((g[1] - h[1]) * height) ** 2 <= hold_px * hold_px
        if inside and not self._landing:
            return h
        if commit:
            self._held, self._landing = g, h is not None and not inside
        return g

    def reset(self) -> None:
        """Forget the history (this view's next frame starts fresh, as frame 0) and the
        gaze it held."""
        self.planner.reset()
        self._held, self._landing = None, False

    @property
    def frame(self) -> int:
        """Frames rendered in this view since its last reset."""
        return self.planner.index

    @property
    def history(self) -> History | None:
        """The history this view's next frame reads (None before the first frame or after a
        reset)."""
        return self.planner.history

    @property
    def stats(self) -> dict[str, Any]:
        """Stats of this view's last frame (reading them synchronises)."""
        return self.outputs.stats

    @property
    def buffers(self) -> dict[str, Any]:
        """This view's last frame's named buffers."""
        return self.outputs.buffers

    def buffer(self, name: str):
        """A buffer of this view's last frame as a NumPy array (see the integrator's).

        Parameters
        ----------
        name : str
            The buffer's name.

        Returns
        -------
        array : numpy.ndarray or None
            As :meth:`~.outputs.FrameOutputs.export`.
        """
        return self.outputs.export(name)


class Views:
    """The integrator's views, made as they are first addressed (``views[i]``, ``i >= 0``)."""

    def __init__(self):
        self._views: list[View] = [View(0)]
        # (sensor, view) pairs bound by bind(), out of reach of a frozen function's traversal
        self._bound = Hidden([])

    def __getitem__(self, index: int) -> View:
        if isinstance(index, (str, bytes, bool)):      # check_int would take "1"
            raise ParameterError("view", index, "an integer >= 0 and <= 1023")
        index = check_int("view", index, 0, 1023)
        while len(self._views) <= index:
            self._views.append(View(len(self._views)))
        return self._views[index]

    def __len__(self) -> int:
        return len(self._views)

    def __iter__(self):
        return iter(self._views)

    def bind(self, sensor: mi.Sensor, index: int) -> View:
        """Render ``sensor``, which need not be one of the scene's, as view ``index`` (an eye
        of :class:`foveated_mi.stereo.Stereo`).

        Parameters
        ----------
        sensor : mi.Sensor
            The sensor.
        index : int
            The view.

        Returns
        -------
        view : View
            The view (made on first use).
        """
        view = self[index]
        pairs = [(s, i) for s, i in self._bound.value if s is not sensor]
        self._bound.value = pairs + [(sensor, index)]
        return view

    def of(self, scene: mi.Scene, sensor: mi.Sensor) -> View:
        """The view that renders ``sensor``: the one it is bound to (:meth:`bind`), else its
        index among the scene's sensors, else 0.

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        sensor : mi.Sensor
            The sensor rendered.

        Returns
        -------
        view : View
            The view (made on first use).
        """
        for s, i in self._bound.value:
            if s is sensor:
                return self[i]
        for i, s in enumerate(scene.sensors()):
            if s is sensor:
                return self[i]
        return self[0]

