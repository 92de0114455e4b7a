r"""Options of the ``foveated`` integrator: defaults, presets and validation.

``DEFAULTS`` is the paper's pipeline (Kwon et al. 2019). A *preset* replaces a group of
defaults by a configuration tuned together; any option given explicitly wins over both:

``paper``
    The paper as published: sampling map with θ = 0.1, σp = 0.8, Strategy 2 launch layout
    (``rows_blocks``), history without a cap, plain JFA (N/2 … 1), approximate Sibson
    interpolation with the text's in-circle test ``d(q, p) < r``, tone mapping then the basic
    à-trous filter (§3.5). Where the text is silent, the authors' public code
    (``ohseokkwon/Foveated-Rendering-using-Ray-Tracing``, commit 37426a9): one à-trous
    level (``main.cpp`` 355) with σ = 1 for colour, normal and position (``ATrous.cpp``
    53-55; the shader's ``exp(-d²/φ)`` with φ = 1), the Uncharted 2 tone curve
    (``shared_helper_funcs.h`` 354-373) applied to the frame before the filter.
    ``compact``, ``jfa+1``, ``max_history`` caps, the inclusive test and
    ``tonemap_samples`` (the authors' per-sample tone mapping, an option) are extensions.

    Edge rays: the text asks for "edge detection by the depth buffer" and names no test.
    The authors' code holds a Sobel test on depth (``shared_helper_funcs.h`` 116-129,
    ``|Gx| + |Gy| > 0.99`` in scene units) but does not call it (``samplingStep.cu`` line
    85 is commented out). That test is ``edge_detector = "sobel"`` with
    ``edge_threshold = 0.99``; the preset keeps the relative depth jump (0.1), because the
    Sobel test in scene units marks 38 % (voxel-monument) to 78 % (voxel-city) of a 256²
    frame as edges, above every ray budget of the paper's Table 1 (3.3 % to 19.8 %).
    Rays are forced at depth edges only (``emission_edges`` off).
``oidn``
    For a Monte Carlo nested integrator, best measured at equal time with Intel Open Image
    Denoise installed (``pip install -e '.[denoise]'`` from a clone): wider sampling (θ = 0.25),
    albedo demodulation, the stochastic surface-aware fill and OIDN. Not differentiable
    (a gradient pass raises). Emission edges are traced every frame (``emission_edges``).
``guided``
    The differentiable noise-aware pipeline, no extra dependency: albedo demodulation, the
    G-buffer-guided sparse reconstruction and the variance-guided à-trous filter (SVGF), which
    stops smoothing where the history has converged; emission edges traced every frame. In
    ``benchmarks/bench_equal_time.py`` (640x360, frame 16, still gaze; measured against the
    earlier ``paper`` pipeline: compact reorder, capped history, five à-trous levels)
    ``guided`` at 2 spp is ahead of it at 4 spp by
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
    "tonemap_samples": False,
    "history": True,
    "max_history": 32.0,
    "sibson_inclusive": True,
    "edge_detector": "relative",
    "reprojection_tolerance": 0.02,
    "clamp": 1e4,
    "timing": False,
    "map_seed": -1,
}

#: Preset name -> the defaults it replaces (see the module docstring).
PRESETS: dict[str, dict[str, Any]] = {
    # As published (Kwon et al. 2019) and, where the text is silent, the authors' code: the
    # Strategy 2 launch layout, an uncapped history, plain JFA, the strict in-circle test,
    # one à-trous level with unit sigmas (see the module docstring).
    "paper": {"reorder": "rows_blocks", "max_history": 0.0, "jfa": "jfa",
              "sibson_inclusive": False,
              "atrous_iterations": 1, "sigma_color": 1.0, "sigma_normal": 1.0,
              "sigma_position": 1.0, "tonemap": "uncharted2"},
    "oidn": {"theta": 0.25, "sigma_p": 0.8, "demodulate": True, "reconstruction": "stochastic",
             "denoiser": "oidn", "emission_edges": True},
    "guided": {"demodulate": True, "reconstruction": "guided", "denoiser": "svgf",
               "emission_edges": True},
}
PRESET_NAMES = ("auto", *PRESETS)
DENOISERS = ("none", "atrous", "svgf", "oidn")
EDGE_DETECTORS = ("relative", "sobel")
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




def _check_max_history(value) -> float:
    """0 (no cap, the paper) or a cap in [1, 1e9]."""
    v = check_range("max_history", value, 0.0, 1e9)
    if 0.0 < v < 1.0:
        raise ParameterError("max_history", value, "0 (no cap) or a number in [1, 1e9]")
    return v


def validate_options(options: dict[str, Any], gradients: bool = False) -> dict[str, Any]:
    """Check every option and return them all, normalised, with the preset resolved
    (``gradients``: see :func:`resolve_preset`).

    Raises :class:`~foveated_mi.validate.ParameterError` (one line) for an unknown option or
    a bad value."""
    from . import reconstruct as rec
    from . import postprocess as post
    from .frame.reorder import REORDER_MODES
    from .frame.shading import PIXEL_FILTERS

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
        "tonemap_samples": check_bool("tonemap_samples", o["tonemap_samples"]),
        "history": check_bool("history", o["history"]),
        "max_history": _check_max_history(o["max_history"]),
        "sibson_inclusive": check_bool("sibson_inclusive", o["sibson_inclusive"]),
        "edge_detector": check_choice("edge_detector", o["edge_detector"], EDGE_DETECTORS),
        "reprojection_tolerance": check_range("reprojection_tolerance",
                                              o["reprojection_tolerance"], 0.0, 1.0),
        "clamp": check_range("clamp", o["clamp"], 0.0, 3e38, lo_open=True),
        "timing": check_bool("timing", o["timing"]),
        "map_seed": check_int("map_seed", o["map_seed"], -1, 0xFFFFFFFF),
    }
    if out["tonemap_samples"]:
        # The history and the reconstruction then hold display values: demodulation and
        # SVGF's variance estimate assume radiance.
        if out["demodulate"]:
            raise ParameterError("demodulate", True, "False with tonemap_samples = True")
        if out["denoiser"] == "svgf":
            raise ParameterError("denoiser", "svgf", "atrous, oidn or none with "
                                 "tonemap_samples = True")
    if out["denoiser"] == "oidn":
        from .denoise import INSTALL_HINT, oidn_available
        if not oidn_available():
            raise ParameterError("denoiser", "oidn", f"pyoidn installed ({INSTALL_HINT}), or "
                                 "another of " + ", ".join(DENOISERS))
    return out
