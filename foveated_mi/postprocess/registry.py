"""The denoiser registry: one uniform call per frame, one registration line per denoiser.

A denoiser is a function of a :class:`DenoiseInput` (the reconstructed image, the G-buffer,
the resolved shading buffer with its moments, the nearest sites, the film size, the options
and whether this is a gradient pass) returning the filtered image, or a :class:`Denoised`
with its intermediate buffers. It registers beside its code, as ``mi.register_integrator``
does::

    register_denoiser("svgf", svgf_stage, differentiable=True, domain="irradiance")

The options (validation, CLI flags, the docstring's parameter table) and the gradient pass
learn of it from :data:`DENOISERS`. The post-processing pass
(:func:`foveated_mi.frame.post.post_pass`) calls ``DENOISERS[name].fn(ctx)`` once per frame.
"""
from __future__ import annotations

from typing import Any, Callable, NamedTuple

import mitsuba as mi

from ..kernels.buffers import GBuffer, Resolved
from ..kernels.grid import Grid
from ..validate import check_choice

#: The value domains a denoiser may declare (:mod:`foveated_mi.frame.domain`).
DOMAINS = ("radiance", "irradiance", "display")


class DenoiseInput(NamedTuple):
    """What a denoiser may read of the frame (all flat per-pixel Dr.Jit buffers)."""
    image: mi.Color3f            #: the reconstructed image, in the denoiser's domain
    gbuffer: GBuffer             #: the frame's G-buffer
    resolved: Resolved           #: the resolved shading buffer (mean, moments, counts, mask)
    nearest: mi.UInt32           #: each pixel's nearest site
    width: int
    height: int
    options: dict[str, Any]      #: the options it declared (``reads``), validated
    grad_pass: bool = False      #: a gradient pass runs the image formation again
    #: samples the reconstruction averaged per pixel, where its method declares a number
    samples: mi.Float | None = None
    #: the buffers' grid and its neighbour rule (None: the film of ``width`` x ``height``)
    grid: Grid | None = None
    #: the cells whose result the formation reads (None: all); a denoiser may leave the
    #: others as they are (the foveal buffer's cells off the film)
    region: mi.Bool | None = None
    #: what the denoiser kept of this G-buffer on an earlier frame (its ``Denoised.kept``),
    #: given back while the G-buffer holds (a still view); None: none kept
    kept: Any = None
    #: the G-buffer is the last frame's and holds: what the denoiser derives from it alone
    #: may be returned as ``Denoised.kept``, to be given back next frame
    keep: bool = False


class Denoised(NamedTuple):
    """A denoiser's result: the image and the buffers it kept (``None`` where it has none)."""
    image: mi.Color3f
    filtered: mi.Color3f | None = None
    tonemapped: mi.Color3f | None = None
    variance: mi.Float | None = None
    #: what it derived from the G-buffer alone, for the next frames while it holds
    #: (``DenoiseInput.keep``); None: nothing
    kept: Any = None


class Denoiser(NamedTuple):
    """A registered denoiser (see :func:`register_denoiser`)."""
    fn: Callable[[DenoiseInput], "mi.Color3f | Denoised"]
    differentiable: bool
    domain: str
    materials: bool
    display_values: bool
    available: Callable[[], bool] | None
    requirement: str
    replayable: bool = False
    independent_noise: bool = False
    reads: tuple[str, ...] = ()
    active: Callable[[dict], bool] | None = None
    grid_aware: bool = False


#: Denoiser name -> :class:`Denoiser`, in registration order.
DENOISERS: dict[str, Denoiser] = {}


def register_denoiser(name: str, fn: Callable[[DenoiseInput], Any], *, differentiable: bool,
                      domain: str = "radiance", materials: bool = False,
                      display_values: bool = True, available: Callable[[], bool] | None = None,
                      requirement: str = "", replayable: bool = False,
                      independent_noise: bool = False, reads: tuple[str, ...] = (),
                      active: Callable[[dict], bool] | None = None,
                      grid_aware: bool = False) -> None:
    """Make ``fn`` the denoiser ``name`` (the option value ``denoiser = name``).

    Parameters
    ----------
    name : str
        The denoiser's name.
    fn : callable
        ``fn(ctx)`` of a :class:`DenoiseInput`, returning the image or a :class:`Denoised`.
    differentiable : bool
        A gradient pass may differentiate it (else a gradient pass of a frame that used it
        raises, and the image formation skips it when run for gradients).
    domain : str, optional
        The values ``ctx.image`` holds and it returns (:mod:`foveated_mi.frame.domain`):
        ``"irradiance"``, the reconstruction's own values (irradiance with ``demodulate``) before
        the albedo is multiplied back; ``"radiance"``, after it; ``"display"``, the tone-mapped
        radiance, mapped back after it (the formation does both conversions).
    materials : bool, optional
        It reads the G-buffer's albedo and emission.
    display_values : bool, optional
        It also works on tone-mapped samples (``tonemap_samples``).
    available : callable or None, optional
        Whether its dependency is installed (None: always).
    requirement : str, optional
        What to install.
    replayable : bool, optional
        It is Dr.Jit arithmetic only (no host call, no read of a value), so its kernels may be
        recorded once and replayed (:mod:`foveated_mi.frame.formation`).
    independent_noise : bool, optional
        It expects each pixel's noise independent of its neighbours' (a network trained on such
        noise), so ``pixel_filter = "auto"`` gives it filter importance sampling instead of
        splatting.
    reads : tuple of str, optional
        The options it reads (``ctx.options`` holds exactly these).
    active : callable or None, optional
        ``active(options)``: whether it changes a frame with these options, the ones it reads
        (else it is not called, and costs nothing: no tone-mapping round trip either).
    grid_aware : bool, optional
        It reads neighbours through ``ctx.grid``'s neighbour rule (a wrapped axis wraps); a
        formation in a buffer with a wrapped axis hands any other denoiser a plain image padded
        with the columns of the other side, and crops the result
        (:func:`foveated_mi.kernels.grid.wrap_padding`).

    Raises
    ------
    ParameterError
        If ``domain`` is not one of :data:`DOMAINS`.
    """
    check_choice("domain", domain, DOMAINS)
    DENOISERS[name] = Denoiser(fn, bool(differentiable), domain, bool(materials),
                               bool(display_values), available, requirement, bool(replayable),
                               bool(independent_noise), tuple(reads), active, bool(grid_aware))


def unregister_denoiser(name: str) -> None:
    """Remove the denoiser ``name`` (tests; a frame that uses it no longer validates).

    Parameters
    ----------
    name : str
        The denoiser's name (an unknown name is ignored).
    """
    DENOISERS.pop(name, None)


def as_denoised(result: Any) -> Denoised:
    """A denoiser's result as a :class:`Denoised` (a bare image is its filtered image).

    Parameters
    ----------
    result : mi.Color3f or Denoised
        What the denoiser returned.

    Returns
    -------
    denoised : Denoised
        ``result`` itself, or ``Denoised(result, filtered=result)``.
    """
    return result if isinstance(result, Denoised) else Denoised(result, filtered=result)


register_denoiser("none", lambda ctx: Denoised(ctx.image), differentiable=True, replayable=True,
                  grid_aware=True,
                  active=lambda o: False)
