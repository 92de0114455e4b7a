"""FovVideoVDP (Mantiuk et al. 2021): a foveated, perceptual quality score in JOD.

Optional: it needs ``pyfvvdp`` and PyTorch (``pip install -e '.[perceptual]'`` from a clone;
a CPU build of torch is enough). Without them :func:`available` is false and nothing here
imports torch. ``pyfvvdp`` is licensed CC BY-NC 4.0 (non-commercial use).

JOD (just-objectionable differences) is 10 for an image identical to the reference and falls
as differences grow more visible; one JOD unit means 75 % of observers prefer the better of
two images. :func:`jod` scores one frame (image mode), foveated at the gaze;
:func:`jod_video` scores a sequence as a video (FovVideoVDP's temporal channels, about 250 ms
of frames, see flicker and judder), with a fixation point per frame. A video's JOD is not the
mean of its frames' JODs.

Viewing condition (the same for every row of a study):

* **display** -- the photometry of one of pyfvvdp's display models (peak luminance,
  contrast, ambient light); default ``standard_fhd``: 200 cd/m², 1000:1, 250 lux.
* **geometry** -- the film fills a display whose centre has ``ppd`` pixels per degree (the
  study's ``[metrics] ppd``, shared with FLIP; default 67), so the frame spans
  ``width / ppd`` degrees horizontally; or, with ``fov_horizontal``, the film spans that
  many degrees (a headset whose display spans the sensor's field of view).
* **gaze** -- the fixation point, the scene's gaze (normalised film coordinates, origin
  top-left).

Both images are display-referred sRGB in [0, 1] (``render.to_display``), as pyfvvdp's
``sRGB`` colour space expects. The display models ship inside the package: it runs offline.
"""
from __future__ import annotations

import importlib.util
import json
import math
import os
import warnings
from functools import lru_cache

import numpy as np

from .validate import ParameterError, check_point2, check_range

__all__ = ["available", "axis_geometry", "display_names", "jod", "jod_video", "INSTALL_HINT",
           "DEFAULT_DISPLAY", "COLUMNS", "columns"]

INSTALL_HINT = "pip install -e '.[perceptual]'"
DEFAULT_DISPLAY = "standard_fhd"
#: Columns a study adds to ``results.csv`` when the extra is installed.
COLUMNS = ("jod",)


def columns(motion: bool, monitor: bool) -> tuple[str, ...]:
    """The JOD columns of a study (with the extra).

    Parameters
    ----------
    motion : bool
        The study has a ``[motion]`` table (adds ``jod_video``).
    monitor : bool
        A second viewing condition, ``[viewer] monitor`` (adds the ``_monitor`` twins).

    Returns
    -------
    columns : tuple of str
        ``jod``, ``jod_video`` in motion, then their ``_monitor`` twins.
    """
    base = COLUMNS + (("jod_video",) if motion else ())
    return base + (tuple(f"{c}_monitor" for c in base) if monitor else ())


def available() -> bool:
    """Whether ``pyfvvdp`` and ``torch`` can be imported (checked without importing them).

    Returns
    -------
    available : bool
        Both are found.
    """
    return all(importlib.util.find_spec(m) is not None for m in ("pyfvvdp", "torch"))


def _package_dir() -> str | None:
    spec = importlib.util.find_spec("pyfvvdp")
    if spec is None or not spec.submodule_search_locations:
        return None
    return list(spec.submodule_search_locations)[0]


@lru_cache(maxsize=1)
def display_names() -> tuple[str, ...]:
    """The display models pyfvvdp ships, read from its JSON.

    Returns
    -------
    names : tuple of str
        Empty without the extra.
    """
    d = _package_dir()
    if d is None:
        return ()
    try:
        with open(os.path.join(d, "fvvdp_data", "display_models.json")) as f:
            return tuple(json.load(f))
    except (OSError, ValueError):
        return ()


def check_display(name: str, display: str) -> str:
    """``display`` if it names a pyfvvdp display model (any string without the extra).

    Parameters
    ----------
    name, display : str
        The input's name, for the error message, and the model's name (one of
        :func:`display_names` when the extra is installed).

    Returns
    -------
    display : str
        ``display``, unchanged.

    Raises
    ------
    ParameterError
        For an empty or unknown name.
    """
    if not isinstance(display, str) or not display:
        raise ParameterError(name, display, "the name of a FovVideoVDP display model, e.g. "
                             f"{DEFAULT_DISPLAY!r}")
    names = display_names()
    if names and display not in names:
        raise ParameterError(name, display, "one of " + ", ".join(names))
    return display


def _fov(width: int, ppd: float | None, fov_horizontal: float | None) -> float:
    """The horizontal field of view of the display: given, or the one that puts exactly
    ``ppd`` pixels per degree at the centre of a flat display."""
    if fov_horizontal is not None:
        return check_range("fov_horizontal", fov_horizontal, 0.0, 180.0, lo_open=True)
    ppd = check_range("ppd", ppd, 0.0, None, lo_open=True)
    return 2.0 * math.degrees(math.atan(width * math.tan(math.radians(0.5 / ppd))))


def axis_geometry(width: int, height: int, fov: float, axis: tuple[float, float]):
    """FovVideoVDP's flat display geometry of a ``width`` x ``height`` image ``fov`` degrees
    across, with the view's optical axis at ``axis`` (normalised film position) rather than
    the image's centre: each pixel's direction is measured from the axis, as through a
    headset's off-axis eye buffer.

    Parameters
    ----------
    width, height : int
        The image's size.
    fov : float
        Degrees across the image.
    axis : tuple of float
        Where the optical axis meets the image.

    Returns
    -------
    geometry : pyfvvdp.fvvdp_display_model.fvvdp_display_geometry
        A geometry whose ``pix2view_direction`` is measured from the axis.
    """
    import torch
    from pyfvvdp.fvvdp_display_model import fvvdp_display_geometry
    ax, ay = check_point2("axis", axis)

    class AxisGeometry(fvvdp_display_geometry):
        def pix2view_direction(self, resolution_pix, x_pix, y_pix):
            # The base class's flat projection, measured from the axis.
            res = torch.as_tensor(resolution_pix, dtype=torch.float32)
            x_m = (x_pix - res[0] * ax) * self.display_size_m[0] / res[0]
            y_m = -(y_pix - res[1] * ay) * self.display_size_m[1] / res[1]
            return torch.stack((torch.rad2deg(torch.atan(x_m / self.distance_m)),
                                torch.rad2deg(torch.atan(y_m / self.distance_m))), dim=0)

    return AxisGeometry((width, height), fov_horizontal=fov)


@lru_cache(maxsize=8)
def _metric(width: int, height: int, fov: float, display: str,
            axis: tuple[float, float] = (0.5, 0.5)):
    import torch
    import pyfvvdp
    from pyfvvdp.fvvdp_display_model import fvvdp_display_geometry
    geometry = fvvdp_display_geometry((width, height), fov_horizontal=fov) \
        if tuple(axis) == (0.5, 0.5) else axis_geometry(width, height, fov, axis)
    return pyfvvdp.fvvdp(display_name=display, display_geometry=geometry, foveated=True,
                         quiet=True, device=torch.device("cpu")), torch


def jod(reference: np.ndarray, test: np.ndarray, *, gaze: tuple[float, float] = (0.5, 0.5),
        ppd: float = 67.0, display: str = DEFAULT_DISPLAY,
        fov_horizontal: float | None = None) -> float:
    """FovVideoVDP's JOD of ``test`` against ``reference``.

    Parameters
    ----------
    reference, test : numpy.ndarray
        Both (H, W, 3) display-referred sRGB in [0, 1].
    gaze : tuple of float, optional
        The fixation, in normalised film coordinates.
    ppd : float, optional
        Pixels per degree at the centre of a flat display (when ``fov_horizontal`` is None).
    display : str, optional
        A pyfvvdp display model.
    fov_horizontal : float or None, optional
        Degrees across the film; None: from ``ppd``.

    Returns
    -------
    jod : float
        Just-objectionable-difference score (10: identical).

    Raises
    ------
    ParameterError
        For bad input or without the extra.
    """
    if not available():
        raise ParameterError("jod", "pyfvvdp", f"pyfvvdp and torch installed ({INSTALL_HINT})")
    ref = np.asarray(reference, dtype=np.float32)
    tst = np.asarray(test, dtype=np.float32)
    if ref.ndim != 3 or ref.shape[2] != 3 or ref.shape != tst.shape:
        raise ParameterError("test", tst.shape, f"an (H, W, 3) image of the reference's shape "
                             f"{ref.shape}")
    gx, gy = check_point2("gaze", gaze)
    display = check_display("display", display)
    h, w = ref.shape[:2]
    fov = _fov(w, ppd, fov_horizontal)
    with warnings.catch_warnings():       # pyfvvdp's own SciPy deprecations
        warnings.simplefilter("ignore", DeprecationWarning)
        metric, torch = _metric(w, h, float(fov), display)
    fix = np.array([min(max(gx * w, 0.0), w - 1.0), min(max(gy * h, 0.0), h - 1.0)])
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        q, _ = metric.predict(torch.from_numpy(np.clip(tst, 0.0, 1.0)),
                              torch.from_numpy(np.clip(ref, 0.0, 1.0)),
                              dim_order="HWC", fixation_point=fix)
    return float(q)


def _video_inputs(reference, test, fixations) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`jod_video`'s videos as float32 and its fixations one pair a frame, checked."""
    ref = np.asarray(reference, dtype=np.float32)
    tst = np.asarray(test, dtype=np.float32)
    if ref.ndim != 4 or ref.shape[3] != 3 or ref.shape[0] < 2:
        raise ParameterError("reference", ref.shape, "an (F, H, W, 3) video of at least 2 "
                             "frames")
    if tst.shape != ref.shape:
        raise ParameterError("test", tst.shape, f"a video of the reference's shape {ref.shape}")
    n = ref.shape[0]
    fix = np.asarray(fixations, dtype=np.float64)
    if fix.shape == (2,):
        fix = np.tile(fix, (n, 1))
    if fix.shape != (n, 2) or not np.all(np.isfinite(fix)):
        raise ParameterError("fixations", f"<array of shape {fix.shape}>",
                             f"finite (x, y) per frame, shape ({n}, 2)")
    return ref, tst, fix


def jod_video(reference: np.ndarray, test: np.ndarray, *, fixations, fps: float,
              ppd: float | None = 67.0, fov_horizontal: float | None = None,
              display: str = DEFAULT_DISPLAY, axis: tuple[float, float] = (0.5, 0.5)
              ) -> float:
    """FovVideoVDP's JOD of the video ``test`` against ``reference``.

    Bad input, or a missing extra, raises :class:`ParameterError`.

    Parameters
    ----------
    reference, test : numpy.ndarray
        Both (F, H, W, 3) display-referred sRGB in [0, 1], F >= 2.
    fixations : array_like
        Frame ``f`` fixated at ``fixations[f]`` (normalised film coordinates); one pair for all
        frames also works.
    fps : float
        Frames per second.
    ppd, fov_horizontal : float or None, optional
        The geometry: ``fov_horizontal`` degrees across the film when given, else ``ppd`` at its
        centre.
    display : str, optional
        A pyfvvdp display model.
    axis : tuple of float, optional
        Where the view's optical axis meets the film (normalised film position): FovVideoVDP
        measures each pixel's direction from it. The image's centre by default, as
        FovVideoVDP places it; a headset's eye buffer has its axis off centre
        (:attr:`foveated_mi.stereo.Frustum.axis`).

    Returns
    -------
    jod : float
        Just-objectionable-difference score (10: identical).
    """
    if not available():
        raise ParameterError("jod_video", "pyfvvdp", f"pyfvvdp and torch installed "
                             f"({INSTALL_HINT})")
    ref, tst, fix = _video_inputs(reference, test, fixations)
    fps = check_range("fps", fps, 0.0, 1000.0, lo_open=True)
    h, w = ref.shape[1:3]
    display = check_display("display", display)
    ax, ay = check_point2("axis", axis)
    fov = _fov(w, ppd, fov_horizontal)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        metric, torch = _metric(w, h, float(fov), display, (ax, ay))
    px = np.stack([np.clip(fix[:, 0] * w, 0.0, w - 1.0), np.clip(fix[:, 1] * h, 0.0, h - 1.0)],
                  -1)
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        q, _ = metric.predict(torch.from_numpy(np.clip(tst, 0.0, 1.0)),
                              torch.from_numpy(np.clip(ref, 0.0, 1.0)),
                              dim_order="FHWC", frames_per_second=float(fps),
                              fixation_point=torch.from_numpy(px))
    return float(q)
