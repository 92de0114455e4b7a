r"""Intel Open Image Denoise as a pipeline stage (``denoiser = "oidn"``).

OIDN's ``RT`` filter (a trained U-Net) denoises the remodulated radiance, guided by the
G-buffer's albedo and normal (:func:`foveated_mi.denoise.denoise`). It is trained on renders
whose noise is independent from pixel to pixel, which the stochastic reconstruction
(:mod:`foveated_mi.reconstruct.stochastic`) provides in the sparse periphery.

**A stage boundary.** OIDN runs outside Dr.Jit on materialised host buffers: this stage
evaluates its inputs and synchronises, the one place where a frame leaves the JIT. It is
optional (``pip install -e '.[denoise]'`` from a clone) and **not differentiable**: a
gradient pass of a frame that used it raises (see
:class:`foveated_mi.integrators.foveated.FoveatedIntegrator`).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ..denoise import denoise


def _host(v, width: int, height: int) -> np.ndarray:
    """(H, W, 3) float32 copy of a 3 x N Dr.Jit array."""
    return np.ascontiguousarray(np.asarray(v.numpy(), dtype=np.float32).T.reshape(height, width, 3))


def oidn(color: mi.Color3f, albedo: mi.Color3f | None, normal: mi.Vector3f | None, width: int,
         height: int, *, quality: str = "high", clean_aux: bool = False) -> mi.Color3f:
    """``color`` denoised by OIDN, guided by ``albedo`` and ``normal`` when given.

    Non-finite input values are treated as 0 (OIDN would spread them)."""
    c = dr.select(dr.isfinite(color), dr.detach(color), 0.0)
    aux = [a for a in (albedo, normal) if a is not None]
    dr.eval(c, *aux)
    out = denoise(_host(c, width, height),
                  None if albedo is None else _host(albedo, width, height),
                  None if normal is None else _host(normal, width, height),
                  hdr=True, quality=quality, clean_aux=clean_aux)
    return mi.Color3f(mi.Float(out[..., 0].ravel()), mi.Float(out[..., 1].ravel()),
                      mi.Float(out[..., 2].ravel()))
