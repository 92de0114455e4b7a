r"""Options of the ``foveated`` integrator: defaults, presets and validation.

``DEFAULTS`` is the paper's pipeline (Kwon et al. 2019). A *preset* replaces a group of
defaults by a configuration tuned together; any option given explicitly wins over both:

``paper``
    The paper as published: sampling map with θ = 0.1, σp = 0.8, approximate Sibson
    interpolation of radiance, the edge-avoiding à-trous filter in the tone-mapped domain.
    Rays are forced at depth edges only (``emission_edges`` off).
``oidn``
    For a Monte Carlo nested integrator, best measured at equal time with Intel Open Image
    Denoise installed (``pip install foveated_mi[denoise]``): wider sampling (θ = 0.25),
    albedo demodulation, the stochastic surface-aware fill and OIDN. Not differentiable
    (a gradient pass raises). Emission edges are traced every frame (``emission_edges``).
``guided``
    The differentiable noise-aware pipeline, no extra dependency: albedo demodulation, the
    G-buffer-guided sparse reconstruction and the variance-guided à-trous filter (SVGF), which
    stops smoothing where the history has converged; emission edges traced every frame. In ``benchmarks/bench_equal_time.py``
    (640x360, frame 16, still gaze) ``guided`` at 2 spp is ahead of ``paper`` at 4 spp by
    +2.9 / +6.1 dB (frame / fovea) on the staircase in 337 against 371 ms, and by
    +2.1 / +8.5 dB on voxel-city in 272 against 228 ms.
``auto`` (default)
    ``oidn`` when ``pyoidn`` can be imported, else ``guided``; ``guided`` whenever the frames
    are differentiated (a nested AD integrator such as ``prb``, or ``mi.render`` with
    parameters that require gradients), so that gradients are exact. ``stats["preset"]``
    names the one used.

See ``benchmarks/bench_equal_time.py`` and the README for the measurements behind them.
"""
from __future__ import annotations

import math
from typing import Any

from .validate import (ParameterError, check_bool, check_choice, check_int, check_point2,
                       check_range, check_sigma)

#: The paper's pipeline; every option of the integrator, with its default.
DEFAULTS: dict[str, Any] = {
    "preset": "auto",
    "theta": 0.1,
    "sigma_p": 0.8,
    "gaze": (0.5, 0.5),
    "reorder": "compact",
    "pixel_filter": "splat",
    "block_height": 8,
    "edge_threshold": 0.1,
    "emission_edges": False,
    "demodulate": False,
    "reconstruction": "sibson",
    "max_radius": 32,
    "target_samples": 32.0,
    "guided_levels": 5,
    "stochastic_jitter": 4.0,
    "stochastic_tries": 3,
    "jfa": "jfa+1",
    "denoiser": "atrous",
    "atrous_iterations": 5,
    "sigma_color": 0.5,
    "sigma_normal": 0.1,
    "sigma_position": 0.5,
    "sigma_luminance": 4.0,
    "oidn_quality": "high",
    "tonemap": "reinhard",
    "exposure": 0.0,
    "history": True,
    "max_history": 32.0,
    "reprojection_tolerance": 0.02,
    "clamp": 1e4,
    "timing": False,
    "map_seed": -1,
}

#: Preset name -> the defaults it replaces (see the module docstring).
PRESETS: dict[str, dict[str, Any]] = {
    "paper": {},
    "oidn": {"theta": 0.25, "sigma_p": 0.8, "demodulate": True, "reconstruction": "stochastic",
             "denoiser": "oidn", "emission_edges": True},
    "guided": {"demodulate": True, "reconstruction": "guided", "denoiser": "svgf",
               "emission_edges": True},
}
PRESET_NAMES = ("auto", *PRESETS)
DENOISERS = ("none", "atrous", "svgf", "oidn")
OIDN_QUALITIES = ("high", "balanced", "fast")
#: Denoisers a gradient pass cannot differentiate (it runs the frame without them).
NON_DIFFERENTIABLE_DENOISERS = frozenset({"oidn"})


def resolve_preset(preset: str, gradients: bool = False) -> str:
    """The preset ``preset`` stands for (``auto`` -> ``oidn`` or ``guided``).

    ``gradients``: the frames will be differentiated (a nested AD integrator such as
    ``prb``, or a gradient pass), so ``auto`` picks the preset whose gradient is exact."""
    check_choice("preset", preset, PRESET_NAMES)
    if preset != "auto":
        return preset
    if gradients:
        return "guided"
    from .denoise import oidn_available
    return "oidn" if oidn_available() else "guided"




def validate_options(options: dict[str, Any], gradients: bool = False) -> dict[str, Any]:
    """Check every option and return them all, normalised, with the preset resolved
    (``gradients``: see :func:`resolve_preset`).

    Raises :class:`~foveated_mi.validate.ParameterError` (one line) for an unknown option or
    a bad value."""
    from . import reconstruct as rec
    from . import postprocess as post
    from .reorder import REORDER_MODES
    from .shading import PIXEL_FILTERS

    unknown = set(options) - set(DEFAULTS)
    if unknown:
        name = sorted(unknown)[0]
        raise ParameterError(name, options[name], "one of " + ", ".join(sorted(DEFAULTS)))
    preset = resolve_preset(options.get("preset", DEFAULTS["preset"]), gradients)
    o = {**DEFAULTS, **PRESETS[preset], **options}
    out = {
        "preset": preset,
        "theta": check_range("theta", o["theta"], 0.0, None, lo_open=True),
        "sigma_p": check_range("sigma_p", o["sigma_p"], 0.0, 1.0, lo_open=True),
        "gaze": check_point2("gaze", o["gaze"]),
        "reorder": check_choice("reorder", o["reorder"], REORDER_MODES),
        "pixel_filter": check_choice("pixel_filter", o["pixel_filter"], PIXEL_FILTERS),
        "block_height": check_int("block_height", o["block_height"], 1),
        "edge_threshold": check_range("edge_threshold", o["edge_threshold"], 0.0),
        "emission_edges": check_bool("emission_edges", o["emission_edges"]),
        "demodulate": check_bool("demodulate", o["demodulate"]),
        "reconstruction": check_choice("reconstruction", o["reconstruction"],
                                       list(rec.RECONSTRUCTIONS)),
        "max_radius": check_int("max_radius", o["max_radius"], 1, 4096),
        "target_samples": check_range("target_samples", o["target_samples"], 0.0, 1e9,
                                      lo_open=True),
        "guided_levels": check_int("guided_levels", o["guided_levels"], 1, 12),
        "stochastic_jitter": check_range("stochastic_jitter", o["stochastic_jitter"], 0.0, 1e4),
        "stochastic_tries": check_int("stochastic_tries", o["stochastic_tries"], 0, 64),
        "jfa": check_choice("jfa", o["jfa"], rec.JFA_VARIANTS),
        "denoiser": check_choice("denoiser", o["denoiser"], DENOISERS),
        "atrous_iterations": check_int("atrous_iterations", o["atrous_iterations"], 0, 16),
        "sigma_color": check_sigma("sigma_color", o["sigma_color"]),
        "sigma_normal": check_sigma("sigma_normal", o["sigma_normal"]),
        "sigma_position": check_sigma("sigma_position", o["sigma_position"]),
        "sigma_luminance": check_sigma("sigma_luminance", o["sigma_luminance"]),
        "oidn_quality": check_choice("oidn_quality", o["oidn_quality"], OIDN_QUALITIES),
        "tonemap": check_choice("tonemap", o["tonemap"], list(post.TONEMAPPERS)),
        "exposure": check_range("exposure", o["exposure"], -64.0, 64.0),
        "history": check_bool("history", o["history"]),
        "max_history": check_range("max_history", o["max_history"], 1.0, 1e9),
        "reprojection_tolerance": check_range("reprojection_tolerance",
                                              o["reprojection_tolerance"], 0.0, 1.0),
        "clamp": check_range("clamp", o["clamp"], 0.0, 3e38, lo_open=True),
        "timing": check_bool("timing", o["timing"]),
        "map_seed": check_int("map_seed", o["map_seed"], -1, 0xFFFFFFFF),
    }
    if out["denoiser"] == "oidn":
        from .denoise import INSTALL_HINT, oidn_available
        if not oidn_available():
            raise ParameterError("denoiser", "oidn", f"pyoidn installed ({INSTALL_HINT}), or "
                                 "another of " + ", ".join(DENOISERS))
    return out
