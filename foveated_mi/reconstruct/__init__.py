"""Reconstruction of the sparse shading buffer (Kwon et al. 2019, §3.4).

Two stages, both plain functions on flat per-pixel buffers (docs/ARCHITECTURE.md):

1. :func:`jump_flood` - nearest site (shaded pixel) of every pixel by the Jump Flooding
   Algorithm; :func:`voronoi_fill` gathers the site colours (the ``filled`` buffer).
2. an interpolation method from :data:`RECONSTRUCTIONS` (``voronoi``, ``sibson``,
   ``discrete_sibson``, ``fast_sibson``, and ``guided``, the G-buffer-guided reconstruction
   for noisy samples), called directly or through :func:`reconstruct`. A method registers
   beside its code with :func:`register_reconstruction`.

Example::

    nearest = jump_flood(shading_mask, W, H)
    interpolated = reconstruct("sibson", shading, shading_mask, nearest, W, H, max_radius=32)
"""
from ..kernels import NO_SITE
from .registry import RECONSTRUCTIONS, reconstruct, register_reconstruction, uses_guide
# Registration order is the order of the choices.
from .interpolate import discrete_sibson, fast_sibson, sibson, voronoi
from .guided import Guide, guided
from .stochastic import stochastic
from .jfa import JFA_VARIANTS, jfa_steps, jump_flood, voronoi_fill
from .sat import box_mean, box_sum, interleave_rgb0, summed_area_table

__all__ = [
    "NO_SITE", "JFA_VARIANTS", "jfa_steps", "jump_flood", "voronoi_fill",
    "RECONSTRUCTIONS", "reconstruct", "register_reconstruction", "uses_guide", "voronoi", "sibson", "discrete_sibson",
    "fast_sibson", "guided", "stochastic", "Guide",
    "interleave_rgb0", "summed_area_table", "box_sum", "box_mean",
]
