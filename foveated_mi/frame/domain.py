r"""The value domains of a frame, and every conversion between them, in one place.

- **radiance**: linear, as the nested integrator traces it; what ``mi.render`` returns.
- **irradiance**: with ``demodulate``, radiance less the emission seen at the pixel, over the
  G-buffer's albedo, :math:`E = (L - L_e) / \hat a`
  (:mod:`foveated_mi.kernels.demodulation`): textures then come from the full-resolution
  G-buffer instead of sparse samples. Reconstruction, and a denoiser registered in this
  domain (``svgf``), work on it; :func:`to_radiance` multiplies the albedo back.
- **display**: tone-mapped values. With ``tonemap_samples`` each sample is tone-mapped before
  it is averaged (:func:`tonemap_samples`, the authors' order) and the reconstruction is
  mapped back to radiance (:func:`from_display_samples`), so that every later buffer means
  what it means without the option. A denoiser registered in this domain (``atrous``, the
  paper's §3.5 order) gets the tone-mapped image (:func:`to_display`) and returns display
  values, mapped back by :func:`from_display`.

The film formation (:mod:`foveated_mi.frame.film`) and the integrator call these and nothing
else to change domain. Each is a fixed function of its input, so gradients flow through it.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..kernels import demodulate, remodulate
from ..kernels.buffers import GBuffer
from ..postprocess import tonemap
from ..postprocess.inverse import inverse_tonemap
from ..postprocess.registry import DOMAINS  # noqa: F401  (the domains a denoiser declares)
from .settings import DomainSettings
from .shading import TracedSamples

def tonemap_samples(samples: TracedSamples, operator: str, exposure: float) -> TracedSamples:
    """Each sample tone-mapped before it is developed (``tonemap_samples``); rejected
    samples stay 0.

    Parameters
    ----------
    samples : TracedSamples
        The traced samples (radiance, and which were accepted).
    operator : str
        The tone-mapping operator.
    exposure : float
        The exposure, in stops.

    Returns
    -------
    samples : TracedSamples
        ``samples`` with each accepted sample's radiance tone-mapped, the others 0.
    """
    return samples._replace(radiance=dr.select(
        samples.ok, tonemap(samples.radiance, operator, exposure), 0.0))


def to_irradiance(radiance: mi.Color3f, gb: GBuffer, d: DomainSettings) -> mi.Color3f:
    r"""The reconstruction's working values: irradiance with ``demodulate``, else as given.

    Parameters
    ----------
    radiance : mi.Color3f
        Radiance, one value per entry of ``gb``.
    gb : GBuffer
        The G-buffer (its albedo and emission).
    d : DomainSettings
        The domain settings (``demodulate``).

    Returns
    -------
    values : mi.Color3f
        :math:`(L - L_e) / \hat a` with ``demodulate``, else ``radiance``.
    """
    return demodulate(radiance, gb.albedo, gb.emission) if d.demodulate else radiance


def from_display_samples(values: mi.Color3f, d: DomainSettings) -> mi.Color3f:
    """A reconstruction of tone-mapped samples back to linear values (``tonemap_samples``;
    the identity without it). The round trip is the identity below the operator's cap.

    Parameters
    ----------
    values : mi.Color3f
        The reconstruction's values.
    d : DomainSettings
        The domain settings (``tonemap_samples``, ``tonemap``, ``exposure``).

    Returns
    -------
    values : mi.Color3f
        The values inverse tone-mapped with ``tonemap_samples``, else as given.
    """
    if not d.tonemap_samples:
        return values
    return inverse_tonemap(values, d.tonemap, d.exposure)


def to_radiance(values: mi.Color3f, gb: GBuffer, d: DomainSettings,
                clamp: bool = False) -> mi.Color3f:
    """Working values back to radiance: the albedo multiplied back with ``demodulate``.

    Parameters
    ----------
    values : mi.Color3f
        The working values (irradiance with ``demodulate``).
    gb : GBuffer
        The G-buffer (its albedo and emission).
    d : DomainSettings
        The domain settings (``demodulate``, ``clamp``).
    clamp : bool, optional
        Nothing above ``d.clamp`` reaches the image (spreading irradiance from a dark site to a
        brighter albedo scales it by their ratio). Only with ``demodulate``.

    Returns
    -------
    radiance : mi.Color3f
        The remodulated values with ``demodulate``, else ``values`` as given.
    """
    if not d.demodulate:
        return values
    radiance = remodulate(values, gb.albedo, gb.emission)
    return dr.minimum(radiance, dr.opaque(mi.Float, d.clamp)) if clamp else radiance


def to_display(radiance: mi.Color3f, d: DomainSettings) -> mi.Color3f:
    """Radiance to display values, for a denoiser that works on them.

    Parameters
    ----------
    radiance : mi.Color3f
        Radiance.
    d : DomainSettings
        The domain settings (``tonemap``, ``exposure``).

    Returns
    -------
    display : mi.Color3f
        The tone-mapped values.
    """
    return tonemap(radiance, d.tonemap, d.exposure)


def from_display(display: mi.Color3f, d: DomainSettings) -> mi.Color3f:
    """A display-domain denoiser's output back to radiance.

    Parameters
    ----------
    display : mi.Color3f
        Display (tone-mapped) values.
    d : DomainSettings
        The domain settings (``tonemap``, ``exposure``).

    Returns
    -------
    radiance : mi.Color3f
        The inverse tone-mapped values.
    """
    return inverse_tonemap(display, d.tonemap, d.exposure)
