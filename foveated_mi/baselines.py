"""Uniform baselines for equal-time comparisons: every pixel at ``spp`` samples, optionally
denoised with Intel Open Image Denoise (:mod:`foveated_mi.denoise`).

``render_uniform`` times one frame as the foveated integrator's ``timings_ms["total"]`` does:
``dr.sync_thread()`` before, the image evaluated and ``dr.sync_thread()`` after. With
``denoise=True`` the frame also renders albedo and shading normals with Mitsuba's ``aov``
integrator (``albedo:albedo,normal:sh_normal``, same ``spp`` and seed, so the auxiliary
buffers are antialiased like the colour) and runs OIDN on the three; both count in the frame
time::

    time_ms = render_ms + aov_ms + denoise_ms

``spp`` is always passed to ``mi.render`` explicitly. ``mi.render(spp=N)`` leaves N as the
sensor sampler's sample count, so both functions here restore the sampler's count afterwards:
a caller relying on the sensor's own count is not silently changed.
"""
from __future__ import annotations

import time
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np

from .validate import ParameterError, check_int

__all__ = ["render_uniform", "render_reference", "AOV_INTEGRATOR"]

#: The auxiliary buffers OIDN uses, as a Mitsuba ``aov`` integrator.
AOV_INTEGRATOR = {"type": "aov", "aovs": "albedo:albedo,normal:sh_normal"}

_aov = None


def _aov_integrator() -> "mi.Integrator":
    global _aov
    if _aov is None or _aov[0] != mi.variant():
        _aov = (mi.variant(), mi.load_dict(AOV_INTEGRATOR))
    return _aov[1]


class _KeepSampleCount:
    """Restore the sensor sampler's sample count that ``mi.render(spp=N)`` overwrites."""

    def __init__(self, scene):
        self.sampler = scene.sensors()[0].sampler()

    def __enter__(self):
        self.count = self.sampler.sample_count()
        return self

    def __exit__(self, *exc):
        self.sampler.set_sample_count(self.count)
        return False


def _timed_render(scene, integrator, spp: int, seed: int) -> tuple[np.ndarray, float]:
    dr.sync_thread()
    t0 = time.perf_counter()
    img = mi.render(scene, integrator=integrator, spp=spp, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    ms = (time.perf_counter() - t0) * 1e3
    return np.array(img, dtype=np.float32), ms


def _check_integrator(scene, integrator):
    integ = scene.integrator() if integrator is None else integrator
    if not isinstance(integ, mi.Integrator):
        raise ParameterError("integrator", integrator, "a Mitsuba integrator (or None for the "
                             "scene's own)")
    return integ


def render_uniform(scene: "mi.Scene", *, spp: int, seed: int = 0, denoise: bool = False,
                   integrator: "mi.Integrator | None" = None) -> tuple[np.ndarray, dict[str, Any]]:
    """One uniform frame: linear (H, W, 3) float32 image and stats
    ``{"time_ms", "spp", "denoised"}`` (+ ``render_ms``, ``aov_ms``, ``denoise_ms`` when
    denoised). ``integrator`` defaults to the scene's own. Raises :class:`ParameterError`
    for bad arguments, and when ``denoise`` is asked for without ``pyoidn``.
    """
    spp = check_int("spp", spp, 1)
    seed = check_int("seed", seed, 0, 2**32 - 1)
    if not isinstance(denoise, bool):
        raise ParameterError("denoise", denoise, "true or false")
    integ = _check_integrator(scene, integrator)
    if denoise:
        from .denoise import INSTALL_HINT, oidn_available
        if not oidn_available():
            raise ParameterError("denoise", True, f"pyoidn installed ({INSTALL_HINT})")
    with _KeepSampleCount(scene):
        return _render_uniform(scene, integ, spp, seed, denoise)


def _render_uniform(scene, integ, spp, seed, denoise):
    color, render_ms = _timed_render(scene, integ, spp, seed)
    color = color[..., :3]
    stats: dict[str, Any] = {"spp": spp, "denoised": denoise, "render_ms": render_ms}
    if not denoise:
        stats["time_ms"] = render_ms
        return color, stats
    from .denoise import denoise as oidn
    aux, aov_ms = _timed_render(scene, _aov_integrator(), spp, seed)
    t0 = time.perf_counter()
    image = oidn(color, aux[..., 0:3], aux[..., 3:6], hdr=True)
    denoise_ms = (time.perf_counter() - t0) * 1e3
    stats.update(aov_ms=aov_ms, denoise_ms=denoise_ms, time_ms=render_ms + aov_ms + denoise_ms)
    return image, stats


def render_reference(scene: "mi.Scene", *, spp: int, seed: int = 0,
                     integrator: "mi.Integrator | None" = None,
                     max_samples_per_pass: int = 1 << 24) -> np.ndarray:
    """A converged (H, W, 3) float32 reference: ``spp`` samples per pixel split into passes of
    at most ``max_samples_per_pass`` samples (so a 1024² x 256 spp render does not build one
    268M-lane wavefront), averaged with weights ``spp_k / spp``. Pass ``k`` uses seed
    ``seed + k``. With one pass it is exactly ``mi.render(..., spp=spp, seed=seed)``."""
    spp = check_int("spp", spp, 1)
    seed = check_int("seed", seed, 0, 2**32 - 1)
    budget = check_int("max_samples_per_pass", max_samples_per_pass, 1)
    integ = _check_integrator(scene, integrator)
    w, h = scene.sensors()[0].film().crop_size()
    per_pass = max(1, min(spp, budget // max(1, w * h)))
    acc, done, k = None, 0, 0
    with _KeepSampleCount(scene):
        while done < spp:
            n = min(per_pass, spp - done)
            img = np.array(mi.render(scene, integrator=integ, spp=n, seed=seed + k),
                           dtype=np.float64)[..., :3]
            acc = img * n if acc is None else acc + img * n
            done += n
            k += 1
    return (acc / spp).astype(np.float32)
