"""The reconstruction registry: method name -> function and what it declares (docs/ARCHITECTURE.md).

Every method has the signature ``fn(shading, site_mask, nearest, width, height, *,
max_radius=32, ...) -> mi.Color3f``. It registers beside its code with what it reads::

    register_reconstruction("guided", guided, guided=True,
                            options={"levels": "guided_levels", ...}, averages="target_samples")

``guided``: it takes the frame's :class:`~foveated_mi.reconstruct.guided.Guide` (G-buffer and
sample counts) as ``guide``; ``seeded``: it takes the fill's ``seed``; ``options``: its keyword
parameters, each set from the option named (the reconstruction pass passes exactly these);
``averages``: the option whose value is the number of samples it averages per pixel, which a
variance-guided denoiser reads; ``keeps_sites``: a guided method that leaves every traced
pixel its own value, so that with every pixel traced it is the identity and does not run
(an unguided method is the identity there by construction). The options, the CLI and the
docs learn of a method from :data:`RECONSTRUCTIONS`.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import mitsuba as mi

from ..validate import check_choice, check_int


class Method(NamedTuple):
    """A registered reconstruction method (see :func:`register_reconstruction`)."""
    fn: Callable[..., mi.Color3f]
    guided: bool
    seeded: bool
    options: dict[str, str]        #: keyword parameter -> the option that sets it
    averages: str | None
    #: a traced pixel keeps its own value (with every pixel traced: the identity)
    keeps_sites: bool = False

    @property
    def keywords(self) -> set[str]:
        """The keyword parameters it takes besides ``max_radius``."""
        return set(self.options) | ({"guide"} if self.guided else set()) \
            | ({"seed"} if self.seeded else set())


#: Method name -> :class:`Method`, in registration order.
RECONSTRUCTIONS: dict[str, Method] = {}


def register_reconstruction(name: str, fn: Callable[..., mi.Color3f], *, guided: bool = False,
                            seeded: bool = False, options: dict[str, str] | None = None,
                            averages: str | None = None, keeps_sites: bool = False) -> None:
    """Make ``fn`` the reconstruction method ``name`` (``reconstruction = name``), with what it
    reads (module docstring).

    Parameters
    ----------
    name : str
        The method's name.
    fn : callable
        ``fn(shading, site_mask, nearest, width, height, *, max_radius=32, ...)``, returning
        the dense image (``mi.Color3f``).
    guided : bool, optional
        It takes the frame's :class:`~foveated_mi.reconstruct.guided.Guide` as ``guide``.
    seeded : bool, optional
        It takes the fill's ``seed``.
    options : dict of str to str or None, optional
        Its keyword parameters, each mapped to the option that sets it.
    averages : str or None, optional
        The option whose value is the number of samples it averages per pixel.
    keeps_sites : bool, optional
        A guided method that leaves every traced pixel its own value: with every pixel
        traced the reconstruction pass skips it.
    """
    RECONSTRUCTIONS[name] = Method(fn, bool(guided), bool(seeded), dict(options or {}),
                                   averages, bool(keeps_sites) or not guided)


def uses_guide(method: str) -> bool:
    """Whether ``method`` takes the G-buffer guide (and so needs no noise-free sites).

    Parameters
    ----------
    method : str
        A key of :data:`RECONSTRUCTIONS`.

    Returns
    -------
    guided : bool
        Whether it was registered with ``guided=True``.
    """
    return RECONSTRUCTIONS[method].guided


def reconstruct(method: str, shading: mi.Color3f, site_mask: mi.Bool, nearest: mi.UInt32,
                width: int, height: int, *, max_radius: int = 32, guide=None,
                **params) -> mi.Color3f:
    """Interpolate with the method named ``method`` (a key of :data:`RECONSTRUCTIONS`).

    Parameters
    ----------
    method : str
        The method's name.
    shading : mi.Color3f
        The sparse shading buffer, one entry per pixel (read at the sites).
    site_mask : mi.Bool
        The sites (traced pixels).
    nearest : mi.UInt32
        Each pixel's nearest site (:func:`~foveated_mi.reconstruct.jfa.jump_flood`).
    width, height : int
        Film size, in pixels.
    max_radius : int, optional
        Cap on an interpolation's radius, in pixels (at least 1).
    guide : Guide or None, optional
        The G-buffer guide, for the methods that declare it.
    **params
        Keyword parameters, passed to the methods that declare them; the others are ignored, so
        a caller can offer every method's parameters at once.

    Returns
    -------
    image : mi.Color3f
        The dense image.
    """
    check_choice("method", method, RECONSTRUCTIONS)
    max_radius = check_int("max_radius", max_radius, 1)
    entry = RECONSTRUCTIONS[method]
    offered = {"guide": guide, **params}
    extra = {k: v for k, v in offered.items() if k in entry.keywords}
    return entry.fn(shading, site_mask, nearest, width, height, max_radius=max_radius, **extra)
