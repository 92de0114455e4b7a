"""The ``film`` formation: history resolve, reconstruction and post-processing on the film's pixels.

The paper's image formation (Kwon et al. 2019, Fig. 1): the sparse shading buffer is merged
with the reprojected history (Fig. 4), reconstructed by Jump Flooding and interpolation
(§3.4) and filtered (§3.5), every buffer one value per film pixel. Every weight comes from
the G-buffer, the sampling map or detached values, so the image is a fixed function of the
traced values (:mod:`foveated_mi.frame.adjoint`).
"""
from __future__ import annotations

from typing import Any

import drjit as dr
import mitsuba as mi

from ..timing import StageTimer
from . import reproject as _reproject
from . import sampling as _sampling
from .formation import FormationInput, Formed, register_formation
from . import domain
from . import post as _post
from . import reconstruction as _reconstruction
from .post import post_pass
from .reconstruction import reconstruction_pass
from .shading import ShadingBuffer

#: Options the film formation reads itself (its passes declare theirs).
READS = ("max_history", "demodulate", "tonemap_samples", "tonemap", "exposure")


def jfa_bound(width: int, height: int, o: dict[str, Any]) -> int | None:
    """The longest Jump Flooding step a frame needs: the sampling law's largest gap between
    sites, rounded up to a power of two (what :func:`~foveated_mi.reconstruct.jump_flood`
    does with it anyway); None where the law bounds nothing."""
    if o["sampling_law"] == "acuity":
        gap = _sampling.gap_bound(width, height, o["acuity_floor"])
    elif o["sampling_law"] == "polar":
        # The widest cell, at the rings' reach: its pixel is at most a cell diagonal from
        # any pixel it covers.
        grid = _sampling.foveal_grid(width, height, float(o["ray_budget"]),
                                     _sampling.fovea_radius(width, height, o["theta"]))
        gap = 2.0 * float(grid.cell_size(grid.reach))
    elif o["theta_deg"] > 0:
        gap = None        # the law's smallest P needs the sensor's projection: no bound
    else:
        gap = _sampling.largest_gap(width, height, gaze=o["gaze"], theta=o["theta"],
                                    sigma_p=o["sigma_p"])
    if gap is None:
        return None
    b = 1
    while b < gap:
        b *= 2
    return b


def film_view(width: int, height: int, o: dict[str, Any]) -> dict[str, Any]:
    """The options as the film formation reads them: its own, and those its reconstruction
    and post-processing passes declare (with the methods ``o`` names). The sampling law
    enters only through the Jump Flooding bound (host scalars, no sync), so a moving gaze
    rarely changes the view."""
    names = READS + _reconstruction.reads(o) + _post.reads(o)
    view = {k: o[k] for k in dict.fromkeys(names)}
    view["jfa_bound"] = jfa_bound(width, height, o)
    return view


def form_film(shading: ShadingBuffer, inp: FormationInput, o: dict[str, Any],
              timer: StageTimer, grad_pass: bool = False) -> Formed:
    """History resolve, reconstruction and post-processing of one frame (module docstring);
    ``o``: the options through :func:`film_view`."""
    gb, width, height = inp.gbuffer, inp.width, inp.height
    if o["demodulate"] and inp.emission_edges is not None:
        # At an emitter's edge the emission seen at the pixel's centre is not its footprint's
        # (a partial cover of the light): subtracting it could leave negative irradiance,
        # which the reconstruction would spread. Such pixels are divided by the albedo only.
        gb = gb._replace(emission=dr.select(inp.emission_edges, 0.0, gb.emission))
    # History resolve (Fig. 4): this frame's samples blended with the reprojected history.
    resolved = _reproject.resolve(shading.value, shading.mask, inp.spp, inp.reprojection,
                                  inp.history, o["max_history"], shading.moment2)
    timer.mark("trace", resolved.shading, resolved.mask, resolved.count)
    # Reconstruction (§3.4): nearest sites, Voronoi fill and interpolation, on irradiance
    # with demodulate; a reconstruction of tone-mapped samples back to linear values.
    recon = reconstruction_pass(domain.to_irradiance(resolved.shading, gb, o), resolved, gb,
                                width, height, o, seed=inp.fill_seed,
                                emission_edges=inp.emission_edges, max_gap=o["jfa_bound"])
    recon = recon._replace(filled=domain.from_display_samples(recon.filled, o),
                           interpolated=domain.from_display_samples(recon.interpolated, o))
    timer.mark("reconstruct", recon.nearest, recon.filled, recon.interpolated)
    # Post-processing (§3.5): the registered denoiser, the albedo multiplied back.
    post = post_pass(recon, resolved, gb, width, height, o, grad_pass)
    timer.mark("post", post.image)
    buffers = {"traced": shading.mask, "shading": resolved.shading,
               "shading_mask": resolved.mask, "history_count": resolved.count,
               "resampled": resolved.resampled, "nearest": recon.nearest,
               "filled": post.filled, "interpolated": post.interpolated,
               "tonemapped": post.tonemapped, "filtered": post.filtered,
               "variance": post.variance, "image": post.image}
    history = {"mean": resolved.shading, "count": resolved.count, "moment2": resolved.moment2}
    return Formed(post.image, buffers, history)


def film_stats(buffers: dict[str, Any]) -> dict[str, Any]:
    """Pixels that took their value from the history only, and pixels without a value."""
    return {"resampled": dr.count(buffers["resampled"]),
            "holes": dr.count(~buffers["shading_mask"])}


register_formation("film", form_film, view=film_view, stats=film_stats,
                   counted=("resampled", "shading_mask"))
