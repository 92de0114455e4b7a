"""Post-processing (Kwon et al. 2019, §3.5): tone mapping, then an edge-avoiding à-trous
wavelet filter guided by the G-buffer (Dammertz et al. 2010).

Noise filters for Monte Carlo samples: :func:`svgf` (variance-guided à-trous on demodulated
irradiance) and :func:`oidn` (Intel Open Image Denoise, optional, not differentiable).

Pipeline order, as in the paper::

    tonemapped = tonemap(interpolated, operator, exposure)
    filtered   = atrous(tonemapped, normal, position, width, height, valid=hit)
"""
from __future__ import annotations

from ..frame._shared import B3_SPLINE
from .atrous import atrous, check_sigma
from .oidn import oidn
from .svgf import svgf
from .tonemap import MAX_EXPOSURE, TONEMAPPERS, check_exposure, tonemap

__all__ = ["B3_SPLINE", "MAX_EXPOSURE", "TONEMAPPERS", "atrous", "check_exposure", "check_sigma",
           "oidn", "svgf", "tonemap"]
