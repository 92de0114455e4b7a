"""Post-processing pass (Kwon et al. 2019, §3.5): the denoiser, and the albedo multiplied back.

One call of the registered denoiser (:data:`foveated_mi.postprocess.DENOISERS`) per frame,
on a :class:`~foveated_mi.postprocess.DenoiseInput`. A denoiser registered with
``demodulated=True`` (``svgf``) filters the reconstruction's own values before the albedo
is multiplied back (:mod:`foveated_mi.frame.demodulate`); the others (``atrous``, ``oidn``)
filter radiance after it. A gradient pass skips a non-differentiable denoiser (the gradient
pass of a frame that used one raises before it gets here).
"""
from __future__ import annotations

from typing import Any, NamedTuple

import drjit as dr
import mitsuba as mi

from ..postprocess import DENOISERS, DenoiseInput, Denoised
from ..postprocess.registry import as_denoised
from ..kernels import remodulate
from ..kernels.buffers import GBuffer, Resolved
from .reconstruction import Reconstruction


#: Options the post-processing pass reads besides those its denoiser declares.
READS = ("denoiser", "demodulate", "clamp")


def reads(o: dict[str, Any]) -> tuple[str, ...]:
    """The options the post-processing pass reads with the denoiser of ``o``."""
    return READS + DENOISERS[o["denoiser"]].reads


class PostProcessed(NamedTuple):
    image: mi.Color3f                 #: the frame's radiance
    filled: mi.Color3f                #: Voronoi fill, radiance
    interpolated: mi.Color3f          #: interpolation, radiance
    tonemapped: mi.Color3f | None     #: the denoiser's buffers (None where it has none)
    filtered: mi.Color3f | None
    variance: mi.Float | None


def post_pass(recon: Reconstruction, resolved: Resolved, gb: GBuffer, width: int, height: int,
              o: dict[str, Any], grad_pass: bool = False) -> PostProcessed:
    """The denoiser of ``o["denoiser"]`` and remodulation (module docstring)."""
    entry = DENOISERS[o["denoiser"]]
    run = entry.differentiable or not grad_pass
    ctx = DenoiseInput(recon.interpolated, gb, resolved, recon.nearest, width, height,
                       {k: o[k] for k in entry.reads}, grad_pass, recon.samples)
    out = Denoised(recon.interpolated)
    if entry.demodulated and run:
        out = as_denoised(entry.fn(ctx))
    filled, interpolated = recon.filled, recon.interpolated
    if o["demodulate"]:
        filled = remodulate(filled, gb.albedo, gb.emission)
        interpolated = remodulate(interpolated, gb.albedo, gb.emission)
        # Spreading E from a dark site to a brighter albedo scales it by a_q / a_min:
        # keep the clamp's promise that nothing above it reaches the image.
        image = dr.minimum(remodulate(out.image, gb.albedo, gb.emission),
                           dr.opaque(mi.Float, o["clamp"]))
        out = out._replace(image=image, filtered=None if out.filtered is None else image)
    if not entry.demodulated and run:
        out = as_denoised(entry.fn(ctx._replace(image=out.image)))
    return PostProcessed(out.image, filled, interpolated, out.tonemapped, out.filtered,
                         out.variance)
