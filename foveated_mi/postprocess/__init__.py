"""Post-processing (Kwon et al. 2019, §3.5): tone mapping, then an edge-avoiding à-trous
wavelet filter guided by the G-buffer (Dammertz et al. 2010).

Noise filters for Monte Carlo samples: :func:`svgf` (variance-guided à-trous on demodulated
irradiance) and :func:`oidn` (Intel Open Image Denoise, optional, not differentiable).

Pipeline order, as in the paper::

    tonemapped = tonemap(interpolated, operator, exposure)
    filtered   = atrous(tonemapped, normal, position, width, height, valid=hit)

Denoisers and tone mappers are registries (:data:`DENOISERS`, :data:`TONEMAPPERS`): each
registers in one line beside its code (:func:`register_denoiser`,
:func:`register_tonemapper`).
"""
from __future__ import annotations

from ..kernels import B3_SPLINE
from .registry import (DENOISERS, DenoiseInput, Denoised, register_denoiser,
                       unregister_denoiser)
from .tonemap import MAX_EXPOSURE, TONEMAPPERS, check_exposure, register_tonemapper, tonemap
# Registration order is the order of the choices: none, atrous, svgf, oidn.
from .atrous import atrous, check_sigma
from .svgf import svgf
from .oidn import oidn

__all__ = ["B3_SPLINE", "DENOISERS", "DenoiseInput", "Denoised", "MAX_EXPOSURE", "TONEMAPPERS",
           "atrous", "check_exposure", "check_sigma", "oidn", "register_denoiser",
           "register_tonemapper", "svgf", "tonemap", "unregister_denoiser"]
