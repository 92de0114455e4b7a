"""Intel Open Image Denoise through ``pyoidn`` (optional: ``pip install -e '.[denoise]' (from a clone)``).

:func:`denoise` is a validated wrapper over :func:`pyoidn.denoise` with OIDN's ``RT`` filter:
colour, and optionally albedo and normal, as float32 (H, W, 3) arrays (copied to C-contiguous
float32 here; pyoidn rejects float64). The filter is a trained U-Net, not a formula: it
estimates the noise-free image from the noisy colour, guided by the auxiliary buffers.
Normals may be world-space in [-1, 1] (Mitsuba's ``aov`` integrator, ``sh_normal``); albedo
in [0, 1]. ``hdr=True`` for linear radiance (any value >= 0).

Device and filter reuse: ``pyoidn.denoise`` already keeps one committed CPU device and one
filter per filter type for the whole process and only rebinds the images and re-commits the
filter per call. A wrapper that instead kept a ``pyoidn.Device`` / ``pyoidn.Filter`` with
persistent image buffers of a fixed size (copy in, ``execute()``, copy out) measured the same,
with bit-identical outputs (``docs/results.md#oidns-device-and-filter-reuse``). So
:func:`denoise` on the CPU device calls ``pyoidn.denoise``. Only the first call of a process
pays for the device. The other paths below (OIDN buffers, memory owned by Dr.Jit) keep one
device and one filter per device kind in the same way (:func:`run_filter`).

**Device choice.** OIDN runs on its CPU device, or on its CUDA device on a ``cuda_*`` variant
when ``pyoidn`` reports one (:func:`oidn_cuda_available`): :func:`choose_device` decides,
from the variant, the request and the availability. The request is the ``device`` argument,
else ``$FOVEATED_MI_OIDN_DEVICE`` (``auto``, ``cpu`` or ``cuda``; unset means ``auto``).
``cuda`` is refused with one line on a non-CUDA variant or without an OIDN CUDA device.
pyoidn 2.5's one-call API takes NumPy arrays on the CPU device, or PyTorch tensors; its
``Device`` / ``Buffer`` / ``Filter`` classes also take raw device pointers
(``Buffer.shared``). :func:`denoise` (NumPy in and out) on the CUDA device therefore copies
its images into OIDN device buffers and back; :func:`foveated_mi.postprocess.oidn` hands
OIDN the pointers of Dr.Jit's own CUDA arrays instead, so a frame never leaves the GPU.
"""
from __future__ import annotations

import importlib.util
import logging
import os
import threading

import numpy as np

from .validate import ParameterError, check_choice

__all__ = ["oidn_available", "oidn_cuda_available", "denoise", "choose_device",
           "requested_device", "resolve_device", "last_device", "QUALITIES", "DEVICES",
           "DEVICE_ENV", "INSTALL_HINT"]

QUALITIES = ("high", "balanced", "fast", "default")
DEVICES = ("auto", "cpu", "cuda")
DEVICE_ENV = "FOVEATED_MI_OIDN_DEVICE"
INSTALL_HINT = "pip install -e '.[denoise]' (from a clone)"
_log = logging.getLogger("foveated_mi")


def oidn_available() -> bool:
    """Whether ``pyoidn`` (Intel Open Image Denoise) can be imported.

    Returns
    -------
    available : bool
        Found without importing it.
    """
    return importlib.util.find_spec("pyoidn") is not None


def oidn_cuda_available(device_id: int = 0) -> bool:
    """Whether ``pyoidn`` offers OIDN's CUDA device for CUDA device ``device_id``.

    Parameters
    ----------
    device_id : int, optional
        The CUDA device.

    Returns
    -------
    available : bool
        False without ``pyoidn``, or when its CUDA module fails.
    """
    if not oidn_available():
        return False
    try:
        import pyoidn
        return bool(pyoidn.Device.is_cuda_available(int(device_id)))
    except Exception:  # a broken CUDA module of OIDN counts as no CUDA device
        return False


def choose_device(variant: str | None, requested: str = "auto", cuda_available: bool = False,
                  name: str = DEVICE_ENV) -> str:
    """OIDN's device (``"cpu"`` or ``"cuda"``) for frames of ``variant``: a pure decision.

    Parameters
    ----------
    variant : str or None
        The Mitsuba variant.
    requested : str, optional
        ``auto``: CUDA on a ``cuda_*`` variant when ``cuda_available``, else CPU. ``cpu``: CPU
        on any variant (a CUDA frame then goes through host memory). ``cuda``: CUDA, refused with
        one line (:class:`ParameterError` naming ``name``) on another variant or without the
        device.
    cuda_available : bool, optional
        Whether OIDN's CUDA device exists (:func:`oidn_cuda_available`).
    name : str, optional
        The request's name in an error message.

    Returns
    -------
    device : str
        ``"cpu"`` or ``"cuda"``.
    """
    check_choice(name, requested, DEVICES)
    on_cuda = isinstance(variant, str) and variant.startswith("cuda_")
    if requested == "cuda":
        if not on_cuda:
            raise ParameterError(name, requested, f"'auto' or 'cpu' on the {variant!r} variant "
                                 "(OIDN's CUDA device needs a cuda_* variant)")
        if not cuda_available:
            raise ParameterError(name, requested, "'auto' or 'cpu': pyoidn offers no OIDN "
                                 "CUDA device on this machine")
        return "cuda"
    if requested == "cpu":
        return "cpu"
    return "cuda" if on_cuda and cuda_available else "cpu"


def requested_device(device: str | None = None) -> tuple[str, str]:
    """The OIDN device requested: ``device`` when given, else ``$FOVEATED_MI_OIDN_DEVICE``.

    Parameters
    ----------
    device : str or None, optional
        ``auto``, ``cpu`` or ``cuda``; None reads the environment variable (unset or empty:
        ``auto``).

    Returns
    -------
    request : str
        The validated request.
    name : str
        The name an error should carry (``device`` or the variable's).
    """
    if device is not None:
        return check_choice("device", device, DEVICES), "device"
    value = os.environ.get(DEVICE_ENV, "").strip() or "auto"
    return check_choice(DEVICE_ENV, value, DEVICES), DEVICE_ENV


def resolve_device(variant: str | None, device: str | None = None, device_id: int = 0) -> str:
    """:func:`choose_device` for ``variant`` with the request of :func:`requested_device`; asks
    ``pyoidn`` about CUDA only on a ``cuda_*`` variant.

    Parameters
    ----------
    variant : str or None
        The Mitsuba variant.
    device : str or None, optional
        The request (None: ``$FOVEATED_MI_OIDN_DEVICE``, else ``auto``).
    device_id : int, optional
        The CUDA device.

    Returns
    -------
    device : str
        ``"cpu"`` or ``"cuda"``.
    """
    request, name = requested_device(device)
    on_cuda = isinstance(variant, str) and variant.startswith("cuda_")
    cuda = on_cuda and request != "cpu" and oidn_cuda_available(device_id)
    return choose_device(variant, request, cuda, name)


_last_device: str | None = None
_logged: set = set()


def last_device() -> str | None:
    """The device (``"cpu"`` / ``"cuda"``) of the last OIDN call of this process, or None.

    Returns
    -------
    device : str or None
        None before the first call.
    """
    return _last_device


def _used(device: str, variant: str | None) -> None:
    """Record the device of a call; the first call on each device logs one line."""
    global _last_device
    _last_device = device
    if device not in _logged:
        _logged.add(device)
        _log.info("OIDN denoises on its %s device (variant %s)", device.upper(), variant)


def _variant() -> str | None:
    import mitsuba as mi
    return mi.variant()


# --------------------------------------------------------------------- OIDN devices and filters
_QUALITY_CODES = {"default": 0, "fast": 4, "balanced": 5, "high": 6}  # OIDN_QUALITY_*
_FORMAT_FLOAT3 = 3                                                    # OIDN_FORMAT_FLOAT3
_lock = threading.RLock()
_filters: dict[tuple[str, int], tuple] = {}   # (device, CUDA id) -> (pyoidn Device, RT Filter)


def _check(device, kind: str, what: str) -> None:
    from pyoidn.capi import oidn_Capi, oidn_ffi
    msg = oidn_ffi.new("const char**")
    code = int(oidn_Capi.oidnGetDeviceError(device._device, msg))
    if code:
        text = oidn_ffi.string(msg[0]).decode(errors="replace") if msg[0] != oidn_ffi.NULL else ""
        raise RuntimeError(f"OIDN {what} failed on its {kind.upper()} device "
                           f"(error {code}): {text or 'no message'}")


def _filter(kind: str, device_id: int = 0):
    """The committed OIDN device of ``kind`` (CUDA: on device ``device_id``, default stream)
    and its ``RT`` filter, created once per process."""
    key = (kind, int(device_id) if kind == "cuda" else 0)
    if key not in _filters:
        import pyoidn
        from pyoidn.capi import oidn_Capi, oidn_ffi
        if kind == "cuda":
            dev = pyoidn.Device.__new__(pyoidn.Device)
            dev._device = oidn_Capi.oidnNewCUDADevice(
                oidn_ffi.new("int[]", [key[1]]),
                oidn_ffi.new("cudaStream_t[]", [oidn_ffi.NULL]), 1)
        else:
            dev = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
        _check(dev, kind, "device creation")
        dev.commit()
        _check(dev, kind, "device commit")
        flt = pyoidn.Filter(dev, pyoidn.OIDN_FILTER_TYPE_RT)
        _check(dev, kind, "filter creation")
        _filters[key] = (dev, flt)
    return _filters[key]


def run_filter(kind: str, images: dict, width: int, height: int, *, device_id: int = 0,
               hdr: bool = True, quality: str = "high", clean_aux: bool = False) -> None:
    """Run OIDN's ``RT`` filter on the ``kind`` device, synchronously.

    Parameters
    ----------
    kind : str
        ``"cpu"`` or ``"cuda"``.
    images : dict
        ``color`` / ``albedo`` / ``normal`` / ``output`` to tightly packed float32 RGB that
        device can read: an ``(address, bytes)`` pair (memory owned elsewhere, wrapped without a
        copy) or a ``pyoidn.Buffer`` of that device. ``output`` is written.
    width, height : int
        Image size, in pixels.
    device_id : int, optional
        The CUDA device.
    hdr : bool, optional
        The colour is linear radiance (any value >= 0).
    quality : str, optional
        One of :data:`QUALITIES`.
    clean_aux : bool, optional
        The auxiliary images are noise-free (only with an albedo).
    """
    import pyoidn
    with _lock:
        dev, flt = _filter(kind, device_id)
        bufs = []
        try:
            for name in ("albedo", "normal"):
                if name not in images:
                    flt.unset_image(name)
            for name, image in images.items():
                if not isinstance(image, pyoidn.Buffer):
                    image = pyoidn.Buffer.shared(dev, int(image[0]), int(image[1]))
                    bufs.append(image)
                flt.set_image(name, image, _FORMAT_FLOAT3, width, height)
            flt.set_bool("hdr", hdr)
            flt.set_bool("cleanAux", clean_aux and "albedo" in images)
            flt.set_quality(_QUALITY_CODES[quality])
            flt.commit()
            _check(dev, kind, "filter commit")
            flt.execute()
            _check(dev, kind, "filter execution")
        finally:
            for name in images:       # no pointer outlives this call
                flt.unset_image(name)
            for buf in bufs:
                buf.release()


def _denoise_device_copy(kind: str, images: dict[str, np.ndarray], hdr: bool, quality: str,
                         clean_aux: bool, device_id: int = 0) -> np.ndarray:
    """NumPy images through OIDN buffers on the ``kind`` device: copied in, filtered, copied out."""
    import pyoidn
    h, w, _ = images["color"].shape
    out = np.empty_like(images["color"])
    nbytes = out.nbytes
    with _lock:
        dev, _ = _filter(kind, device_id)
        bufs = {name: pyoidn.Buffer(dev, nbytes) for name in (*images, "output")}
        try:
            for name, arr in images.items():
                bufs[name].write(0, nbytes, arr)
            _check(dev, kind, "buffer upload")
            run_filter(kind, bufs, w, h, device_id=device_id, hdr=hdr, quality=quality,
                       clean_aux=clean_aux)
            bufs["output"].read(0, nbytes, out)
            _check(dev, kind, "buffer download")
        finally:
            for b in bufs.values():
                b.release()
    return out


def _image(name: str, value, shape: tuple[int, ...] | None) -> np.ndarray:
    arr = np.asarray(value)
    allowed = "a finite real (H, W, 3) array" + (
        f" of the colour's shape {shape}" if shape is not None else " with H, W >= 1")
    if arr.ndim != 3 or arr.shape[2] != 3 or 0 in arr.shape or not (
            np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)) \
            or (shape is not None and arr.shape != shape):
        raise ParameterError(name, f"{arr.dtype} array of shape {arr.shape}", allowed)
    arr = np.ascontiguousarray(arr, dtype=np.float32)
    bad = int(np.count_nonzero(~np.isfinite(arr)))
    if bad:
        raise ParameterError(name, f"array with {bad} NaN/inf values (after float32 "
                             "conversion)", allowed)
    return arr


def denoise(color, albedo=None, normal=None, *, hdr: bool = True,
            quality: str = "high", clean_aux: bool = False,
            device: str | None = None) -> np.ndarray:
    """Denoised copy of ``color`` by OIDN's ``RT`` filter.

    Bad input, and a missing ``pyoidn``, raise a one-line :class:`ParameterError`.

    Parameters
    ----------
    color : array_like
        (H, W, 3), finite; negative values are clamped to 0 for HDR input (OIDN's HDR mode
        expects radiance >= 0), LDR input must lie in [0, 1].
    albedo, normal : array_like or None, optional
        Guides of the same shape; OIDN requires albedo whenever normal is given.
    hdr : bool, optional
        ``color`` is linear radiance.
    quality : str, optional
        One of :data:`QUALITIES`.
    clean_aux : bool, optional
        The guides are noise-free (OIDN then skips prefiltering them); even for a noise-free
        G-buffer sampled at pixel centres, leaving it off measured better (OIDN's prefilter also
        anti-aliases them).
    device : str or None, optional
        ``auto`` | ``cpu`` | ``cuda`` (None: ``$FOVEATED_MI_OIDN_DEVICE``, else ``auto``; see
        :func:`choose_device`); on the CUDA device the images go through OIDN device buffers.

    Returns
    -------
    image : numpy.ndarray
        float32 (H, W, 3).
    """
    if not oidn_available():
        raise ParameterError("denoise", True, f"pyoidn installed for the OIDN denoiser "
                             f"({INSTALL_HINT})")
    if not isinstance(hdr, bool):
        raise ParameterError("hdr", hdr, "true or false")
    check_choice("quality", quality, QUALITIES)
    if not isinstance(clean_aux, bool):
        raise ParameterError("clean_aux", clean_aux, "true or false")
    c = _image("color", color, None)
    a = None if albedo is None else _image("albedo", albedo, c.shape)
    n = None if normal is None else _image("normal", normal, c.shape)
    if n is not None and a is None:
        raise ParameterError("albedo", None, "an albedo image whenever normal is given (OIDN)")
    if hdr:
        c = np.maximum(c, 0.0)
    elif c.min() < 0.0 or c.max() > 1.0:
        raise ParameterError("color", f"array with values in [{c.min():g}, {c.max():g}]",
                             "values in [0, 1] for hdr=False (LDR)")
    variant = _variant()
    kind = resolve_device(variant, device)
    _used(kind, variant)
    if kind == "cuda":
        images = {"color": c, **({} if a is None else {"albedo": a}),
                  **({} if n is None else {"normal": n})}
        return _denoise_device_copy("cuda", images, hdr, quality, clean_aux)
    import pyoidn

    out = pyoidn.denoise(c, a, n, hdr=hdr, quality=quality, clean_aux=clean_aux and a is not None)
    return np.asarray(out, dtype=np.float32)
