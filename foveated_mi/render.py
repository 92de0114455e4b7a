"""One foveated frame end to end, for the CLI, notebooks and benchmarks.

:class:`FrameRenderer` wraps a loaded scene with a ``foveated`` integrator (the scene's own
integrator becomes the nested one unless it is already ``foveated``), renders timed frames
and, optionally, the full frame of the nested integrator for comparison.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np

from .integrators.foveated import FoveatedIntegrator

#: EXR layers written by :meth:`FrameResult.write`, in order.
EXR_LAYERS = ("image", "sampling_map", "shading", "nearest", "filled", "interpolated",
              "tonemapped", "filtered", "probability", "depth")


def to_display(linear: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Display-referred image in [0, 1] for metrics and previews.

    Reinhard ``x / (1 + x)`` after ``2^exposure``, then the sRGB encoding (colour-science).
    Non-finite values -> 0 (+inf -> 1).

    Parameters
    ----------
    linear : array_like
        Linear image, any shape.
    exposure : float, optional
        Exposure in stops.

    Returns
    -------
    display : numpy.ndarray
        float64, the shape of ``linear``.
    """
    import colour
    x = np.nan_to_num(np.asarray(linear, dtype=np.float64), nan=0.0, posinf=1e30, neginf=0.0)
    x = np.maximum(x * 2.0 ** exposure, 0.0)
    return np.clip(colour.cctf_encoding(x / (1.0 + x), function="sRGB"), 0.0, 1.0)


def make_integrator(scene: mi.Scene, options: dict[str, Any]) -> FoveatedIntegrator:
    """The ``foveated`` integrator for ``scene``.

    Parameters
    ----------
    scene : mi.Scene
        The scene. When its own integrator is already ``foveated`` it is reused with
        ``options`` set; else its own (a sampling integrator) becomes the nested one.
    options : dict
        Options of the foveated integrator.

    Returns
    -------
    integrator : FoveatedIntegrator
        The integrator.
    """
    own = scene.integrator()
    if isinstance(own, FoveatedIntegrator):
        own.set_options(**options)
        return own
    nested = own if isinstance(own, mi.SamplingIntegrator) else None
    return FoveatedIntegrator(nested=nested, **options)


@dataclass
class FrameResult:
    image: np.ndarray
    layers: dict[str, np.ndarray]
    stats: dict[str, Any]
    full: np.ndarray | None = None
    exposure: float = 0.0
    tonemap: str = "reinhard"
    extra: dict[str, Any] = field(default_factory=dict)

    def write(self, exr_path: str) -> None:
        """Write the EXR (all layers) and a PNG preview next to it, each atomically."""
        from .io import write_exr, write_png
        d = os.path.dirname(os.path.abspath(exr_path))
        os.makedirs(d, exist_ok=True)
        layers = dict(self.layers)
        if self.full is not None:
            layers["full"] = self.full
        write_exr(exr_path, layers, attrs={"foveated_mi_stats": _json(self.stats)})
        write_png(os.path.splitext(exr_path)[0] + ".png", self.image, exposure=self.exposure,
                  tonemap=self.tonemap)


def _json(stats):
    import json
    return json.dumps(stats)


def frame_layers(integ: FoveatedIntegrator, image: np.ndarray) -> dict[str, np.ndarray]:
    """The EXR layers of the integrator's last frame as (H, W, C) float32 arrays.

    Those of :data:`EXR_LAYERS` that the frame's formation made on the film's pixels (a
    formation that works in another buffer has no ``nearest``, and its ``filtered`` lies on its
    own grid; one that keeps its G-buffer and history on its samples has no ``shading`` or
    ``depth`` on the film).

    Parameters
    ----------
    integ : FoveatedIntegrator
        The integrator that rendered the frame.
    image : numpy.ndarray
        The frame, (H, W, C).

    Returns
    -------
    layers : dict of str to numpy.ndarray
        Layer name -> (H, W, C) float32; ``shading`` carries its mask as a fourth channel.
    """
    h, w = image.shape[:2]

    def get(name):
        v = integ.buffer(name) if name in integ.buffers else None
        v = None if v is None else np.asarray(v, dtype=np.float32)
        return v if v is not None and v.shape[:2] == (h, w) else None
    out = {"image": image.astype(np.float32)}
    out["sampling_map"] = get("sampling_map")[..., None]
    shading, mask = get("shading"), get("shading_mask")
    if shading is not None and mask is not None:       # none on a formation's own samples
        out["shading"] = np.concatenate([shading * mask[..., None], mask[..., None]], -1)
    for name in ("nearest", "filled", "interpolated", "tonemapped", "filtered"):
        v = get(name)
        if v is not None:
            out[name] = v
    for name in ("probability", "depth"):
        v = get(name)
        if v is not None:
            out[name] = v[..., None]
    return out


def _timed(fn):
    dr.sync_thread()
    t0 = time.perf_counter()
    out = fn()
    dr.eval(out)
    dr.sync_thread()
    return out, (time.perf_counter() - t0) * 1e3


class FrameRenderer:
    """Render foveated frames of ``scene`` (and the full reference on request)."""

    def __init__(self, scene: mi.Scene, options: dict[str, Any] | None = None, *, spp: int = 1):
        self.scene = scene
        self.spp = spp
        self.integrator = make_integrator(scene, dict(options or {}))

    def render_full(self, seed: int = 0, spp: int | None = None) -> tuple[np.ndarray, float]:
        """The nested integrator over the whole frame: image and wall time (ms)."""
        img, ms = _timed(lambda: mi.render(self.scene, integrator=self.integrator.nested,
                                           spp=spp or self.spp, seed=seed))
        return np.asarray(img), ms

    def render_frame(self, seed: int = 0, *, warmup: int = 0,
                     compare_full: bool = False) -> FrameResult:
        """Render one frame after ``warmup`` untimed frames (history reset after them)."""
        integ = self.integrator
        for k in range(warmup):
            mi.render(self.scene, integrator=integ, spp=self.spp, seed=seed + 1000 + k)
        if warmup:
            integ.reset()
        img = mi.render(self.scene, integrator=integ, spp=self.spp, seed=seed)
        image = np.asarray(img)
        stats = integ.stats
        result = FrameResult(image=image, layers=frame_layers(integ, image), stats=stats,
                             exposure=integ.exposure, tonemap=integ.tonemap)
        if compare_full:
            from .metrics import psnr, ssim
            for k in range(warmup):
                self.render_full(seed=seed + 1000 + k)
            full, full_ms = self.render_full(seed=seed)
            ref, test = to_display(full, integ.exposure), to_display(image, integ.exposure)
            stats["full_ms"] = full_ms
            total = stats["timings_ms"]["total"]
            stats["speedup"] = full_ms / total if total else None
            stats["psnr"] = float(psnr(ref, test, data_range=1.0))
            stats["ssim"] = float(ssim(ref, test, data_range=1.0))
            result.full = full.astype(np.float32)
        return result
