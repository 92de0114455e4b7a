"""One frame driver: the order of operations of a frame, whoever asks for it.

A sequence (``foveated-mi sequence``), a study's ``[motion]`` rows (one eye or two) and the
live view render their frames the same way; only where a frame's inputs come from (a
sequence config, a study task's motion, the live view's mailbox) and what happens to the
frame afterwards (files written, scored, sent to the page) differ. A frame is a
:class:`FrameInput` and :meth:`FrameDriver.step` does, in this order:

1. move the camera, only when it differs from the one the scene is at (the integrator sees
   any update of the sensor as a move, even to the same pose: ``reapply`` keeps that for
   the callers whose results were measured so);
2. on a cut, reset every view's history, before anything is rendered;
3. set the gaze: the eye's under eye tracking; the lens centre
   (:func:`foveated_mi.paths.lens_centre`) under fixed foveation, whatever the eye does
   (the input keeps the eye's for the caller's stats); each eye's own for two eyes;
4. render, forced to host memory inside the timed region (a lazy result would put its cost
   on whatever evaluates it next), and time it.

What renders is a *view*: one foveated integrator (:class:`FoveatedView`, or
:class:`RendererView` with a frame's layers), both eyes with one integrator
(:class:`StereoView`), a uniform baseline (:class:`UniformView`, :class:`UniformEyesView`),
or a caller's own function of the gaze (:class:`FunctionView`). Each renders through
``render(gaze, eye_gazes, seed, spp) -> (image, stats, result)``, resets through
``reset()`` and tells its lens centre through ``lens_centre()``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator, NamedTuple

import numpy as np

from .paths import lens_centre

__all__ = ["FrameInput", "Frame", "FrameDriver", "run_frames", "path_inputs", "FoveatedView",
           "RendererView", "UniformView", "StereoView", "UniformEyesView", "FunctionView"]


@dataclass(frozen=True)
class FrameInput:
    """What one frame is given.

    Attributes
    ----------
    index : int
        The frame, from 0.
    camera : dict or None
        The camera (``{origin, target, up, fov}``) the frame is seen from; None leaves the
        scene's camera where it is.
    cut : bool
        Whether the camera cuts before this frame (every view's history starts again).
    gaze : tuple of float or None
        The eye's gaze, normalised on the film (the head's for two eyes): what the eye tracker
        reports, late and jittered as it is.
    eye_gazes : pair of tuple of float or None
        Each eye's own gaze (a binocular eye tracker's); None: both eyes fixate where the
        head's gaze meets the scene.
    seed : int
        The frame's seed.
    spp : int
        Samples per pixel (0: the sensor's).
    """
    index: int
    camera: dict | None = None
    cut: bool = False
    gaze: tuple | None = None
    eye_gazes: tuple | None = None
    seed: int = 0
    spp: int = 0


class Frame(NamedTuple):
    """One rendered frame (:meth:`FrameDriver.step`)."""
    input: FrameInput      #: what the frame was given (its ``gaze`` the eye's)
    image: Any             #: the image on the host: (H, W, 3), or each eye's for two eyes
    stats: Any             #: the view's stats (each eye's, by eye, for two eyes)
    time_ms: float         #: wall-clock time of the forced render
    gaze: Any              #: the gaze rendered with (the lens centre under fixed foveation)
    eye_gazes: Any         #: each eye's gaze rendered with, None when derived from ``gaze``
    result: Any            #: the view's own result (a FrameResult, a StereoFrame, ...)


class FrameDriver:
    """Renders frames of a view in the one order of operations (module docstring).

    Parameters
    ----------
    scene : mi.Scene
        The scene; its first sensor is the camera (the head for two eyes).
    view : object
        What renders (module docstring).
    eye_tracking : bool, optional
        False: fixed foveation, every frame at the view's lens centre (measured once).
    camera : dict, optional
        The camera the scene is at now (a first frame there is not moved); None: unknown,
        the first frame with a camera moves it.
    reapply : bool, optional
        Also move to a camera equal to the current one, at every frame after the first. The
        integrator sees any update of the sensor as a camera move (its G-buffer is made
        again, the moving camera's settings apply), so this renders other images on a
        still stretch of a camera path; a sequence and a study's path render so.
    clock : callable, optional
        Seconds as a float (``time.perf_counter``).
    """

    def __init__(self, scene, view, *, eye_tracking: bool = True, camera: dict | None = None,
                 reapply: bool = False, clock: Callable[[], float] = time.perf_counter):
        from .validate import ParameterError
        for name, value in (("eye_tracking", eye_tracking), ("reapply", reapply)):
            if not isinstance(value, bool):
                raise ParameterError(name, value, "true or false")
        self.scene, self.view, self.clock = scene, view, clock
        self.camera, self.home, self.reapply, self.frames = camera, None, reapply, 0
        self.fixed = None if eye_tracking else view.lens_centre()

    @property
    def eye_tracking(self) -> bool:
        """False: fixed foveation (each frame at the view's lens centre)."""
        return self.fixed is None

    @eye_tracking.setter
    def eye_tracking(self, on: bool) -> None:
        from .validate import check_bool
        self.fixed = None if check_bool("eye_tracking", on) else self.view.lens_centre()

    def move(self, camera: dict | None) -> bool:
        """Move the scene's camera to ``camera`` if it is another (or, with ``reapply``,
        after the first frame); whether it moved."""
        if camera is None or (camera == self.camera and not (self.reapply and self.frames)):
            return False
        from .scenes import apply_camera, camera_of
        if self.home is None:           # where the camera was before this driver moved it
            self.home = camera_of(self.scene)
        apply_camera(self.scene, camera)
        self.camera = camera
        return True

    def restore(self) -> None:
        """Put the camera back where it was before the first move (if any)."""
        if self.home is not None:
            from .scenes import apply_camera
            apply_camera(self.scene, self.home)
            self.camera, self.home = None, None

    def step(self, frame: FrameInput) -> Frame:
        """Render one frame: camera, cut, gaze, the forced and timed render.

        Parameters
        ----------
        frame : FrameInput
            The frame's inputs.

        Returns
        -------
        frame : Frame
            Its image, stats, time and the gazes it was rendered with.
        """
        self.move(frame.camera)
        if frame.cut:
            self.view.reset()
        gaze, eye_gazes = frame.gaze, frame.eye_gazes
        if self.fixed is not None:      # fixed foveation: the density stays at the lens centre
            if getattr(self.view, "two_eyes", False):
                eye_gazes = self.fixed
            else:
                gaze = self.fixed
        t0 = self.clock()
        image, stats, result = self.view.render(gaze, eye_gazes, frame.seed, frame.spp)
        time_ms = (self.clock() - t0) * 1e3
        self.frames += 1
        return Frame(frame, image, stats, time_ms, gaze, eye_gazes, result)


def run_frames(driver: FrameDriver, inputs: Iterable[FrameInput], *,
               restore: bool = True) -> Iterator[Frame]:
    """Each input's frame in turn (:meth:`FrameDriver.step`), for callers that follow a path.

    Parameters
    ----------
    driver : FrameDriver
        The driver.
    inputs : iterable of FrameInput
        The frames' inputs, in order (read one frame at a time).
    restore : bool, optional
        Put the camera back where it was when the loop ends, however it ends (a cached
        scene serves later work).

    Yields
    ------
    frame : Frame
        Each rendered frame.
    """
    try:
        for frame in inputs:
            yield driver.step(frame)
    finally:
        if restore:
            driver.restore()


def _host(image) -> np.ndarray:
    """The image evaluated and copied to the host, float32."""
    return np.array(image, dtype=np.float32)


class FoveatedView:
    """One foveated integrator's view: its gaze set, ``mi.render`` forced.

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    integrator : FoveatedIntegrator
        The integrator (its history is the view's).
    """
    two_eyes = False

    def __init__(self, scene, integrator):
        self.scene, self.integrator = scene, integrator

    def reset(self) -> None:
        """A cut: the history starts again."""
        self.integrator.reset()

    def lens_centre(self) -> tuple[float, float]:
        """The scene sensor's lens centre (fixed foveation's gaze)."""
        return lens_centre(self.scene.sensors()[0])

    def render(self, gaze, eye_gazes, seed: int, spp: int):
        """``(image, stats, image)`` at ``gaze`` (``eye_gazes`` is not used)."""
        import mitsuba as mi
        self.integrator.gaze = tuple(gaze)
        image = _host(mi.render(self.scene, integrator=self.integrator, spp=spp, seed=seed))
        return image, self.integrator.stats, image


class RendererView(FoveatedView):
    """A :class:`foveated_mi.render.FrameRenderer`'s view: its frame with layers (and the
    full render beside it with ``compare_full``); its spp is the renderer's.

    Parameters
    ----------
    renderer : FrameRenderer
        The renderer.
    compare_full : bool, optional
        Also render the full frame and score the foveated one against it.
    """

    def __init__(self, renderer, *, compare_full: bool = False):
        super().__init__(renderer.scene, renderer.integrator)
        self.renderer, self.compare_full = renderer, bool(compare_full)

    def render(self, gaze, eye_gazes, seed: int, spp: int):
        """``(image, stats, FrameResult)`` at ``gaze``."""
        self.integrator.gaze = tuple(gaze)
        res = self.renderer.render_frame(seed=seed, compare_full=self.compare_full)
        return res.image, res.stats, res


class UniformView:
    """A uniform baseline (:func:`foveated_mi.baselines.render_uniform`): no gaze, no history.

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    denoise : bool, optional
        Denoise with OIDN.
    scale : float, optional
        Render scale (dynamic resolution).
    """
    two_eyes = False

    def __init__(self, scene, *, denoise: bool = False, scale: float = 1.0):
        self.scene, self.denoise, self.scale = scene, bool(denoise), scale

    def reset(self) -> None:
        """Nothing to reset."""

    def lens_centre(self) -> tuple[float, float]:
        """The scene sensor's lens centre."""
        return lens_centre(self.scene.sensors()[0])

    def render(self, gaze, eye_gazes, seed: int, spp: int):
        """``(image, stats, image)`` of :func:`~foveated_mi.baselines.render_uniform`."""
        from .baselines import render_uniform
        image, stats = render_uniform(self.scene, spp=spp, seed=seed, denoise=self.denoise,
                                      scale=self.scale)
        return image, stats, image


class StereoView:
    """Both eyes with one integrator (:class:`foveated_mi.stereo.Stereo`): a cut resets both;
    fixed foveation puts each eye at its own lens centre.

    Parameters
    ----------
    stereo : Stereo
        The eyes and their views.
    """
    two_eyes = True

    def __init__(self, stereo):
        self.stereo = stereo

    def reset(self) -> None:
        """A cut: both eyes' histories start again."""
        self.stereo.cut()

    def lens_centre(self) -> tuple:
        """Each eye's lens centre, left then right."""
        from .stereo import EYES
        return tuple(lens_centre(self.stereo.sensors[eye]) for eye in EYES)

    def render(self, gaze, eye_gazes, seed: int, spp: int):
        """``([left, right], {eye: stats}, StereoFrame)``: the eyes fixating the head's
        ``gaze``, or each its own of ``eye_gazes``."""
        from .stereo import EYES
        frame = self.stereo.render(tuple(gaze), seed=seed, spp=spp, eye_gazes=eye_gazes)
        images = [_host(frame.left), _host(frame.right)]
        return images, {eye: self.stereo.views[eye].stats for eye in EYES}, frame


class UniformEyesView:
    """Both eyes of a rig rendered uniformly, each its own sensor (the right eye's seed the
    left one's + 1, so their noise is independent).

    Parameters
    ----------
    eyes : EyeSensors
        The eyes' sensors, following the head.
    denoise : bool, optional
        Denoise with OIDN.
    scale : float, optional
        Render scale (dynamic resolution).
    """
    two_eyes = True

    def __init__(self, eyes, *, denoise: bool = False, scale: float = 1.0):
        self.eyes, self.denoise, self.scale = eyes, bool(denoise), scale

    def reset(self) -> None:
        """Nothing to reset."""

    def lens_centre(self) -> tuple:
        """Each eye's lens centre, left then right."""
        from .stereo import EYES
        return tuple(lens_centre(self.eyes[eye]) for eye in EYES)

    def render(self, gaze, eye_gazes, seed: int, spp: int):
        """``([left, right], {eye: stats}, runs)`` at the head's current pose."""
        from .baselines import render_uniform
        from .stereo import EYES
        self.eyes.follow()
        runs = [render_uniform(self.eyes.scene, spp=spp, seed=(seed + k) % 2**32,
                               denoise=self.denoise, sensor=self.eyes[eye], scale=self.scale)
                for k, eye in enumerate(EYES)]
        return [r[0] for r in runs], {eye: r[1] for eye, r in zip(EYES, runs)}, runs


class FunctionView:
    """A caller's own frame function as a view: ``render(gaze, eye_gazes)`` (or
    ``render(gaze)`` for one eye) returning a tuple whose first item is the image.

    Parameters
    ----------
    render : callable
        The frame function; it forces its render itself.
    scene : mi.Scene
        The scene (fixed foveation's lens centre: its sensor's, or each eye's of ``eyes``).
    eyes : EyeSensors, optional
        Two eyes: ``render`` takes each eye's gaze too.
    reset : callable, optional
        What a cut resets (the history the function's integrator keeps).
    """

    def __init__(self, render: Callable, scene, *, eyes=None, reset: Callable | None = None):
        self.fn, self.scene, self.eyes, self._reset = render, scene, eyes, reset
        self.two_eyes = eyes is not None

    def reset(self) -> None:
        """A cut: the function's history starts again (``reset`` given)."""
        if self._reset is not None:
            self._reset()

    def lens_centre(self):
        """The lens centre (each eye's for two eyes)."""
        if self.eyes is None:
            return lens_centre(self.scene.sensors()[0])
        from .stereo import EYES
        return tuple(lens_centre(self.eyes[eye]) for eye in EYES)

    def render(self, gaze, eye_gazes, seed: int, spp: int):
        """``(image, out, out)``, ``out`` what the function returned."""
        out = self.fn(gaze, eye_gazes) if self.two_eyes else self.fn(gaze)
        return out[0], out, out


def path_inputs(gazes, cameras=None, *, eye_gazes=None, seed: int = 0,
                spp: int = 0) -> Iterator[FrameInput]:
    """The inputs of a path's frames: frame ``k`` at ``cameras[k]`` (the camera stays put
    without a camera path), looking at ``gazes[k]`` (and each eye at ``eye_gazes[k]``).

    Parameters
    ----------
    gazes : sequence of pair of float
        Each frame's gaze, normalised.
    cameras : sequence of dict, optional
        Each frame's camera.
    eye_gazes : sequence of pair of pair of float, optional
        Each frame's gaze of each eye.
    seed, spp : int, optional
        Every frame's seed and samples per pixel.

    Yields
    ------
    frame : FrameInput
        Frame ``k``'s inputs, in order.
    """
    for k, gaze in enumerate(gazes):
        yield FrameInput(k, camera=cameras[k] if cameras else None, gaze=tuple(gaze),
                         eye_gazes=None if not eye_gazes else tuple(map(tuple, eye_gazes[k])),
                         seed=seed, spp=spp)
