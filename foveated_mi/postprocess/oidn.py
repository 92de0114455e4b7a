r"""Intel Open Image Denoise as a pipeline stage (``denoiser = "oidn"``).

OIDN's ``RT`` filter (a trained U-Net) denoises the remodulated radiance, guided by the
G-buffer's albedo and normal (:func:`foveated_mi.denoise.denoise`). It is trained on renders
whose noise is independent from pixel to pixel, which the stochastic reconstruction
(:mod:`foveated_mi.reconstruct.stochastic`) provides in the sparse periphery.

**A stage boundary.** OIDN runs outside Dr.Jit on materialised buffers: this stage
evaluates its inputs and synchronises, the one place where a frame leaves the JIT. It is
optional (``pip install -e '.[denoise]'`` from a clone) and **not differentiable**: a
gradient pass of a frame that used it raises (see
:class:`foveated_mi.integrators.foveated.FoveatedIntegrator`).

**Device.** :func:`foveated_mi.denoise.resolve_device` picks OIDN's device: on a ``cuda_*``
variant its CUDA device when pyoidn offers one, else its CPU device;
``$FOVEATED_MI_OIDN_DEVICE`` (or ``device=``) forces ``cpu`` or ``cuda``. Where the device
can read Dr.Jit's memory (the CUDA device on a CUDA variant, the CPU device on an LLVM one),
OIDN reads and writes Dr.Jit's own arrays in place (their addresses from DLPack): the colour
and guides are interleaved to ``RGBRGB...`` by one kernel, OIDN filters, and the result is
read back by another, with no NumPy array and no copy between host and GPU. The stage still
synchronises once, so that the inputs are complete when OIDN starts. Only the CPU device
forced on a CUDA variant goes through host memory (NumPy). The first call on a device logs
the device, and :func:`foveated_mi.denoise.last_device` names the last one used.
"""
from __future__ import annotations

import ctypes

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import denoise as _dn
from ..denoise import denoise
from ..validate import ParameterError, check_choice
from .registry import DenoiseInput, Denoised, register_denoiser


def _host(v, width: int, height: int) -> np.ndarray:
    """(H, W, 3) float32 copy of a 3 x N Dr.Jit array."""
    return np.ascontiguousarray(np.asarray(v.numpy(), dtype=np.float32).T.reshape(height, width, 3))


class _DLDevice(ctypes.Structure):
    _fields_ = [("type", ctypes.c_int32), ("id", ctypes.c_int32)]


class _DLTensor(ctypes.Structure):  # DLPack's DLTensor, the head of its DLManagedTensor
    _fields_ = [("data", ctypes.c_void_p), ("device", _DLDevice), ("ndim", ctypes.c_int32),
                ("code", ctypes.c_uint8), ("bits", ctypes.c_uint8), ("lanes", ctypes.c_uint16),
                ("shape", ctypes.POINTER(ctypes.c_int64)),
                ("strides", ctypes.POINTER(ctypes.c_int64)), ("byte_offset", ctypes.c_uint64)]


_capsule_pointer = ctypes.pythonapi.PyCapsule_GetPointer
_capsule_pointer.restype = ctypes.c_void_p
_capsule_pointer.argtypes = [ctypes.py_object, ctypes.c_char_p]


def _address(v: mi.Float) -> tuple[int, int, tuple[int, int], object]:
    """``(address, bytes, (DLPack device type, device id), capsule)`` of an evaluated flat
    ``mi.Float`` (device type 1: host memory, 2: CUDA memory).

    The capsule keeps the memory alive; the array must stay unchanged while it is used."""
    cap = v.__dlpack__()
    t = _DLTensor.from_address(_capsule_pointer(cap, b"dltensor"))
    n = dr.width(v)
    if t.ndim != 1 or (t.code, t.bits, t.lanes) != (2, 32, 1) or t.shape[0] != n \
            or (bool(t.strides) and t.strides[0] != 1):
        raise RuntimeError("Dr.Jit exported an unexpected DLPack layout for a Float array")
    return t.data + t.byte_offset, 4 * n, (int(t.device.type), int(t.device.id)), cap


def _denoise_in_place(c: mi.Color3f, albedo, normal, width: int, height: int, *, kind: str,
                      quality: str, clean_aux: bool) -> mi.Color3f:
    """OIDN on the ``kind`` device over Dr.Jit's own memory (see the module docstring)."""
    check_choice("quality", quality, _dn.QUALITIES)
    if normal is not None and albedo is None:
        raise ParameterError("albedo", None, "an albedo image whenever normal is given (OIDN)")
    n = width * height
    flat = {"color": dr.ravel(dr.maximum(c, 0.0), order="F")}  # HDR input is radiance >= 0
    for name, v in (("albedo", albedo), ("normal", normal)):
        if v is not None:
            flat[name] = dr.ravel(mi.Color3f(dr.detach(v)), order="F")
    out = dr.empty(mi.Float, 3 * n)
    dr.make_opaque(out)                 # allocated now, so that OIDN has somewhere to write
    dr.eval(*flat.values())
    dr.sync_thread()                    # the inputs are complete before OIDN reads them
    held = {name: _address(v) for name, v in {**flat, "output": out}.items()}
    where = {h[2][0] for h in held.values()}
    if where != {2 if kind == "cuda" else 1}:
        raise RuntimeError(f"OIDN's {kind.upper()} device cannot read Dr.Jit's arrays on "
                           f"the {mi.variant()} variant (DLPack device types {sorted(where)})")
    device_id = held["output"][2][1]
    _dn.run_filter(kind, {name: h[:2] for name, h in held.items()}, width, height,
                   device_id=device_id, hdr=True, quality=quality, clean_aux=clean_aux)
    return dr.unravel(mi.Color3f, out, order="F")


def oidn(color: mi.Color3f, albedo: mi.Color3f | None, normal: mi.Vector3f | None, width: int,
         height: int, *, quality: str = "high", clean_aux: bool = False,
         device: str | None = None) -> mi.Color3f:
    """``color`` denoised by OIDN, guided by ``albedo`` and ``normal`` when given.

    Non-finite input values are treated as 0 (OIDN would spread them).

    Parameters
    ----------
    color : mi.Color3f
        HDR radiance to denoise (detached: OIDN has no gradient).
    albedo : mi.Color3f or None
        Albedo guide (required whenever ``normal`` is given).
    normal : mi.Vector3f or None
        Normal guide.
    width, height : int
        Film size, in pixels.
    quality : str, optional
        OIDN's filter quality.
    clean_aux : bool, optional
        The guides are noise-free.
    device : str or None, optional
        ``auto`` | ``cpu`` | ``cuda`` (default: ``$FOVEATED_MI_OIDN_DEVICE``, else ``auto``; see
        :func:`foveated_mi.denoise.choose_device`).

    Returns
    -------
    color : mi.Color3f
        The denoised image.

    Raises
    ------
    ParameterError
        If pyoidn is not installed.
    """
    if not _dn.oidn_available():
        raise ParameterError("denoise", True, f"pyoidn installed for the OIDN denoiser "
                             f"({_dn.INSTALL_HINT})")
    variant = mi.variant()
    kind = _dn.resolve_device(variant, device)
    c = dr.select(dr.isfinite(color), dr.detach(color), 0.0)
    if (kind == "cuda") == variant.startswith("cuda_"):   # OIDN can read Dr.Jit's memory
        _dn._used(kind, variant)
        return _denoise_in_place(c, albedo, normal, width, height, kind=kind, quality=quality,
                                 clean_aux=clean_aux)
    # OIDN's CPU device on a CUDA variant: through host memory.
    aux = [a for a in (albedo, normal) if a is not None]
    dr.eval(c, *aux)
    out = denoise(_host(c, width, height),
                  None if albedo is None else _host(albedo, width, height),
                  None if normal is None else _host(normal, width, height),
                  hdr=True, quality=quality, clean_aux=clean_aux, device="cpu")
    return mi.Color3f(mi.Float(out[..., 0].ravel()), mi.Float(out[..., 1].ravel()),
                      mi.Float(out[..., 2].ravel()))


def oidn_stage(ctx: DenoiseInput) -> Denoised:
    """The ``oidn`` denoiser of a frame: :func:`oidn` on the radiance, guided by the G-buffer's
    albedo and normal (a stage boundary).

    Parameters
    ----------
    ctx : DenoiseInput
        The frame's image, G-buffer and options (``oidn_quality``, ``clamp``).

    Returns
    -------
    denoised : Denoised
        The denoised image, clamped at ``clamp`` (the network may overshoot), as both the image
        and the filtered buffer.
    """
    gb = ctx.gbuffer
    image = dr.minimum(oidn(ctx.image, gb.albedo, gb.normal, ctx.width, ctx.height,
                            quality=ctx.options["oidn_quality"]),
                       dr.opaque(mi.Float, ctx.options["clamp"]))   # the network may overshoot
    return Denoised(image, filtered=image)


# Trained on independent per-pixel noise: splatted (correlated) noise is left in place.
register_denoiser("oidn", oidn_stage, differentiable=False, materials=True,
                  independent_noise=True, available=lambda: _dn.oidn_available(),
                  requirement=f"pyoidn installed ({_dn.INSTALL_HINT})",
                  reads=("oidn_quality", "clamp"))
