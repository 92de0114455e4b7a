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

from typing import Callable, NamedTuple

import drjit as dr
import mitsuba as mi

from ..postprocess import DENOISERS, DenoiseInput, Denoised
from ..postprocess.registry import as_denoised
from ..kernels.buffers import GBuffer, Resolved
from . import domain
from .reconstruction import Reconstruction
from .settings import DenoiseSettings, DomainSettings


class PostProcessed(NamedTuple):
    image: mi.Color3f                 #: the frame's radiance
    filled: mi.Color3f                #: Voronoi fill, radiance
    interpolated: mi.Color3f          #: interpolation, radiance
    tonemapped: mi.Color3f | None     #: the denoiser's buffers (None where it has none)
    filtered: mi.Color3f | None
    variance: mi.Float | None


def runs(n: DenoiseSettings, grad_pass: bool) -> bool:
    """Whether the denoiser runs: active for its options, and differentiable in a gradient
    pass (which skips it otherwise).

    Parameters
    ----------
    n : DenoiseSettings
        The denoiser and the options it reads.
    grad_pass : bool
        Whether this is a gradient pass.

    Returns
    -------
    runs : bool
        Whether the denoiser is called.
    """
    return n.active and (DENOISERS[n.name].differentiable or not grad_pass)


def denoise_in_domain(call: Callable[[DenoiseInput], object], where: str, ctx: DenoiseInput,
                      image: mi.Color3f, d: DomainSettings,
                      on: mi.Bool | None = None) -> Denoised:
    """A denoiser called in the domain its registration declares.

    Parameters
    ----------
    call : callable
        The denoiser, ``call(ctx)``.
    where : str
        Its domain (:data:`~foveated_mi.postprocess.registry.DOMAINS`).
    ctx : DenoiseInput
        Its input; its ``image`` is replaced.
    image : mi.Color3f
        The values to denoise: the working values for ``irradiance``, radiance otherwise.
    d : DomainSettings
        The value domains.
    on : mi.Bool, optional
        The entries that hold a value, where some do not (a buffer's empty cells): they stay
        without one in ``display`` (NaN, which no filter tap reads) and are black in
        ``radiance`` (a network sees no non-finite value).

    Returns
    -------
    denoised : Denoised
        The result in the values of ``image``, with the tone-mapped input and the filtered
        output in ``display``.
    """
    if where == "display":
        tonemapped = domain.to_display(image, d)
        if on is not None:
            tonemapped = dr.select(on, tonemapped, dr.nan)
        filtered = as_denoised(call(ctx._replace(image=tonemapped))).image
        return Denoised(domain.from_display(filtered, d), filtered=filtered,
                        tonemapped=tonemapped)
    if where == "radiance" and on is not None:
        image = dr.select(on, image, 0.0)
    return as_denoised(call(ctx._replace(image=image)))


def post_pass(recon: Reconstruction, resolved: Resolved, gb: GBuffer, width: int, height: int,
              d: DomainSettings, n: DenoiseSettings, grad_pass: bool = False) -> PostProcessed:
    """The denoiser ``n`` in its domain, and remodulation (module docstring).

    Parameters
    ----------
    recon : Reconstruction
        The reconstruction pass's buffers (working values).
    resolved : Resolved
        The resolved shading buffer.
    gb : GBuffer
        The G-buffer.
    width, height : int
        The film's size.
    d : DomainSettings
        The value domains.
    n : DenoiseSettings
        The denoiser and the options it reads.
    grad_pass : bool, optional
        Whether this is a gradient pass (which skips a non-differentiable denoiser).

    Returns
    -------
    post : PostProcessed
        The image, the fill and the interpolation (radiance), and the denoiser's buffers.
    """
    entry = DENOISERS[n.name]
    run = runs(n, grad_pass)
    ctx = DenoiseInput(recon.interpolated, gb, resolved, recon.nearest, width, height,
                       n.options, grad_pass, recon.averaged)
    out = Denoised(recon.interpolated)
    if entry.domain == "irradiance" and run:
        out = denoise_in_domain(entry.fn, entry.domain, ctx, recon.interpolated, d)
    filled = domain.to_radiance(recon.filled, gb, d)
    interpolated = domain.to_radiance(recon.interpolated, gb, d)
    if d.demodulate:
        image = domain.to_radiance(out.image, gb, d, clamp=True)
        out = out._replace(image=image, filtered=None if out.filtered is None else image)
    if entry.domain != "irradiance" and run:
        out = denoise_in_domain(entry.fn, entry.domain, ctx, out.image, d)
    return PostProcessed(out.image, filled, interpolated, out.tonemapped, out.filtered,
                         out.variance)
