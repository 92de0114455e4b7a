"""The ``film`` formation: history resolve, reconstruction and post-processing on the film's pixels.

The paper's image formation (Kwon et al. 2019, Fig. 1): the sparse shading buffer is merged
with the reprojected history (Fig. 4), reconstructed by Jump Flooding and interpolation
(§3.4) and filtered (§3.5), every buffer one value per film pixel. Every weight comes from
the G-buffer, the sampling map or detached values, so the image is a fixed function of the
traced values (:mod:`foveated_mi.frame.adjoint`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import drjit as dr

from ..timing import StageTimer
from . import cells as _cells
from . import reproject as _reproject
from . import sampling as _sampling
from .formation import FormationInput, Formed, register_formation
from . import domain
from .post import post_pass
from .reconstruction import reconstruction_pass
from .settings import (DenoiseSettings, DomainSettings, ReconstructionSettings,
                       SamplingSettings)
from .shading import ShadingBuffer

@dataclass(frozen=True)
class FilmSettings:
    """What the film formation reads: its own settings and its passes'. Hashable: the key of
    its recording (:class:`~.formation.FrozenFormation`)."""
    max_history: float
    domain: DomainSettings
    reconstruction: ReconstructionSettings
    denoise: DenoiseSettings
    #: the longest Jump Flooding step the frame's sampling law needs (:func:`jfa_bound`)
    jfa_bound: int | None
    #: the denoiser where the camera moved (``sigma_luminance_moving``; None: as still)
    denoise_moving: DenoiseSettings | None = None
    #: the history's cap where the camera moved (``max_history_moving``; 0: as still)
    max_history_moving: float = 0.0


def jfa_bound(width: int, height: int, law: SamplingSettings,
              gaze: tuple[float, float]) -> int | None:
    """The longest Jump Flooding step a frame needs: the sampling law's largest gap between
    sites, rounded up to a power of two (what :func:`~foveated_mi.reconstruct.jump_flood`
    does with it anyway).

    Parameters
    ----------
    width, height : int
        The film's size.
    law : SamplingSettings
        The sampling law (``acuity`` cells with their ``viewer_ppd`` given or measured:
        :func:`foveated_mi.configure.viewer_options`).
    gaze : tuple of float
        The gaze, a normalised film position (read by ``kwon`` in film units only).

    Returns
    -------
    bound : int or None
        A power of two, in pixels; None where the law bounds nothing (``theta_deg > 0``, or a
        law too sparse for a useful bound).
    """
    if law.law == "acuity":
        gap = _sampling.gap_bound(width, height, law.acuity_floor)
    elif law.law == "polar":
        # The widest cell, at the rings' reach: its pixel is at most a cell diagonal from
        # any pixel it covers.
        grid = _cells.foveal_grid(width, height, law.ray_budget,
                                  _cells.fovea_radius(width, height, law.theta),
                                  _cells.cell_offset(law))
        gap = 2.0 * float(grid.cell_size(grid.reach))
    elif law.law == "flat":
        gap = _sampling.flat_gap(width, height, law.ray_budget)
    elif law.theta_deg > 0:
        gap = None        # the law's smallest P needs the sensor's projection: no bound
    else:
        gap = _sampling.largest_gap(width, height, gaze=gaze, theta=law.theta,
                                    sigma_p=law.sigma_p)
    if gap is None:
        return None
    b = 1
    while b < gap:
        b *= 2
    return b


def form_film(shading: ShadingBuffer, inp: FormationInput, s: FilmSettings,
              timer: StageTimer, grad_pass: bool = False) -> Formed:
    """History resolve, reconstruction and post-processing of one frame (module
    docstring).

    Parameters
    ----------
    shading : ShadingBuffer
        The frame's shading buffer, one entry per film pixel.
    inp : FormationInput
        The frame's G-buffer, reprojection, history and sizes.
    s : FilmSettings
        The formation's settings.
    timer : StageTimer
        Marks the ``trace``, ``reconstruct`` and ``post`` stages.
    grad_pass : bool, optional
        Whether this is a gradient pass (which skips a non-differentiable denoiser).

    Returns
    -------
    formed : Formed
        The image, the named buffers on the film's grid, and the history (``mean``, ``count``,
        ``moment2``).
    """
    gb, width, height, d = inp.gbuffer, inp.width, inp.height, s.domain
    denoise = s.denoise_moving if inp.moving and s.denoise_moving is not None else s.denoise
    cap = s.max_history_moving if inp.moving and s.max_history_moving > 0 else s.max_history
    if d.demodulate and inp.emission_edges is not None:
        # At an emitter's edge the emission seen at the pixel's centre is not its footprint's
        # (a partial cover of the light): subtracting it could leave negative irradiance,
        # which the reconstruction would spread. Such pixels are divided by the albedo only.
        gb = gb._replace(emission=dr.select(inp.emission_edges, 0.0, gb.emission))
    # History resolve (Fig. 4): this frame's samples blended with the reprojected history.
    resolved = _reproject.resolve(shading.value, shading.mask, inp.spp, inp.reprojection,
                                  inp.history, cap, shading.moment2)
    timer.mark("reconstruct", resolved.shading, resolved.mask, resolved.count)
    # Reconstruction (§3.4): nearest sites, Voronoi fill and interpolation, on irradiance
    # with demodulate; a reconstruction of tone-mapped samples back to linear values.
    recon = reconstruction_pass(domain.to_irradiance(resolved.shading, gb, d), resolved, gb,
                                width, height, s.reconstruction, seed=inp.fill_seed,
                                emission_edges=inp.emission_edges, max_gap=s.jfa_bound)
    recon = recon._replace(filled=domain.from_display_samples(recon.filled, d),
                           interpolated=domain.from_display_samples(recon.interpolated, d))
    timer.mark("reconstruct", recon.nearest, recon.filled, recon.interpolated)
    # Post-processing (§3.5): the registered denoiser, the albedo multiplied back.
    post = post_pass(recon, resolved, gb, width, height, d, denoise, grad_pass)
    timer.mark("post", post.image)
    buffers = {"traced": shading.mask, "shading": resolved.shading,
               "shading_mask": resolved.mask, "history_count": resolved.count,
               "resampled": resolved.resampled, "nearest": recon.nearest,
               "filled": post.filled, "interpolated": post.interpolated,
               "tonemapped": post.tonemapped, "filtered": post.filtered,
               "variance": post.variance, "image": post.image}
    history = {"mean": resolved.shading, "count": resolved.count, "moment2": resolved.moment2}
    return Formed(post.image, buffers, history)


def film_stats(buffers: dict[str, dr.ArrayBase]) -> dict[str, Any]:
    """Pixels that took their value from the history only, and pixels without a value.

    Parameters
    ----------
    buffers : dict
        The formation's buffers (``resampled`` and ``shading_mask`` are read).

    Returns
    -------
    stats : dict
        ``resampled`` and ``holes``, counts on the device.
    """
    return {"resampled": dr.count(buffers["resampled"]),
            "holes": dr.count(~buffers["shading_mask"])}


register_formation("film", form_film, stats=film_stats,
                   counted=("resampled", "shading_mask"))
