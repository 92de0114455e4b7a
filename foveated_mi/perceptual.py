"""FovVideoVDP (Mantiuk et al. 2021): a foveated, perceptual quality score in JOD.

Optional: it needs ``pyfvvdp`` and PyTorch (``pip install -e '.[perceptual]'`` from a clone;
a CPU build of torch is enough). Without them :func:`available` is false and nothing here
imports torch. ``pyfvvdp`` is licensed CC BY-NC 4.0 (non-commercial use).

JOD (just-objectionable differences) is 10 for an image identical to the reference and falls
as differences grow more visible; one JOD unit means 75 % of observers prefer the better of
two images. The score is of one frame (image mode), foveated at the gaze.

Viewing condition (the same for every row of a study):

* **display** -- the photometry of one of pyfvvdp's display models (peak luminance,
  contrast, ambient light); default ``standard_fhd``: 200 cd/m², 1000:1, 250 lux.
* **geometry** -- the film fills a display whose centre has ``ppd`` pixels per degree (the
  study's ``[metrics] ppd``, shared with FLIP; default 67), so the frame spans
  ``width / ppd`` degrees horizontally.
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

__all__ = ["available", "display_names", "jod", "INSTALL_HINT", "DEFAULT_DISPLAY", "COLUMNS"]

INSTALL_HINT = "pip install -e '.[perceptual]'"
DEFAULT_DISPLAY = "standard_fhd"
#: Columns a study adds to ``results.csv`` when the extra is installed.
COLUMNS = ("jod",)


def available() -> bool:
    """Whether ``pyfvvdp`` and ``torch`` can be imported (checked without importing them)."""
    return all(importlib.util.find_spec(m) is not None for m in ("pyfvvdp", "torch"))


def _package_dir() -> str | None:
    spec = importlib.util.find_spec("pyfvvdp")
    if spec is None or not spec.submodule_search_locations:
        return None
    return list(spec.submodule_search_locations)[0]


@lru_cache(maxsize=1)
def display_names() -> tuple[str, ...]:
    """The display models pyfvvdp ships (empty without the extra); read from its JSON."""
    d = _package_dir()
    if d is None:
        return ()
    try:
        with open(os.path.join(d, "fvvdp_data", "display_models.json")) as f:
            return tuple(json.load(f))
    except (OSError, ValueError):
        return ()


def check_display(name: str, display: str) -> str:
    """``display`` if it names a pyfvvdp display model (any string without the extra)."""
    if not isinstance(display, str) or not display:
        raise ParameterError(name, display, "the name of a FovVideoVDP display model, e.g. "
                             f"{DEFAULT_DISPLAY!r}")
    names = display_names()
    if names and display not in names:
        raise ParameterError(name, display, "one of " + ", ".join(names))
    return display


@lru_cache(maxsize=8)
def _metric(width: int, height: int, ppd: float, display: str):
    import torch
    import pyfvvdp
    from pyfvvdp.fvvdp_display_model import fvvdp_display_geometry
    # a horizontal field of view that puts exactly `ppd` pixels per degree at the centre
    fov = 2.0 * math.degrees(math.atan(width * math.tan(math.radians(0.5 / ppd))))
    geometry = fvvdp_display_geometry((width, height), fov_horizontal=fov)
    return pyfvvdp.fvvdp(display_name=display, display_geometry=geometry, foveated=True,
                         quiet=True, device=torch.device("cpu")), torch


def jod(reference: np.ndarray, test: np.ndarray, *, gaze: tuple[float, float] = (0.5, 0.5),
        ppd: float = 67.0, display: str = DEFAULT_DISPLAY) -> float:
    """FovVideoVDP's JOD of ``test`` against ``reference``: both (H, W, 3) display-referred
    sRGB in [0, 1], fixated at ``gaze``. Raises :class:`ParameterError` for bad input or
    without the extra."""
    if not available():
        raise ParameterError("jod", "pyfvvdp", f"pyfvvdp and torch installed ({INSTALL_HINT})")
    ref = np.asarray(reference, dtype=np.float32)
    tst = np.asarray(test, dtype=np.float32)
    if ref.ndim != 3 or ref.shape[2] != 3 or ref.shape != tst.shape:
        raise ParameterError("test", tst.shape, f"an (H, W, 3) image of the reference's shape "
                             f"{ref.shape}")
    gx, gy = check_point2("gaze", gaze)
    ppd = check_range("ppd", ppd, 0.0, None, lo_open=True)
    display = check_display("display", display)
    h, w = ref.shape[:2]
    with warnings.catch_warnings():       # pyfvvdp's own SciPy deprecations
        warnings.simplefilter("ignore", DeprecationWarning)
        metric, torch = _metric(w, h, float(ppd), display)
    fix = np.array([min(max(gx * w, 0.0), w - 1.0), min(max(gy * h, 0.0), h - 1.0)])
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        q, _ = metric.predict(torch.from_numpy(np.clip(tst, 0.0, 1.0)),
                              torch.from_numpy(np.clip(ref, 0.0, 1.0)),
                              dim_order="HWC", fixation_point=fix)
    return float(q)
