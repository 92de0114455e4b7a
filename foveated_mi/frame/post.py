"""Post-processing pass (Kwon et al. 2019, §3.5): the denoiser in its domain, and the albedo
multiplied back.

One call of the registered denoiser (:data:`foveated_mi.postprocess.DENOISERS`) per frame,
on a :class:`~foveated_mi.postprocess.DenoiseInput` in the domain its registration declares
(:mod:`foveated_mi.frame.domain`): ``irradiance`` (``svgf``) filters the reconstruction's own
values before the albedo is multiplied back; ``radiance`` (``oidn``) filters radiance after
it; ``display`` (``atrous``) filters the tone-mapped radiance, mapped back after. A
denoiser whose registration says it is not ``active`` for the options is not called, and a
gradient pass skips a non-differentiable one (the gradient pass of a frame that used one
raises before it gets here).
"""
from __future__ import annotations

from typing import Any, NamedTuple

import drjit as dr
import mitsuba as mi

from ..postprocess import DENOISERS, DenoiseInput, Denoised
from ..postprocess.registry import as_denoised
from ..kernels.buffers import GBuffer, Resolved
from . import domain
from .reconstruction import Reconstruction


#: Options the post-processing pass reads besides those its denoiser declares.
READS = ("denoiser", "demodulate", "clamp")
#: ... and those of the tone map, for a denoiser in the display domain.
DISPLAY = ("tonemap", "exposure")


def reads(o: dict[str, Any]) -> tuple[str, ...]:
    """The options the post-processing pass reads with the denoiser of ``o``."""
    entry = DENOISERS[o["denoiser"]]
    return READS + (DISPLAY if entry.domain == "display" else ()) + entry.reads


class PostProcessed(NamedTuple):
    image: mi.Color3f                 #: the frame's radiance
    filled: mi.Color3f                #: Voronoi fill, radiance
    interpolated: mi.Color3f          #: interpolation, radiance
    tonemapped: mi.Color3f | None     #: the denoiser's buffers (None where it has none)
    filtered: mi.Color3f | None
    variance: mi.Float | None


def post_pass(recon: Reconstruction, resolved: Resolved, gb: GBuffer, width: int, height: int,
              o: dict[str, Any], grad_pass: bool = False) -> PostProcessed:
    """The denoiser of ``o["denoiser"]`` in its domain, and remodulation (module docstring)."""
    entry = DENOISERS[o["denoiser"]]
    run = (entry.differentiable or not grad_pass) and (entry.active is None or entry.active(o))
    ctx = DenoiseInput(recon.interpolated, gb, resolved, recon.nearest, width, height,
                       {k: o[k] for k in entry.reads}, grad_pass, recon.samples)
    out = Denoised(recon.interpolated)
    if entry.domain == "irradiance" and run:
        out = as_denoised(entry.fn(ctx))
    filled = domain.to_radiance(recon.filled, gb, o)
    interpolated = domain.to_radiance(recon.interpolated, gb, o)
    if o["demodulate"]:
        image = domain.to_radiance(out.image, gb, o, clamp=True)
        out = out._replace(image=image, filtered=None if out.filtered is None else image)
    if entry.domain == "radiance" and run:
        out = as_denoised(entry.fn(ctx._replace(image=out.image)))
    elif entry.domain == "display" and run:
        tonemapped = domain.to_display(out.image, o)
        filtered = as_denoised(entry.fn(ctx._replace(image=tonemapped))).image
        out = Denoised(domain.from_display(filtered, o), filtered=filtered,
                       tonemapped=tonemapped)
    return PostProcessed(out.image, filled, interpolated, out.tonemapped, out.filtered,
                         out.variance)
