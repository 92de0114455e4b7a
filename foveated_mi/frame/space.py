"""Sample spaces: where a frame keeps its traced values, its geometry and its history.

A frame's shading buffer, G-buffer, reprojection map and history live either on the film's
pixels (:class:`FilmSpace`) or on the foveal buffer's samples (:class:`BufferSpace`: the
log-polar cells and the disc's pixels, :mod:`.buffer_space`). A formation declares which
space it forms from (:func:`~.formation.register_formation`'s ``space``); the plan makes that
space by the space's own route (:data:`.plan.PLAN_ROUTES`: :mod:`.film_plan`,
:mod:`.buffer_plan`) and every pass after it asks the space (the interface
:class:`SampleSpace`), never which formation or law ran:

- :meth:`~SampleSpace.develop_at`: where the trace pass develops the rays' estimates
  (:func:`~.shading.develop`);
- :meth:`~SampleSpace.traced_pixels`, :meth:`~SampleSpace.to_pixels`,
  :meth:`~SampleSpace.from_pixels`: the film's traced pixels, and a gradient summed onto them
  from the samples or a tangent read back at the samples (the gradient pass's seam);
- :meth:`~SampleSpace.still_map`, :meth:`~SampleSpace.reprojection_map`: the history's map;
- :meth:`~SampleSpace.history`: the history a frame leaves on the space;
- :attr:`~SampleSpace.layout`: what the history records of the space's layout.

A space's device arrays (:meth:`~SampleSpace.arrays`) are a frozen recording's inputs and its
host values (:meth:`~SampleSpace.key`) its key: :func:`space_of` rebuilds it inside.
Sample positions may change from frame to frame (the gaze moves the buffer's samples), and a
history may be kept on another space than the frame's (the plan then reads none).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from ..kernels.buffers import GBuffer
from . import buffer_space as _buffer_space
from . import reproject as _reproject
from .reproject import History, ReprojectionMap

#: The sample spaces a formation may declare.
SPACES = ("film", "buffer")


class SampleSpace:
    """Where a frame keeps its samples: the interface every pass reads (module docstring).
    ``width`` and ``height`` are the film's; ``kind`` is one of :data:`SPACES`; ``layout`` what
    the history records of the space's layout (None for the film)."""
    width: int
    height: int
    kind: str
    layout: _buffer_space.SampleLayout | None

    @property
    def size(self) -> int:
        """Number of samples."""
        raise NotImplementedError

    def develop_at(self) -> tuple[mi.UInt32, mi.Bool] | None:
        """Where the trace pass develops the rays' estimates: each sample's ray and whether it
        is traced, or None for the film's pixels in launch order."""
        raise NotImplementedError

    def traced_pixels(self, traced: mi.Bool) -> mi.Bool:
        """The film's pixels whose traced value some sample holds.

        Parameters
        ----------
        traced : mi.Bool
            Per sample.

        Returns
        -------
        mask : mi.Bool
            One entry per film pixel.
        """
        raise NotImplementedError

    def to_pixels(self, delta: mi.Color3f, traced: mi.Bool) -> mi.Color3f:
        """A gradient on the samples summed onto their traced pixels: the transpose of
        :meth:`from_pixels`.

        Parameters
        ----------
        delta : mi.Color3f
            The gradient, one value per sample.
        traced : mi.Bool
            Which samples hold a traced value.

        Returns
        -------
        delta : mi.Color3f
            The gradient, one value per film pixel (0 where no traced sample lies).
        """
        raise NotImplementedError

    def from_pixels(self, tangent: mi.Color3f, traced: mi.Bool) -> mi.Color3f:
        """A tangent of the traced pixels read at the samples.

        Parameters
        ----------
        tangent : mi.Color3f
            The tangent, one value per film pixel.
        traced : mi.Bool
            Which samples hold a traced value.

        Returns
        -------
        tangent : mi.Color3f
            One value per sample (0 where not ``traced``).
        """
        raise NotImplementedError

    def still_map(self, history: History) -> ReprojectionMap:
        """Every sample onto itself (a still camera and gaze over an unchanged scene).

        Parameters
        ----------
        history : History
            The previous frame's history, on this space.

        Returns
        -------
        map : ReprojectionMap
            The identity map.
        """
        raise NotImplementedError

    def reprojection_map(self, gb: GBuffer, history: History | None, *, tolerance: float,
                         mode: str, reach: int = 0) -> ReprojectionMap:
        """The samples reprojected into the history's samples.

        Parameters
        ----------
        gb : GBuffer
            The G-buffer at the samples.
        history : History or None
            The previous frame's history (None: every sample misses).
        tolerance : float
            The depth (or plane) test's relative tolerance.
        mode : str
            One of :data:`~.reproject.REPROJECTION_MODES`.
        reach : int, optional
            The film filter's reach, in pixels (a space whose sample's footprint is its own
            ignores it).

        Returns
        -------
        map : ReprojectionMap
            Where each sample's history lies, and whether it may be read.
        """
        raise NotImplementedError

    def history(self, kept: dict[str, mi.Color3f | mi.Float], gb: GBuffer, sensor: mi.Sensor,
                gaze: mi.Point2f | None) -> History:
        """The history a frame leaves on this space, for the next frame to reproject.

        Parameters
        ----------
        kept : dict
            The formation's history (``mean``, ``count``, ``moment2``), one value per sample.
        gb : GBuffer
            The frame's G-buffer at the samples.
        sensor : mi.Sensor
            The frame's sensor (its camera goes with the history).
        gaze : mi.Point2f or None
            The frame's gaze, in film pixels.

        Returns
        -------
        history : History
            What the space's reprojection reads of it next frame.
        """
        raise NotImplementedError

    def arrays(self) -> dict | None:
        """Its device arrays (a recording's inputs; None: it has none)."""
        raise NotImplementedError

    def key(self) -> tuple:
        """Its host values (a recording's key; its first entry is its ``kind``)."""
        raise NotImplementedError


@dataclass(frozen=True)
class FilmSpace(SampleSpace):
    """The film's pixels, one sample each: every map is the identity."""
    width: int
    height: int
    kind = "film"
    layout = None

    @property
    def size(self) -> int:
        return self.width * self.height

    def develop_at(self) -> None:
        return None

    def traced_pixels(self, traced: mi.Bool) -> mi.Bool:
        return traced

    def to_pixels(self, delta: mi.Color3f, traced: mi.Bool) -> mi.Color3f:
        return delta

    def from_pixels(self, tangent: mi.Color3f, traced: mi.Bool) -> mi.Color3f:
        return tangent

    def still_map(self, history: History) -> ReprojectionMap:
        """:func:`~.reproject.still_map`."""
        return _reproject.still_map(history, self.width, self.height)

    def reprojection_map(self, gb: GBuffer, history: History | None, *, tolerance: float,
                         mode: str, reach: int = 0) -> ReprojectionMap:
        """:func:`~.reproject.reprojection_map`: a depth test, the film filter's reach."""
        return _reproject.reprojection_map(gb.position, gb.hit, history, self.width,
                                           self.height, tolerance=tolerance,
                                           direction=gb.direction, mode=mode, reach=reach)

    def history(self, kept: dict[str, mi.Color3f | mi.Float], gb: GBuffer, sensor: mi.Sensor,
                gaze: mi.Point2f | None) -> History:
        """The values and depth at the pixels (a depth test reads them)."""
        return History(**kept, depth=gb.depth, camera=_reproject.camera_state(sensor),
                       width=self.width, height=self.height, layout=None)

    def arrays(self) -> None:
        return None

    def key(self) -> tuple:
        return (self.kind, self.width, self.height)


@dataclass(frozen=True, eq=False)
class BufferSpace(SampleSpace):
    """The foveal buffer's samples (:mod:`.buffer_space`): each one's film ``pixel``, whether
    it is ``on`` (on the film; a patch pixel inside the disc), and its ``ray`` in the launch;
    ``traced``: the samples the launch traces, where not all that are on (another eye's
    samples stand for the rest)."""
    width: int
    height: int
    layout: _buffer_space.SampleLayout
    pixels: mi.UInt32
    on: mi.Bool
    rays: mi.UInt32
    traced: mi.Bool | None = None
    kind = "buffer"

    @property
    def size(self) -> int:
        return self.layout.size

    def develop_at(self) -> tuple[mi.UInt32, mi.Bool]:
        return self.rays, self.on if self.traced is None else self.traced

    def traced_pixels(self, traced: mi.Bool) -> mi.Bool:
        mask = dr.zeros(mi.Bool, self.width * self.height)
        dr.scatter(mask, True, self.pixels, traced)
        return mask

    def to_pixels(self, delta: mi.Color3f, traced: mi.Bool) -> mi.Color3f:
        out = dr.zeros(mi.Color3f, self.width * self.height)
        dr.scatter_reduce(dr.ReduceOp.Add, out, delta, self.pixels, traced)
        return out

    def from_pixels(self, tangent: mi.Color3f, traced: mi.Bool) -> mi.Color3f:
        return dr.gather(mi.Color3f, tangent, self.pixels, traced)

    def still_map(self, history: History) -> ReprojectionMap:
        """:func:`~.buffer_space.still_map`."""
        return _buffer_space.still_map(history, self.layout.size)

    def reprojection_map(self, gb: GBuffer, history: History | None, *, tolerance: float,
                         mode: str, reach: int = 0) -> ReprojectionMap:
        """:func:`~.buffer_space.reprojection_map`: a plane test; ``reach`` is unused."""
        return _buffer_space.reprojection_map(gb, self.on, history, self.layout, self.width,
                                              self.height, tolerance=tolerance, mode=mode)

    def history(self, kept: dict[str, mi.Color3f | mi.Float], gb: GBuffer, sensor: mi.Sensor,
                gaze: mi.Point2f | None) -> History:
        """With the samples' layout, pixels, hit points, normals and view directions, and the
        gaze (a plane test reads them, and the other eye's samples)."""
        return History(**kept, depth=gb.depth, camera=_reproject.camera_state(sensor),
                       width=self.width, height=self.height, layout=self.layout,
                       position=gb.position, normal=gb.normal, gaze=gaze, pixels=self.pixels,
                       direction=gb.direction)

    def arrays(self) -> dict:
        return {"pixels": self.pixels, "on": self.on, "rays": self.rays}

    def key(self) -> tuple:
        return (self.kind, self.width, self.height, self.layout)

    @staticmethod
    def of(key: tuple, arrays: dict) -> BufferSpace:
        """The space of :meth:`key` and :meth:`arrays` (inside a recording).

        Parameters
        ----------
        key : tuple
            What :meth:`key` returned.
        arrays : dict
            What :meth:`arrays` returned.

        Returns
        -------
        space : BufferSpace
            The space rebuilt.
        """
        _, width, height, layout = key
        return BufferSpace(width, height, layout, arrays["pixels"], arrays["on"],
                           arrays["rays"])


def space_of(key: tuple, arrays: dict | None) -> SampleSpace:
    """A space rebuilt from its key and arrays.

    Parameters
    ----------
    key : tuple
        The space's ``key()``; its first entry is its kind.
    arrays : dict or None
        The space's ``arrays()`` (None for the film).

    Returns
    -------
    space : SampleSpace
        The space.
    """
    if key[0] == "film":
        return FilmSpace(key[1], key[2])
    return BufferSpace.of(key, arrays)
