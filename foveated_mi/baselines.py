"""Uniform baselines for equal-time comparisons: every pixel at ``spp`` samples, optionally
denoised with Intel Open Image Denoise (:mod:`foveated_mi.denoise`).

``render_uniform`` times one frame as the foveated integrator's ``timings_ms["total"]`` does:
``dr.sync_thread()`` before, the image evaluated and ``dr.sync_thread()`` after. With
``denoise=True`` the frame also renders albedo and shading normals with Mitsuba's ``aov``
integrator (``albedo:albedo,normal:sh_normal``, same ``spp`` and seed, so the auxiliary
buffers are antialiased like the colour) and runs OIDN on the three; both count in the frame
time::

    time_ms = render_ms + aov_ms + denoise_ms

**The film's filter** (``pixel_filter``). OIDN is trained on independent per-pixel noise.
``mi.render`` splats every sample through the film's filter (Mitsuba's default
``gaussian``), which spreads its noise over the neighbouring pixels, and OIDN leaves such
correlated noise in place. So with ``denoise=True`` the colour is rendered by filter
importance sampling by default (``pixel_filter="auto"`` -> ``importance``,
:class:`foveated_mi.frame.pixel_filter.FilterSampler`): each pixel averages its own
``spp`` samples, drawn from the filter around its centre, with the same expectation as
``mi.render``. On a box film both are the plain per-pixel mean, and ``mi.render`` runs.
Without ``denoise`` the frame is ``mi.render``'s own (``auto`` -> ``splat``).

**Dynamic resolution** (``scale < 1``). The frame is rendered on a film of
``round(scale * W) x round(scale * H)`` pixels (the sensor's own film, resized for the frame
and restored after it: the same camera, filter and field of view), every pixel of it at
``spp``, denoised there on request, then upscaled to the film by :func:`upscale_bilinear`::

    time_ms = render_ms (+ aov_ms + denoise_ms) + upscale_ms

The upscale runs in NumPy because the frame is already a host array here (OIDN runs on host
arrays too); a GPU engine does it in a shader for far less, which is why ``upscale_ms`` is
reported on its own.

``spp`` is always passed to ``mi.render`` explicitly. ``mi.render(spp=N)`` leaves N as the
sensor sampler's sample count, so both functions here restore the sampler's count afterwards:
a caller relying on the sensor's own count is not silently changed.
"""
from __future__ import annotations

import time
import warnings
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np

from .validate import ParameterError, check_choice, check_int, check_range

__all__ = ["render_uniform", "render_reference", "upscale_bilinear", "scaled_size",
           "AOV_INTEGRATOR"]

#: How a uniform frame honours the film's filter (see the module docstring).
PIXEL_FILTERS = ("auto", "splat", "importance")

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

    def __init__(self, scene, sensor=None):
        self.sampler = _sensor(scene, sensor).sampler()

    def __enter__(self):
        self.count = self.sampler.sample_count()
        return self

    def __exit__(self, *exc):
        self.sampler.set_sample_count(self.count)
        return False


def _sensor(scene, sensor=None) -> "mi.Sensor":
    """``sensor``, or the scene's first one when None."""
    if sensor is None:
        return scene.sensors()[0]
    if not isinstance(sensor, mi.Sensor):
        raise ParameterError("sensor", sensor, "a Mitsuba sensor (or None for the scene's own)")
    return sensor


def _timed_render(scene, integrator, spp: int, seed: int, sensor=None
                  ) -> tuple[np.ndarray, float]:
    dr.sync_thread()
    t0 = time.perf_counter()
    img = mi.render(scene, integrator=integrator, spp=spp, seed=seed,
                    sensor=_sensor(scene, sensor))
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
                   integrator: "mi.Integrator | None" = None, pixel_filter: str = "auto",
                   sensor: "mi.Sensor | None" = None, scale: float = 1.0
                   ) -> tuple[np.ndarray, dict[str, Any]]:
    """One uniform frame: every pixel traced with ``spp`` samples, denoised on request; with
    ``scale < 1``, every pixel of a smaller film, upscaled (dynamic resolution).

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    spp : int
        Samples per pixel (>= 1).
    seed : int, optional
        The render's seed, in [0, 2^32).
    denoise : bool, optional
        Denoise with OIDN, guided by an albedo and normal pass (needs ``pyoidn``).
    integrator : mi.Integrator or None, optional
        The integrator (None: the scene's own).
    pixel_filter : str, optional
        ``auto`` (``importance`` when denoised, else ``splat``), ``splat`` (``mi.render``) or
        ``importance`` (filter importance sampling, a sampling integrator only).
    sensor : mi.Sensor or None, optional
        The sensor to render (None: the scene's first; another one, e.g. one eye of a stereo
        rig, sees the same scene).
    scale : float, optional
        Render scale in (0, 1]: the frame is traced (and denoised) on a film of
        :func:`scaled_size` pixels and upscaled bilinearly to the film (1: the film itself).

    Returns
    -------
    image : numpy.ndarray
        Linear float32 (H, W, 3).
    stats : dict
        ``{"time_ms", "render_ms", "spp", "denoised", "pixel_filter"}`` (+ ``aov_ms``,
        ``denoise_ms`` when denoised); ``pixel_filter`` is the estimator that ran (``splat`` on
        a box film, or for an integrator that is not a sampling integrator under ``auto``).
        With ``scale < 1`` also ``scale``, ``size`` (the traced film's (width, height)) and
        ``upscale_ms``, which ``time_ms`` includes.

    Raises
    ------
    ParameterError
        For bad arguments, and when ``denoise`` is asked for without ``pyoidn``.
    """
    spp = check_int("spp", spp, 1)
    seed = check_int("seed", seed, 0, 2**32 - 1)
    if not isinstance(denoise, bool):
        raise ParameterError("denoise", denoise, "true or false")
    pixel_filter = check_choice("pixel_filter", pixel_filter, PIXEL_FILTERS)
    scale = check_range("scale", scale, 0.0, 1.0, lo_open=True)
    integ = _check_integrator(scene, integrator)
    if denoise:
        from .denoise import INSTALL_HINT, oidn_available
        if not oidn_available():
            raise ParameterError("denoise", True, f"pyoidn installed ({INSTALL_HINT})")
    sensor = _sensor(scene, sensor)
    mode = _uniform_pixel_filter(sensor, integ, pixel_filter, denoise)
    with _KeepSampleCount(scene, sensor):
        return _render_scaled(scene, integ, spp, seed, denoise, mode, sensor, scale)


def scaled_size(size, scale: float) -> tuple[int, int]:
    """The film a render scale traces: ``(round(scale * W), round(scale * H))``, at least one
    pixel each way.

    Parameters
    ----------
    size : tuple of int
        The film's (width, height).
    scale : float
        The render scale, in (0, 1].

    Returns
    -------
    size : tuple of int
        The traced film's (width, height).
    """
    scale = check_range("scale", scale, 0.0, 1.0, lo_open=True)
    return tuple(max(1, int(round(scale * int(n)))) for n in size)


class _ResizedFilm:
    """The sensor's film resized to ``size`` (its crop the whole film) and restored on exit:
    the same camera and filter on fewer pixels. The perspective camera keeps its horizontal
    field of view; the vertical one follows the rounded size's aspect (off by less than half
    a traced pixel)."""

    def __init__(self, sensor, size: tuple[int, int]):
        self.params = mi.traverse(sensor)
        self.size = size

    def _set(self, size, crop, offset) -> None:
        p = self.params
        p["film.size"], p["film.crop_size"] = size, crop
        p["film.crop_offset"] = offset
        p.update()

    def __enter__(self):
        p = self.params
        self.saved = (mi.ScalarVector2u(p["film.size"]), mi.ScalarVector2u(p["film.crop_size"]),
                      mi.ScalarPoint2u(p["film.crop_offset"]))
        self._set(mi.ScalarVector2u(self.size), mi.ScalarVector2u(self.size),
                  mi.ScalarPoint2u(0, 0))
        return self

    def __exit__(self, *exc):
        self._set(*self.saved)
        return False


def _render_scaled(scene, integ, spp, seed, denoise, mode, sensor, scale):
    """A uniform frame at render scale ``scale`` (module docstring), as :func:`_render_uniform`
    on the smaller film, then upscaled; the upscale counts in ``time_ms``. Scale 1 is
    :func:`_render_uniform`'s frame itself."""
    if scale == 1.0:
        return _render_uniform(scene, integ, spp, seed, denoise, mode, sensor)
    film = sensor.film()
    full = tuple(int(v) for v in film.size())
    if tuple(int(v) for v in film.crop_size()) != full:
        raise ParameterError("scale", scale, "1 for a film with a crop window (dynamic "
                             "resolution scales the whole film)")
    size = scaled_size(full, scale)
    with _ResizedFilm(sensor, size):
        low, stats = _render_uniform(scene, integ, spp, seed, denoise, mode, sensor)
    t0 = time.perf_counter()
    image = upscale_bilinear(low, full)
    upscale_ms = (time.perf_counter() - t0) * 1e3
    stats.update(scale=scale, size=size, upscale_ms=upscale_ms,
                 time_ms=stats["time_ms"] + upscale_ms)
    return image, stats


def upscale_bilinear(image: np.ndarray, size) -> np.ndarray:
    """Bilinear resize of an (h, w, C) image to ``size`` = (W, H), pixel centres aligned.

    Output pixel ``x`` samples the input at ``u = (x + 0.5) * w / W - 0.5`` (the convention
    of GPU texture filtering and ``skimage.transform.resize(order=1)``), clamped to the edge
    pixels. Linear functions are reproduced exactly (to float32 rounding) wherever ``u``
    needs no clamp, and a constant image stays that constant exactly.

    Parameters
    ----------
    image : numpy.ndarray
        (h, w, C) float image.
    size : tuple of int
        The output's (width, height), each >= 1.

    Returns
    -------
    image : numpy.ndarray
        (H, W, C) float32.
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 3 or min(img.shape) < 1:
        raise ParameterError("image", f"an array of shape {img.shape}", "an (h, w, C) image")
    if not (isinstance(size, (tuple, list)) and len(size) == 2):
        raise ParameterError("size", size, "the output's (width, height)")
    width, height = (check_int("size", n, 1) for n in size)

    def taps(n_out: int, n_in: int):
        u = np.clip((np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5, 0.0, n_in - 1)
        i0 = np.floor(u).astype(np.intp)
        i1 = np.minimum(i0 + 1, n_in - 1)
        return i0, i1, (u - i0).astype(np.float32)

    y0, y1, fy = taps(height, img.shape[0])
    x0, x1, fx = taps(width, img.shape[1])
    # Separable, each pass gathering whole rows (contiguous): along x on the short image,
    # transposed, then along y. a + (b - a) * f, in place, keeps a constant exact.
    cols = np.ascontiguousarray(img.transpose(1, 0, 2))
    a, d = cols[x0], cols[x1]
    d -= a
    d *= fx[:, None, None]
    a += d
    rows = np.ascontiguousarray(a.transpose(1, 0, 2))
    a, d = rows[y0], rows[y1]
    d -= a
    d *= fy[:, None, None]
    a += d
    return a


def _uniform_pixel_filter(sensor, integ, pixel_filter: str, denoise: bool) -> str:
    """The estimator a uniform frame runs: ``splat`` (``mi.render``) or ``importance``."""
    sampling = _samples_rays(integ)
    if pixel_filter == "importance" and not sampling:
        raise ParameterError("integrator", type(integ).__name__, "a sampling integrator "
                             "(such as 'path') for pixel_filter = 'importance', or "
                             "pixel_filter = 'splat'")
    box = sensor.film().rfilter().is_box_filter()
    if pixel_filter == "splat" and denoise and not box:
        from .options import splat_warning
        warnings.warn(splat_warning("denoise = True", "OIDN", "= 'auto'"), UserWarning,
                      stacklevel=3)
    if pixel_filter == "auto":
        pixel_filter = "importance" if denoise and sampling else "splat"
    # On a box film both estimators are the per-pixel mean: mi.render's is the same frame.
    return "splat" if box else pixel_filter


def _samples_rays(integ) -> bool:
    """Whether ``integ`` shades any ray through ``sample()``: one of Mitsuba's sampling
    integrators, or a Python one that defines ``sample`` (not one that only overrides
    ``render``, such as the foveated integrator)."""
    if not isinstance(integ, mi.SamplingIntegrator):
        return False
    mro = type(integ).__mro__
    own = mro[:mro.index(mi.SamplingIntegrator)]
    return type(integ).__module__.startswith("mitsuba") or any("sample" in c.__dict__
                                                                for c in own)


def _timed_importance(scene, integ, spp: int, seed: int, sensor=None
                      ) -> tuple[np.ndarray, float]:
    """A uniform frame by filter importance sampling: every pixel's ``spp`` samples drawn
    from the film's filter around its centre and averaged (the foveated integrator's
    ``pixel_filter = "importance"`` estimator with every pixel traced), timed like
    :func:`_timed_render`."""
    from .frame.pixel_filter import FilterSampler
    from .frame.shading import develop_mean, trace_wavefront
    sensor = _sensor(scene, sensor)
    film = sensor.film()
    width, height = (int(v) for v in film.crop_size())
    # Tabulating the filter reads it back to the host: set-up, like mi.render's film.
    sampler = FilterSampler(film, importance=True)
    dr.sync_thread()
    t0 = time.perf_counter()
    pixels = dr.arange(mi.UInt32, width * height)
    # No clamp, as mi.render (a non-finite sample is dropped here).
    samples = trace_wavefront(scene, sensor, integ, pixels, width, height, spp=spp,
                              seed=dr.opaque(mi.UInt32, seed), clamp=_NO_CLAMP,
                              filter_sampler=sampler)
    value = develop_mean(samples, pixels, spp, width * height).value
    dr.eval(value)
    dr.sync_thread()
    ms = (time.perf_counter() - t0) * 1e3
    img = np.array(mi.TensorXf(dr.ravel(value), shape=(height, width, 3)), dtype=np.float32)
    return img, ms


#: Larger than any finite float32 sample: :func:`trace_wavefront` then clamps nothing.
_NO_CLAMP = float(np.finfo(np.float32).max)


def _render_uniform(scene, integ, spp, seed, denoise, mode, sensor=None):
    if mode == "importance":
        color, render_ms = _timed_importance(scene, integ, spp, seed, sensor)
    else:
        color, render_ms = _timed_render(scene, integ, spp, seed, sensor)
    color = color[..., :3]
    stats: dict[str, Any] = {"spp": spp, "denoised": denoise, "render_ms": render_ms,
                             "pixel_filter": mode}
    if not denoise:
        stats["time_ms"] = render_ms
        return color, stats
    from .denoise import denoise as oidn
    aux, aov_ms = _timed_render(scene, _aov_integrator(), spp, seed, sensor)
    t0 = time.perf_counter()
    image = oidn(color, aux[..., 0:3], aux[..., 3:6], hdr=True)
    denoise_ms = (time.perf_counter() - t0) * 1e3
    stats.update(aov_ms=aov_ms, denoise_ms=denoise_ms, time_ms=render_ms + aov_ms + denoise_ms)
    return image, stats


def render_reference(scene: "mi.Scene", *, spp: int, seed: int = 0,
                     integrator: "mi.Integrator | None" = None,
                     max_samples_per_pass: int = 1 << 24,
                     sensor: "mi.Sensor | None" = None) -> np.ndarray:
    """A converged reference: ``spp`` samples per pixel split into passes, averaged.

    Passes hold at most ``max_samples_per_pass`` samples (so a 1024² x 256 spp render does not
    build one 268M-lane wavefront) and are averaged with weights ``spp_k / spp``. Pass ``k`` uses
    seed ``seed + k``. With one pass it is exactly ``mi.render(..., spp=spp, seed=seed)``.

    Parameters
    ----------
    scene, spp, integrator
        As for :func:`render_uniform`.
    seed : int, optional
        Seed of the first pass, in [0, 2^32).
    max_samples_per_pass : int, optional
        Largest number of samples (pixels x spp) of one pass.
    sensor : mi.Sensor or None, optional
        As for :func:`render_uniform`.

    Returns
    -------
    reference : numpy.ndarray
        Linear float32 (H, W, 3).
    """
    spp = check_int("spp", spp, 1)
    seed = check_int("seed", seed, 0, 2**32 - 1)
    budget = check_int("max_samples_per_pass", max_samples_per_pass, 1)
    integ = _check_integrator(scene, integrator)
    sensor = _sensor(scene, sensor)
    w, h = sensor.film().crop_size()
    per_pass = max(1, min(spp, budget // max(1, w * h)))
    acc, done, k = None, 0, 0
    with _KeepSampleCount(scene, sensor):
        while done < spp:
            n = min(per_pass, spp - done)
            img = np.array(mi.render(scene, integrator=integ, spp=n, seed=seed + k,
                                     sensor=sensor), dtype=np.float64)[..., :3]
            acc = img * n if acc is None else acc + img * n
            done += n
            k += 1
    return (acc / spp).astype(np.float32)


def traced_fraction(image: np.ndarray, stats: dict) -> float:
    """The share of the film's pixels a uniform frame traced: 1, or its scaled film's."""
    w, h = stats.get("size", image.shape[1::-1])
    return w * h / (image.shape[0] * image.shape[1])
