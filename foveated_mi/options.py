r"""Options of the ``foveated`` integrator: the option schema, presets and validation.

:data:`SCHEMA` is the one table of options (:class:`Option`: name, default, kind, range or
choices, help, differentiability). :data:`DEFAULTS`, :func:`validate_options`, the CLI flags
(:mod:`foveated_mi.cli`), the TOML keys of sequence and study files, the integrator's
parameter table (:func:`parameter_table`) and what a gradient pass refuses
(:func:`non_differentiable`) derive from it. The choices of ``reconstruction``, ``denoiser``
and ``tonemap`` are their registries' names, read when asked.

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
    ``compact``, ``jfa+1``, ``max_history`` caps, exclusive history reads, the inclusive test and
    ``tonemap_samples`` (the authors' per-sample tone mapping, an option) are extensions.

    Edge rays: the text asks for "edge detection by the depth buffer" and names no test.
    The authors' code holds a Sobel test on depth (``shared_helper_funcs.h`` 116-129,
    ``|Gx| + |Gy| > 0.99`` in scene units) but does not call it (``samplingStep.cu`` line
    85 is commented out). That test is ``edge_detector = "sobel"`` with
    ``edge_threshold = 0.99``; the preset keeps the relative depth jump (0.1), because the
    Sobel test in scene units marks more of a voxel frame as edges than every ray budget of
    the paper's Table 1 (3.3 % to 19.8 %; ``docs/results.md#edge-rays-sobel-in-scene-units``).
    Rays are forced at depth edges only (``emission_edges`` off).
``oidn``
    For a Monte Carlo nested integrator, best measured at equal time with Intel Open Image
    Denoise installed (``pip install -e '.[denoise]'`` from a clone): wider sampling (θ = 0.25),
    albedo demodulation, the stochastic surface-aware fill and OIDN. Not differentiable
    (a gradient pass raises). Emission edges are traced every frame (``emission_edges``).
    Samples are drawn by filter importance sampling (``pixel_filter = "auto"`` resolves to
    ``importance`` for OIDN): OIDN is trained on independent per-pixel noise and leaves
    the correlated noise of splatting through a film's filter (Mitsuba's default
    ``gaussian``) in place, so on such a film the frame got worse as σp rose; see
    ``benchmarks/bench_pixel_filter_noise.py``.
``guided``
    The differentiable noise-aware pipeline, no extra dependency: albedo demodulation, the
    G-buffer-guided sparse reconstruction and the variance-guided à-trous filter (SVGF), which
    stops smoothing where the history has converged; emission edges traced every frame. Its
    figures at equal time against the earlier ``paper`` pipeline
    (``benchmarks/bench_equal_time.py``): ``docs/results.md#equal-time``.
``auto`` (default)
    ``vr``: at their defaults it reached each measured scene's video JOD faster than
    ``oidn`` or ``guided``, head still or turning, in a headset or on a monitor
    (``docs/results.md#what-auto-stands-for``); ``guided`` whenever the frames are
    differentiated (a nested AD integrator such as ``prb``, or ``mi.render`` with parameters
    that require gradients). ``stats["preset"]`` names the one used.

See ``docs/results.md#equal-time`` (``benchmarks/bench_equal_time.py``) and
``docs/results.md#what-auto-stands-for`` for the measurements behind them.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Callable, Iterable

from .validate import (ParameterError, check_bool, check_choice, check_int, check_point2,
                       check_range, check_sigma, unknown_name)

# -- the option schema -----------------------------------------------------------------------

#: Mitsuba XML type of each kind of option (the docstring's parameter table).
XML_TYPES = {"float": "|float|", "int": "|int|", "bool": "|bool|", "string": "|string|",
             "point": "|point|", "sigma": "|float|"}


@dataclass(frozen=True)
class Option:
    """One option of the ``foveated`` integrator: everything the validation, the CLI, the
    configuration files and the docs know of it.

    ``kind``: ``float``, ``int``, ``bool``, ``string`` (one of ``choices``), ``point`` (two
    numbers) or ``sigma`` (a number > 0, ``inf`` disables the weight). ``choices`` is a tuple
    or a function returning the names (a registry, read when asked). ``check`` replaces the
    kind's check. ``differentiable`` is ``True`` or a predicate on the value that holds where
    a gradient pass can differentiate the frame; ``gradient`` says then what is allowed."""
    name: str
    default: Any
    kind: str
    help: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    choices: tuple[str, ...] | Callable[[], Iterable[str]] | None = None
    check: Callable[[str, Any], Any] | None = None
    allowed: str | None = None          #: the range in words, where the kind's text is not it
    differentiable: bool | Callable[[Any], bool] = True
    gradient: str = ""
    cli: bool = True
    doc: str | None = None              #: longer RST text for the parameter table

    def names(self) -> list[str]:
        """The allowed values of a ``string`` option (a registry's current names)."""
        c = self.choices
        return list(c() if callable(c) else c)

    def validate(self, value: Any) -> Any:
        """The value, normalised; :class:`ParameterError` (one line) when it is not allowed."""
        if self.check is not None:
            return self.check(self.name, value)
        if self.kind == "float":
            return check_range(self.name, value, self.lo, self.hi, lo_open=self.lo_open)
        if self.kind == "int":
            return check_int(self.name, value, self.lo, self.hi)
        if self.kind == "bool":
            return check_bool(self.name, value)
        if self.kind == "point":
            return check_point2(self.name, value)
        if self.kind == "sigma":
            return check_sigma(self.name, value)
        return check_choice(self.name, value, self.names())

    def range_text(self) -> str:
        """The allowed values in words (the parameter table and the CLI help)."""
        if self.allowed is not None:
            return self.allowed
        if self.kind == "string":
            return " | ".join(self.names())
        if self.kind == "bool":
            return "true | false"
        if self.kind == "sigma":
            return "> 0, or inf to disable this weight"
        if self.kind == "point":
            return "two finite numbers (x, y)"
        fmt = (lambda v: str(v)) if self.kind == "int" else (lambda v: f"{v:g}")
        lo = "" if self.lo is None else f"{'>' if self.lo_open else '>='} {fmt(self.lo)}"
        hi = "" if self.hi is None else f"<= {fmt(self.hi)}"
        what = "an integer" if self.kind == "int" else "a number"
        return " ".join(p for p in (what, lo, "and" if lo and hi else "", hi) if p)

    def default_text(self) -> str:
        d = self.default
        if isinstance(d, bool):
            return "true" if d else "false"
        if isinstance(d, tuple):
            return ", ".join(f"{v:g}" for v in d)
        return f"{d:g}" if isinstance(d, float) else str(d)

    def is_differentiable(self, value: Any) -> bool:
        d = self.differentiable
        return d if isinstance(d, bool) else bool(d(value))

    def toml_types(self) -> tuple[type, ...]:
        """The TOML value types a configuration file may give."""
        return {"float": (int, float), "sigma": (int, float), "int": (int,), "bool": (bool,),
                "string": (str,), "point": (list,)}[self.kind]


def _reorder_modes():
    from .frame.reorder import REORDER_MODES
    return REORDER_MODES


def _pixel_filters():
    from .frame.shading import PIXEL_FILTERS
    return ("auto", *PIXEL_FILTERS)


def resolve_pixel_filter(value: str, denoiser: str) -> str:
    """``pixel_filter`` as the frame runs it.

    Parameters
    ----------
    value : str
        ``auto``, ``splat`` or ``importance``.
    denoiser : str
        A registered denoiser.

    Returns
    -------
    pixel_filter : str
        ``auto`` -> ``importance`` when ``denoiser`` is registered with ``independent_noise`` (it
        leaves splatted, correlated noise in place), else ``splat``; an explicit ``splat`` or
        ``importance`` is kept.
    """
    if value != "auto":
        return value
    return "importance" if denoisers()[denoiser].independent_noise else "splat"


class IgnoredOptionWarning(UserWarning):
    """An option given explicitly that the frame's preset, sampling law, formation,
    reconstruction or denoiser does not read (:func:`foveated_mi.configure.ignored_options`)."""


def pixel_filter_warning(given: dict[str, Any], options: dict[str, Any]) -> str | None:
    """The one-line warning for an explicit ``pixel_filter = "splat"`` with a denoiser that needs
    independent per-pixel noise.

    Parameters
    ----------
    given : dict
        The options the user set.
    options : dict
        The validated options.

    Returns
    -------
    warning : str or None
        The warning, else None.
    """
    denoiser = options["denoiser"]
    if given.get("pixel_filter") != "splat" or not denoisers()[denoiser].independent_noise:
        return None
    return splat_warning(f"denoiser = '{denoiser}'", denoiser, "unset (auto)")


def splat_warning(setting: str, denoiser: str, instead: str) -> str:
    """The one-line warning for splatted samples fed to ``denoiser``.

    Parameters
    ----------
    setting : str
        What the user set beside ``pixel_filter = 'splat'``.
    denoiser : str
        The denoiser's name.
    instead : str
        The value to leave ``pixel_filter`` at.

    Returns
    -------
    warning : str
        The warning.
    """
    return (f"pixel_filter = 'splat' with {setting}: on a film whose filter is not box, "
            f"splatting spreads each sample's noise over neighbouring pixels and {denoiser}, "
            f"which expects independent per-pixel noise, leaves it in place; leave "
            f"pixel_filter {instead} or set it to 'importance'")


def _registry(module: str, name: str) -> dict:
    """Registry ``name`` of ``module`` (relative to this package), imported on first use: the
    registries' modules import Mitsuba and Dr.Jit, which reading the options does not need."""
    return getattr(importlib.import_module(module, __package__), name)


def _sampling_laws():
    return _registry(".frame.sampling", "SAMPLING_LAWS")


def _reprojection_modes():
    return _registry(".frame.reproject", "REPROJECTION_MODES")


def _jfa_variants():
    return _registry(".reconstruct", "JFA_VARIANTS")


def formations() -> dict:
    """Formation name -> its registration (:data:`foveated_mi.frame.formation.FORMATIONS`)."""
    return _registry(".frame.formation", "FORMATIONS")


def reconstructions() -> dict:
    """Method name -> :class:`~foveated_mi.reconstruct.registry.Method`
    (:data:`foveated_mi.reconstruct.RECONSTRUCTIONS`)."""
    return _registry(".reconstruct", "RECONSTRUCTIONS")


def denoisers() -> dict:
    """Denoiser name -> :class:`~foveated_mi.postprocess.registry.Denoiser`
    (:data:`foveated_mi.postprocess.DENOISERS`)."""
    return _registry(".postprocess", "DENOISERS")


def tonemappers() -> dict:
    """Operator name -> its function (:data:`foveated_mi.postprocess.TONEMAPPERS`)."""
    return _registry(".postprocess", "TONEMAPPERS")


#: What ``max_history`` and ``max_history_moving`` accept, as their error line says it.
_HISTORY_ALLOWED = {"max_history": "0 (no cap) or a number in [1, 1e9]",
                    "max_history_moving": "0 (as still) or a number in [1, 1e9]"}


def _check_max_history(name: str, value) -> float:
    """0 (no cap, the paper; where the camera moved: as still) or a cap in [1, 1e9]."""
    v = check_range(name, value, 0.0, 1e9)
    if 0.0 < v < 1.0:
        raise ParameterError(name, value, _HISTORY_ALLOWED[name])
    return v


#: The periods over which a still view's settled rays may take turns
#: (``foveal_still_spp = 1 / k``).
STILL_PERIODS = range(2, 17)
_STILL_ALLOWED = (f"0 (off), a whole number of samples in [1, 65536], or 1/k for a whole k "
                  f"in [{STILL_PERIODS[0]}, {STILL_PERIODS[-1]}] (one sample every k frames)")


def _check_still_spp(name: str, value) -> int | float:
    """0 (off), whole samples in [1, 65536], or ``1 / k`` (one sample every ``k`` frames,
    :data:`STILL_PERIODS`; a number to within float rounding, or the text ``"1/k"``;
    returned exactly). An error names the value as given."""
    v = value
    text = value.replace(" ", "") if isinstance(value, str) else ""
    if text.startswith("1/") and text[2:].isdigit() and int(text[2:]) > 0:
        v = 1.0 / int(text[2:])
    try:
        f = check_range(name, v, 0.0, 65536.0)
        if f >= 1.0 or f == 0.0:
            return check_int(name, v, 0, 65536)
    except ParameterError:
        raise ParameterError(name, value, _STILL_ALLOWED) from None
    k = round(1.0 / f)
    if k not in STILL_PERIODS or abs(k * f - 1.0) > 1e-6:
        raise ParameterError(name, value, _STILL_ALLOWED)
    return 1.0 / k


def still_rate(value: int | float) -> tuple[int, int]:
    """``(samples, period)`` of a validated ``foveal_still_spp``: a settled ray traces
    ``samples`` once in ``period`` frames (``(0, 1)``: off)."""
    if value >= 1 or value == 0:
        return int(value), 1
    return 1, round(1.0 / value)


def _choice(name: str, choices: tuple[str, ...], help: str, doc: str | None = None) -> Option:
    """A ``string`` option among the fixed ``choices``, the first of them its default."""
    return Option(name, choices[0], "string", help, choices=choices, doc=doc)


_SCHEMA: tuple[Option, ...] = (
    Option("preset", "auto", "string", "a tuned group of defaults (auto: vr, or guided for "
           "differentiated frames); options given explicitly win",
           choices=lambda: PRESET_NAMES,
           doc="``auto`` (default: ``vr``, the preset that reached each measured scene's video "
           "JOD fastest; ``guided`` for a nested AD integrator or a differentiated "
           "``mi.render``) | "
           "``oidn`` | ``guided`` | ``paper`` | ``vr`` (the formation in a log-polar buffer "
           "around the gaze: ``formation = 'foveal'``): a tuned group of the defaults below (see "
           ":mod:`foveated_mi.options`); options given explicitly win"),
    Option("theta", 0.1, "float", "foveal radius θ in units of half the film diagonal",
           lo=0.0, lo_open=True),
    Option("sigma_p", 0.8, "float", "probability P(θ); 1 traces every pixel",
           lo=0.0, hi=1.0, lo_open=True),
    Option("theta_deg", 0.0, "float", "foveal radius in degrees of eccentricity: P = σp "
           "there, whatever the field of view (0: θ in film units)", lo=0.0, hi=180.0,
           doc="Foveal radius in degrees of eccentricity (the angle between a pixel's ray "
           "and the gaze ray, from the sensor's projection): P = σp there, whatever the "
           "camera's field of view; 0 (the default, and ``paper``) uses ``theta`` in film "
           "units. See :mod:`foveated_mi.frame.sampling`"),
    Option("sampling_law", "kwon", "string", "the sampling probability: kwon (Eq. 1), "
           "acuity (density following the eye's minimum angle of resolution, ray_budget), "
           "polar (the cells of a log-polar buffer, ray_budget) or flat (ray_budget spread "
           "evenly over the film, whatever the gaze)",
           choices=lambda: _sampling_laws(),
           doc="``kwon``: Eq. 1 of the paper (in degrees with ``theta_deg``); ``acuity``: "
           "the density follows the minimum angle of resolution, "
           "ω(e) = 1/48° + 0.022 e (Guenter et al. 2012), scaled to ``ray_budget`` with "
           "the floor ``acuity_floor``; ``polar``: every pixel within ``theta`` of the gaze "
           "(a full-resolution disc), and the pixel under each cell of a log-polar buffer "
           "outside it whose cells are as large as the rest of ``ray_budget`` allows "
           "(:mod:`foveated_mi.kernels.polar`); ``flat``: with ``formation = 'film'``, "
           "``ray_budget`` of the pixels spread "
           "evenly over the film by an ordered-dither pattern that moves on each frame, so "
           "that a still view traces every pixel within ``ceil(1 / ray_budget)`` frames "
           "(``theta``, ``sigma_p`` and the gaze play no part: the same rays as a foveated "
           "law, without the gaze). Under ``formation = 'foveal'`` (``foveal_space = "
           "'buffer'``) ``flat`` is a buffer of cells ``1 / sqrt(ray_budget)`` pixels "
           "across tiling the film (:mod:`foveated_mi.kernels.flat`), with the polar "
           "buffer's jitter, settling, history, denoiser and warp and no disc: dynamic "
           "resolution with temporal accumulation. See "
           ":mod:`foveated_mi.frame.sampling`"),
    Option("ray_budget", 0.1, "float",
           "rays per frame as a fraction of the film's pixels (sampling_law = acuity, polar "
           "or flat)",
           lo=0.0, hi=1.0, lo_open=True,
           doc="With ``sampling_law = 'polar'`` the cells outside the disc grow with the "
           "distance from it, so only cells far below a pixel near the disc reach the whole "
           "film; the buffer stops at cells of a quarter pixel at the disc's edge "
           "(:data:`foveated_mi.frame.cells.MIN_PITCH`), which trace about 0.85 of the "
           "film with ``vr``'s disc, and a budget above that gets them with a warning that "
           "says what the frame traces."),
    Option("acuity_floor", 0.01, "float", "smallest probability of the acuity law "
           "(at most ray_budget)", lo=0.0, hi=1.0),
    _choice("polar_cells", ("log", "acuity"), "the cells of the polar law's buffer outside "
            "its disc: log (square, log-polar) or acuity (sized by the eye's minimum angle of "
            "resolution at viewer_ppd)",
            doc="The cell law of ``sampling_law = 'polar'``'s buffer outside its "
            "full-resolution disc (:mod:`foveated_mi.kernels.polar`): ``log`` (default, and "
            "``vr``), square cells whose size grows in proportion to the distance to the "
            "gaze (a log-polar buffer); ``acuity``, cells whose radial size follows the "
            "minimum angle of resolution ω(e) = 1/48° + 0.022 e (Koskela et al. 2019's "
            "offset c = ω0/m degrees, converted to pixels by ``viewer_ppd``; across, a "
            "cell spans its ring's circumference over the angles, in proportion to the "
            "distance). Either way the cells are sized so that the traced pixels are "
            "``ray_budget`` of the film. See :mod:`foveated_mi.frame.sampling`"),
    Option("viewer_ppd", 0.0, "float", "the viewer's pixels per degree at the film's centre, "
           "read by polar_cells = acuity (0: from the sensor's projection)", lo=0.0, hi=1000.0,
           doc="The viewer's pixels per degree at the film's centre, which converts "
           "``polar_cells = 'acuity'``'s offset from degrees to pixels: 0 (default) measures "
           "it from the sensor's projection, as if the display spanned the sensor's field of "
           "view (:func:`foveated_mi.viewer.pixels_per_degree`); a headset's lenses "
           "concentrate pixels at the centre, so its own figure differs. Read by nothing "
           "else"),
    Option("gaze", (0.5, 0.5), "point", "gaze in normalised film coordinates, origin top-left",
           doc="Gaze in normalised film coordinates, origin top-left; outside [0, 1]^2 is "
           "legal (the viewer looks off-screen). Mitsuba's XML ``<point>`` needs a ``z`` "
           "attribute, which is ignored"),
    Option("gaze_hold_deg", 0.0, "float", "the rendered gaze holds while the given one "
           "stays within this many degrees of it (0: every gaze is rendered as it comes)",
           lo=0.0, hi=30.0,
           doc="A fixation filter for an eye tracker's jitter: each view renders the gaze it "
           "rendered last while the given gaze (the tracker's) stays within this radius of "
           "it, in degrees at the film's centre (its pixels per degree there, from the "
           "sensor's projection), and the given gaze as soon as it leaves, so that a "
           "saccade moves the samples at once and a fixation is a still view: its samples, "
           "disc and history stay, and with ``foveal_still_spp`` it settles. The rendered "
           "gaze is then up to this far from the true one. Stats: ``gaze`` (rendered) and "
           "``gaze_tracked`` (given)"),
    Option("reorder", "compact", "string", "ray reordering (§3.2): the trace wavefront's "
           "layout", choices=_reorder_modes),
    Option("pixel_filter", "auto", "string", "how samples honour the film's filter (auto: "
           "importance for a denoiser that needs independent per-pixel noise, such as oidn, "
           "else splat)", choices=_pixel_filters,
           doc="How samples honour the film's reconstruction filter: ``splat`` (Mitsuba's "
           "own estimator, identical to the nested integrator at sigma_p = 1; neighbouring "
           "pixels share samples, so their noise is correlated) or ``importance`` (filter "
           "importance sampling: independent, unbiased pixels). ``auto`` is ``importance`` "
           "when the denoiser expects independent per-pixel noise (``oidn``: splatted noise "
           "survives it, and the frame got worse as more pixels were traced), else ``splat``; "
           "``splat`` with such a denoiser warns once. Both are the plain per-pixel mean on a "
           "box film. See :mod:`foveated_mi.frame.shading`"),
    Option("block_height", 8, "int", "rows per block of Strategy 2", lo=1),
    Option("edge_threshold", 0.1, "float", "depth edges that force a ray (0 disables them)",
           lo=0.0, doc="Depth edges that force a ray; 0 disables them (see "
           "``edge_detector``). ``stats`` reports ``edge_rays`` and ``edge_fraction``"),
    Option("emission_edges", False, "bool", "trace every frame the pixels whose filter "
           "footprint crosses an emitter's edge",
           doc="Also force rays, every frame, at the pixels whose film-filter footprint holds "
           "both emitted radiance (a light or the environment seen directly, from the "
           "G-buffer) and none, and keep their values off other pixels in the ``guided`` and "
           "``stochastic`` reconstructions (true in the ``oidn`` and ``guided`` presets). A "
           "sparse estimate of such a pixel never converges: it depends on which neighbours "
           "were traced with it. See :func:`foveated_mi.frame.gbuffer.emission_edges`"),
    Option("demodulate", False, "bool", "reconstruct and filter irradiance (radiance / "
           "G-buffer albedo)", doc="Reconstruct and filter irradiance, albedo multiplied "
           "back (:mod:`foveated_mi.kernels.demodulation`)"),
    Option("formation", "film", "string", "the image formation after the trace",
           choices=lambda: formations(),
           doc="The image formation after the trace (:mod:`foveated_mi.frame.formation`): "
           "``film`` resolves the history, reconstructs and post-processes on the film's "
           "pixels (§3.4-3.5); ``foveal`` denoises in the log-polar buffer of "
           "``sampling_law = 'polar'`` (or the even buffer of ``sampling_law = 'flat'``) "
           "and warps it once to the film "
           "(:mod:`foveated_mi.frame.foveal`)"),
    _choice("foveal_upsampling", ("bilinear", "cubic", "joint"), "the warp of the foveal "
            "formation's buffer to the film: bilinear, cubic (Catmull-Rom), or joint (weighted "
            "by the full-resolution G-buffer)",
            doc="How ``formation = 'foveal'`` warps its buffer to the film: ``bilinear`` over "
            "the four cells around a pixel; ``cubic``, Catmull-Rom over the 4 x 4 cells "
            "around it where all of them hold a value (bilinear elsewhere), which keeps more "
            "of the cells' contrast; or ``joint``, a joint bilateral upsampling whose "
            "weights also stop at the film G-buffer's surface edges "
            "(:func:`foveated_mi.frame.foveal.warp`)"),
    Option("foveal_contrast", 0.0, "float", "the foveal buffer's contrast gain before the "
           "warp: each cell pushed away from its neighbours' mean by this times their "
           "difference (0: none)", lo=0.0, hi=4.0,
           doc="With ``formation = 'foveal'``: an unsharp mask at the cells' own scale "
           "before the warp, so that its reach grows with eccentricity as the cells do "
           "(:func:`foveated_mi.frame.foveal.sharpen`); 0 leaves the cells as they are"),
    _choice("foveal_space", ("buffer", "film"), "where the foveal formation keeps its "
            "G-buffer and history: on the buffer's samples, or on the film's pixels",
            doc="Where ``formation = 'foveal'`` keeps its geometry and history: ``buffer`` "
            "casts the G-buffer at the buffer's samples only and reprojects the history "
            "sample to sample, so that nothing but the warp runs on every film pixel "
            "(:mod:`foveated_mi.frame.buffer_space`); ``film`` keeps a full-resolution "
            "G-buffer and the history on the film's pixels (needed by ``foveal_upsampling = "
            "'joint'`` and ``emission_edges``)"),
    _choice("foveal_disc", ("resolved", "denoised"), "what the foveal formation shows in its "
            "full-resolution disc: its pixels as resolved with the history, or denoised too",
            doc="What ``formation = 'foveal'`` shows in the disc around the gaze, where every "
            "pixel is traced: ``resolved``, each pixel's own value blended with its history; "
            "``denoised``, the same values through the frame's denoiser on the disc's square "
            "patch of pixels (a plain image, so a network gets what it was trained on), as the "
            "buffer's cells are (the ``vr`` preset's: with SVGF it smooths only where the "
            "history's variance says a pixel is noisy, so it gains most on a noisy scene: "
            "``docs/results.md#the-disc-around-the-gaze-denoised``)"),
    Option("foveal_disc_iterations", -1, "int", "levels of the denoiser on the foveal "
           "disc's patch (-1: atrous_iterations, the buffer's)", lo=-1, hi=16,
           doc="With ``foveal_disc = 'denoised'``: the levels of the à-trous / SVGF filter on "
           "the disc's patch of full-resolution pixels, apart from the buffer's cells (-1: "
           "``atrous_iterations``, as the cells). A cell spans many pixels, a disc pixel one: "
           "the filter that the cells need reaches further than a converged fovea wants"),
    Option("foveal_disc_iterations_moving", -1, "int", "levels of the denoiser on the "
           "foveal disc's patch in a frame whose camera moved (-1: foveal_disc_iterations, "
           "as a still frame)", lo=-1, hi=16,
           doc="With ``foveal_disc = 'denoised'``: the levels of the à-trous / SVGF filter on "
           "the disc's patch in a frame whose camera moved since the view's last, where its "
           "history is reprojected (-1: ``foveal_disc_iterations``, as a still frame; "
           "setting the camera's parameters, even to the same values, is a move). The motion "
           "hides what fewer levels leave: the ``vr`` preset's 2 scored as 4 did with the head "
           "turning, in less time "
           "(``docs/results.md#the-discs-levels-where-the-camera-moved``)"),
    Option("foveal_disc_sigma_luminance", 0.0, "float", "SVGF's colour sigma on the foveal "
           "disc's patch, in noise deviations (0: sigma_luminance, the buffer's)",
           lo=0.0, hi=1e9,
           doc="With ``foveal_disc = 'denoised'`` and ``denoiser = 'svgf'``: the colour test "
           "on the disc's patch, in noise standard deviations, apart from the buffer's cells "
           "(0: ``sigma_luminance``, as the cells)"),
    Option("foveal_disc_denoiser", "same", "string", "the denoiser on the foveal disc's "
           "patch (same: the frame's denoiser, as the cells)",
           choices=lambda: ("same", *denoisers()),
           differentiable=lambda v: v == "same" or denoisers()[v].differentiable,
           gradient="a differentiable denoiser",
           doc="With ``foveal_disc = 'denoised'``: the denoiser on the disc's square patch of "
           "full-resolution pixels, apart from the buffer's cells (``same``: ``denoiser``, "
           "as the cells). ``oidn`` (at ``oidn_quality``) gives the disc a network that "
           "denoises a disc without history (a view's first frames) from its few samples: it "
           "helps a still head a little, and with the head turning it cost a CPU more time "
           "than it bought (``docs/results.md#the-disc-through-a-network``). A frame whose "
           "denoisers "
           "include one that runs on the host is formed without replay"),
    Option("foveal_disc_spp", 0, "int", "samples per pixel of the foveal disc's rays (0: "
           "the frame's spp, as the cells)", lo=0, hi=1 << 16,
           doc="With ``formation = 'foveal'`` and ``foveal_space = 'buffer'``: the disc's "
           "pixels trace this many samples, the cells the frame's spp (a value of the frame's "
           "spp or more traces the frame's; the ``vr`` preset: 2). The disc holds a large "
           "part of a ``vr`` frame's rays, and fewer samples there cost little video JOD for "
           "the time they save (``docs/results.md#the-disc-at-a-sample-rate-of-its-own``); "
           "its history counts the samples each pixel traced"),
    Option("foveal_interleave", 1, "int", "n: the foveal buffer holds n x n times the cells "
           "and a frame traces one in each n x n block of them, in turn (1: every cell)",
           lo=1, hi=4,
           doc="With ``formation = 'foveal'`` in ``foveal_space = 'buffer'``: the buffer "
           "holds ``n * n`` times the cells that ``ray_budget`` leaves outside the disc, and "
           "each frame traces one cell in each ``n`` x ``n`` block of them, in the order of "
           "an ordered dither, so that a frame's rays still number ``ray_budget`` "
           "(:func:`foveated_mi.frame.buffer_space.interleaved`). A cell not traced shows "
           "its history; one without history (the first frames, a disocclusion) its "
           "neighbours' values. A still view converges to the finer cells in ``n * n`` "
           "frames; a moving one keeps what its history holds"),
    Option("foveal_jitter", 0.0, "float", "a cell's ray goes through a point of the cell that "
           "changes every frame, this fraction of the cell across (0: the cell's centre)",
           lo=0.0, hi=1.0,
           doc="With ``formation = 'foveal'`` in ``foveal_space = 'buffer'`` and ``history``: "
           "each frame a cell's ray goes through a point of the cell, offset from its centre "
           "by this fraction of the cell along its angle and its ring, in a low-discrepancy "
           "sequence of its own (:func:`foveated_mi.frame.buffer_space.ray_shifts`), so that "
           "its history holds the cell's mean rather than one point's value, as a box "
           "prefilter of the cell would; a cell without history traces its centre. The "
           "G-buffer, the launch and the history stay at the cells' centres. It helps a "
           "still view a little at 0.5 and costs video JOD with the head turning; across "
           "whole cells, the first frame after a camera move that ends a long still view "
           "trails a fresh frame "
           "(``docs/results.md#each-cells-ray-through-a-moving-point-of-the-cell``). A "
           "small bright emitter inside a cell lights the whole cell in the frames whose "
           "point falls on it, until the history averages it in"),
    Option("foveal_still_spp", 0, "float", "samples per pixel of a still view's rays once "
           "their history holds its cap, a frame (0: the frame's spp, always; 1/k: one "
           "sample every k frames, the rays in turn)", check=_check_still_spp,
           allowed=_STILL_ALLOWED,
           doc="With ``formation = 'foveal'`` in ``foveal_space = 'buffer'`` and ``history``: "
           "once a view's camera, gaze and scene have held still for as many frames as its "
           "cells take to fill the history's cap (``max_history`` samples, 32 where it is "
           "uncapped, at the frame's spp; times the interleave's turns), each cell's ray "
           "traces this many samples a frame, and the disc's rays once they have filled it "
           "at their own rate (``foveal_disc_spp``), until the view moves. At its cap the "
           "history is an exponential average whose noise hardly depends on the samples a "
           "frame brings, so a still view's frames cost less once they have converged; a "
           "view in motion never settles (its frames are the same). The first settled frame "
           "traces kernels of its own once. A value of the frame's spp or more traces the "
           "frame's (``docs/results.md#a-still-view-that-settles``). Below one, ``1/k`` "
           "traces one sample every ``k`` frames at each settled ray, a ``k``-th of them "
           "each frame on an even lattice (:func:`foveated_mi.frame.buffer_space."
           "settled_turn`), the others showing their history, whose noise at its cap falls "
           "toward the same floor, ``k`` times more slowly; the disc traces every frame "
           "until it settles (``docs/results.md#settled-rays-in-turn``)"),
    Option("foveal_taa", 1.0, "float", "this frame's weight in what each cell of the foveal "
           "buffer shows: 1 shows its denoised value; below 1, blended with what it showed "
           "last frame, clamped to its neighbours' range", lo=0.0, hi=1.0, lo_open=True,
           doc="With ``formation = 'foveal'`` in ``foveal_space = 'buffer'`` and ``history``: "
           "each cell shows its denoised value blended with what it showed in the last frame "
           "(reprojected, and clamped to the range of its 3 x 3 neighbours this frame, as "
           "temporal anti-aliasing does), this frame weighing ``foveal_taa``, so that the "
           "periphery's noise flickers less (:func:`foveated_mi.frame.foveal.stabilize`); 1 "
           "shows the denoised value as it is"),
    Option("reconstruction", "sibson", "string", "interpolation of the sparse shading buffer "
           "(§3.4)", choices=lambda: reconstructions(),
           doc="Interpolation of the sparse shading buffer (§3.4); ``guided`` and "
           "``stochastic`` use the G-buffer (``target_samples``, ``guided_levels``, "
           "``stochastic_jitter``, ``stochastic_tries``)"),
    Option("max_radius", 32, "int", "bound on the interpolation radius in pixels",
           lo=1, hi=4096),
    Option("target_samples", 32.0, "float", "samples a guided reconstruction averages per "
           "pixel", lo=0.0, hi=1e9, lo_open=True),
    Option("guided_levels", 5, "int", "pyramid levels of the guided reconstruction",
           lo=1, hi=12),
    Option("stochastic_jitter", 4.0, "float", "jitter radius (pixels) of the stochastic fill",
           lo=0.0, hi=1e4),
    Option("stochastic_tries", 3, "int", "same-surface retries of the stochastic fill",
           lo=0, hi=64),
    Option("jfa", "jfa+1", "string", "Jump Flooding variant", choices=_jfa_variants),
    Option("denoiser", "atrous", "string", "the post-processing filter (§3.5)",
           choices=lambda: denoisers(),
           differentiable=lambda v: denoisers()[v].differentiable,
           gradient="a differentiable denoiser",
           doc="The post-processing filter (§3.5): ``atrous`` the edge-avoiding à-trous "
           "filter, ``svgf`` variance-guided (``sigma_luminance``), ``oidn`` Intel Open Image "
           "Denoise (``oidn_quality``; not differentiable), ``none``; a registered denoiser "
           "(:func:`foveated_mi.postprocess.register_denoiser`) is one more choice"),
    Option("atrous_iterations", 5, "int", "levels of the à-trous / SVGF filter (0: no filter)",
           lo=0, hi=16),
    Option("sigma_color", 0.5, "sigma", "à-trous colour sigma"),
    Option("sigma_normal", 0.1, "sigma", "à-trous normal sigma"),
    Option("sigma_position", 0.5, "sigma", "à-trous position sigma"),
    Option("sigma_luminance", 4.0, "sigma", "SVGF colour sigma, in noise standard deviations"),
    Option("sigma_luminance_moving", 0.0, "float", "SVGF colour sigma in a frame whose "
           "camera moved, in noise standard deviations (0: sigma_luminance, as a still frame)",
           lo=0.0, hi=1e9,
           doc="With ``denoiser = 'svgf'``: the colour test of a frame whose camera moved "
           "since the view's last (setting the camera's parameters, even to the same values, "
           "is a move), on the frame and on the foveal disc where it has no colour test of "
           "its own (0: ``sigma_luminance``, as a still frame; a ``sigma_luminance`` given "
           "without it holds in every frame, whatever the preset sets). The ``vr`` preset's "
           "6, against 8 still: smoothing across the edges that slide as the head turns is "
           "what flickers, and with 6 the periphery at 10-20 degrees flickered no more than "
           "uniform + history's at the same video JOD, where a still head scores its best "
           "at 8 (``docs/results.md#svgfs-colour-test-where-the-camera-moved``)"),
    _choice("oidn_quality", ("high", "balanced", "fast"), "OIDN's quality setting"),
    Option("tonemap", "reinhard", "string", "tone-mapping operator (filter domain and PNG "
           "output)", choices=lambda: tonemappers()),
    Option("exposure", 0.0, "float", "exposure in stops", lo=-64.0, hi=64.0),
    Option("tonemap_samples", False, "bool", "tone-map every sample before the history",
           differentiable=lambda v: not v,
           gradient="False for gradients (per-sample tone mapping is not part of the "
           "differentiated image)",
           doc="Tone-map every traced sample before the film and the history, as the "
           "authors' code does (``cuda/fov_path_trace_camera.cu`` line 169); the history and "
           "the reconstruction then hold display values and the image is mapped back to "
           "radiance at the end. Off by default and in ``paper`` (the text tone-maps the "
           "frame); not differentiable, not with ``demodulate`` or ``svgf``"),
    Option("history", True, "bool", "temporal reuse through reverse reprojection"),
    Option("max_history", 32.0, "float", "cap on the history sample count (0: no cap)",
           check=_check_max_history, allowed=_HISTORY_ALLOWED["max_history"]),
    Option("max_history_moving", 0.0, "float", "cap on the history sample count in a frame "
           "whose camera moved (0: max_history, as a still frame)", check=_check_max_history,
           allowed=_HISTORY_ALLOWED["max_history_moving"],
           doc="The history's cap in a frame whose camera moved since the view's last "
           "(0: ``max_history``, as a still frame; a ``max_history`` given without it holds "
           "in every frame, whatever the preset sets). A moving view's history lags what it "
           "shows by about half its samples' frames; a still view's averages noise only. "
           "The ``vr`` preset's 8, against 32 still: with the head turning, its periphery "
           "flickered less in every ring and its fovea was sharper, while a still head "
           "settles on the full cap"),
    Option("sibson_inclusive", True, "bool", "sibson's in-circle test: <= (or the text's <)",
           doc="In-circle test of ``sibson``: ``d(q, p) <= r`` (true, the authors' shader) "
           "or ``d(q, p) < r`` (false; the paper's text, ``paper``)"),
    _choice("edge_detector", ("relative", "sobel"), "the depth-edge test that forces rays",
            doc="``relative``: relative depth jump to a 4-neighbour above ``edge_threshold``. "
            "``sobel``: the test in the authors' code (which does not call it), "
            "``|Gx| + |Gy|`` of the 3x3 Sobel filter on depth above the threshold (the "
            "authors use 0.99, in scene units)"),
    Option("reprojection_tolerance", 0.02, "float", "relative depth tolerance of the "
           "reprojection test", lo=0.0, hi=1.0),
    Option("reprojection", "exclusive", "string", "how a pixel reads the history: each "
           "previous pixel serves one pixel (exclusive) or every pixel reads its nearest "
           "previous pixel (nearest, the paper)", choices=_reprojection_modes,
           doc="How a pixel reads the history after a camera move: ``exclusive`` (each "
           "previous pixel serves only the pixel landing nearest its centre; the others start "
           "afresh, so no history value is copied into several pixels, whose noise the "
           "denoisers would then leave in place) or ``nearest`` (every pixel reads its "
           "nearest previous pixel: Nehab et al. 2007, the paper). A still camera reads all "
           "of its history either way. See :mod:`foveated_mi.frame.reproject`"),
    Option("clamp", 1e4, "float", "largest accepted sample component; larger samples are "
           "scaled down", lo=0.0, hi=3e38, lo_open=True),
    Option("frame_ms", 0.0, "float", "hold this frame time in milliseconds: the foveal "
           "formation chooses each frame's ray budget and spp (0: off)", lo=0.0, hi=1e6,
           doc="Hold this frame time (ms; 0, the default: off): before each frame of the "
           "foveal formation the integrator chooses its ``ray_budget``, ``spp``, "
           "``foveal_disc_spp`` and ``foveal_still_spp`` from a ladder of measured "
           "configurations, by a cost model fitted to its own last frames, and times the frame "
           "(forcing it); ``stats['frame_budget']`` gives the budget, the prediction, the "
           "measured time and the choice (:mod:`foveated_mi.budget`)"),
    Option("fps", 0.0, "float", "hold this frame rate: frame_ms = 1000 / fps (0: off)",
           lo=0.0, hi=1e6),
    Option("timing", False, "bool", "synchronise at stage boundaries and report wall time per "
           "stage", cli=False),
    Option("freeze", True, "bool", "replay the recorded kernels of the trace and of the "
           "passes after it instead of tracing them each frame",
           doc="Record the nested integrator's trace (:mod:`foveated_mi.frame.trace`) and the "
           "history resolve, reconstruction and post-processing "
           "(:mod:`foveated_mi.frame.formation`) once per configuration with ``dr.freeze`` "
           "and replay the recorded kernels on later frames: the same image without Python "
           "and Mitsuba tracing them again (for the trace, a virtual call per BSDF and "
           "emitter of the scene). Frames that are differentiated or timed are traced as "
           "usual, and so is the formation of a frame denoised by OIDN; false traces every "
           "frame."),
    Option("map_seed", -1, "int", "pin the sampling map to this seed (-1 follows the frame "
           "seed)", lo=-1, hi=0xFFFFFFFF),
)

#: Option name -> :class:`Option`, in the order of validation, the CLI and the docs.
SCHEMA: dict[str, Option] = {o.name: o for o in _SCHEMA}

#: The paper's pipeline; every option of the integrator, with its default.
DEFAULTS: dict[str, Any] = {o.name: o.default for o in _SCHEMA}

#: Where every option is listed, for an unknown option that is close to none of them.
OPTIONS_HELP = "`foveated-mi render --help`"


def unknown_option(name: str, value: Any,
                   what: str = "an option of the foveated integrator") -> ParameterError:
    """The one-line error of an option :data:`SCHEMA` does not hold: the closest option's name, or
    where the options are listed when none is close.

    Parameters
    ----------
    name : str
        The unknown option.
    value : object
        Its value.
    what : str, optional
        What is allowed, in words.

    Returns
    -------
    error : ParameterError
        The error to raise.
    """
    return ParameterError(name, value, unknown_name(name, SCHEMA, what, see=OPTIONS_HELP))


#: Preset name -> the defaults it replaces (see the module docstring).
PRESETS: dict[str, dict[str, Any]] = {
    # As published (Kwon et al. 2019) and, where the text is silent, the authors' code: the
    # Strategy 2 launch layout, an uncapped history, plain JFA, the strict in-circle test,
    # one à-trous level with unit sigmas (see the module docstring).
    "paper": {"reorder": "rows_blocks", "max_history": 0.0, "jfa": "jfa",
              "reprojection": "nearest",
              "sibson_inclusive": False,
              "atrous_iterations": 1, "sigma_color": 1.0, "sigma_normal": 1.0,
              "sigma_position": 1.0, "tonemap": "uncharted2"},
    "oidn": {"theta": 0.25, "sigma_p": 0.8, "demodulate": True, "reconstruction": "stochastic",
             "denoiser": "oidn", "emission_edges": True, "reorder": "tiles"},
    "guided": {"demodulate": True, "reconstruction": "guided", "denoiser": "svgf",
               "emission_edges": True, "reorder": "tiles"},
    # The formation in a log-polar buffer around the gaze, sized by the ray budget: no
    # reconstruction on the film, the denoiser in the buffer, one warp. Tiles: the launch of
    # its samples built in tile order costs what compact's does, and its scattered rays
    # trace faster in 2D packets (docs/results.md#the-vr-preset). SVGF four levels wide, its
    # colour test at 8 noise deviations: a periphery seen at a few pixels per degree scores
    # higher smooth than with its cells' noise (docs/results.md#the-buffers-filter-strength);
    # at 6 where the camera moved: the edges that slide as the head turns flicker less, at the
    # same video JOD (docs/results.md#svgfs-colour-test-where-the-camera-moved).
    # Its disc at most 2 samples a pixel: above that its rays cost more than the fovea's video
    # JOD gains (docs/results.md#the-disc-at-a-sample-rate-of-its-own). The disc at 2 levels
    # where the camera moved: the same video JOD, a moving frame's cost lower
    # (docs/results.md#the-discs-levels-where-the-camera-moved). A still view settles to one
    # sample every eight frames a ray, in turn, once its history is full: the same video
    # JOD or more, less flicker, an eighth of the rays
    # (docs/results.md#settled-rays-in-turn). The gaze held within 1 degree: a tracker's
    # jitter of 0.25 degrees would keep a fixation from ever settling, and a hold of 0.5
    # does not absorb it (docs/results.md#an-eye-trackers-jitter-held).
    "vr": {"sampling_law": "polar", "formation": "foveal", "ray_budget": 0.1, "theta": 0.15,
           "reorder": "tiles", "edge_threshold": 0.0, "denoiser": "svgf",
           "atrous_iterations": 4, "sigma_luminance": 8.0, "sigma_luminance_moving": 6.0,
           "max_history_moving": 8.0,
           "foveal_disc": "denoised", "foveal_disc_spp": 2, "foveal_disc_iterations_moving": 2,
           "foveal_still_spp": 0.125, "gaze_hold_deg": 1.0},
}
PRESET_NAMES = ("auto", *PRESETS)


def resolve_preset(preset: str, gradients: bool = False) -> str:
    """The preset ``preset`` stands for (``auto`` -> ``vr``, or ``guided`` for gradients).

    Parameters
    ----------
    preset : str
        One of :data:`PRESET_NAMES`.
    gradients : bool, optional
        The frames will be differentiated (a nested AD integrator such as ``prb``, or a gradient
        pass), so ``auto`` picks the preset whose gradient is exact.

    Returns
    -------
    preset : str
        A key of :data:`PRESETS`: ``auto`` gives ``guided`` for gradients, else ``vr``.
    """
    check_choice("preset", preset, PRESET_NAMES)
    if preset != "auto":
        return preset
    # Measured at each preset's defaults against every uniform family, still and moving, in
    # a headset and on a monitor (docs/results.md#what-auto-stands-for): vr reached each
    # scene's video JOD fastest. A differentiated frame is optimised, not viewed: it keeps
    # guided, whose gradient the default's tests check (tests/test_defaults.py).
    return "guided" if gradients else "vr"


def uniform_counterpart(preset: str) -> str:
    """The preset whose history and denoiser a uniform frame (``sigma_p = 1``: every pixel traced)
    shares with ``preset``.

    A preset that forms its frame in a foveal buffer (``vr``) traces ``ray_budget`` of the
    pixels whatever ``sigma_p`` says; its uniform counterpart is the film-space preset with
    the same denoiser.

    Parameters
    ----------
    preset : str
        One of :data:`PRESET_NAMES` (``auto`` is resolved first, without gradients).

    Returns
    -------
    preset : str
        ``preset`` itself, or for a foveal-buffer preset the first film-space preset of
        :data:`PRESETS` with its denoiser (``vr`` -> ``guided``: SVGF).
    """
    preset = resolve_preset(preset)
    if PRESETS[preset].get("formation", DEFAULTS["formation"]) == DEFAULTS["formation"]:
        return preset
    denoiser = PRESETS[preset].get("denoiser", DEFAULTS["denoiser"])
    return next(p for p, o in PRESETS.items()
                if o.get("formation", DEFAULTS["formation"]) == DEFAULTS["formation"]
                and o.get("denoiser", DEFAULTS["denoiser"]) == denoiser)


# -- validation -----------------------------------------------------------------------------

def validate_options(options: dict[str, Any], gradients: bool = False) -> dict[str, Any]:
    """Check every option and return them all, normalised.

    Parameters
    ----------
    options : dict
        The options given.
    gradients : bool, optional
        See :func:`resolve_preset`.

    Returns
    -------
    options : dict
        Every option of :data:`SCHEMA`, with the preset resolved and ``pixel_filter = "auto"``
        resolved by the denoiser (:func:`resolve_pixel_filter`).

    Raises
    ------
    ParameterError
        (One line) for an unknown option or a bad value.
    """
    unknown = set(options) - set(SCHEMA)
    if unknown:
        name = sorted(unknown)[0]
        raise unknown_option(name, options[name])
    preset = resolve_preset(options.get("preset", DEFAULTS["preset"]), gradients)
    defaults = {name: opt.default for name, opt in SCHEMA.items()}
    merged = {**defaults, **PRESETS[preset], "preset": preset, **options}
    out = {name: opt.validate(merged[name]) for name, opt in SCHEMA.items()}
    out["preset"] = preset
    out["pixel_filter"] = resolve_pixel_filter(out["pixel_filter"], out["denoiser"])
    # The preset's disc and still rates need the buffer's samples, its disc levels a
    # denoised disc.
    foveal = out["formation"] == "foveal"
    for name, off, needed in (("foveal_disc_spp", 0, out["foveal_space"] == "buffer"),
                              ("foveal_still_spp", 0, out["foveal_space"] == "buffer"),
                              ("foveal_disc_iterations_moving", -1,
                               out["foveal_disc"] == "denoised")):
        if name not in options and not (foveal and needed):
            out[name] = off
    for still, moving in (("sigma_luminance", "sigma_luminance_moving"),
                          ("max_history", "max_history_moving")):
        if still in options and moving not in options:
            # A colour test or cap given is the one every frame reads, not the preset's
            # moving one.
            out[moving] = 0.0
    out["frame_ms"] = _check_frame_budget(out["frame_ms"], out["fps"])
    if out["frame_ms"] > 0 and (out["formation"], out["foveal_space"]) != ("foveal", "buffer"):
        raise ParameterError("frame_ms", out["frame_ms"], "0 unless formation = 'foveal' and "
                             "foveal_space = 'buffer' (the vr preset chooses its rays to hold it)")
    _check_combination(out)
    return out


def _check_frame_budget(frame_ms: float, fps: float) -> float:
    """The frame time to hold from ``frame_ms`` and ``fps`` (validated, 0 each: off).

    Parameters
    ----------
    frame_ms : float
        Milliseconds a frame (0: off).
    fps : float
        Frames a second (0: off); ``frame_ms = 1000 / fps``.

    Returns
    -------
    frame_ms : float
        The budget in ms (0: off).

    Raises
    ------
    ParameterError
        Where both are given and disagree by more than a frame time written to three
        significant figures can (0.5 %).
    """
    if fps <= 0:
        return frame_ms
    ms = 1000.0 / fps
    if frame_ms > 0 and abs(frame_ms - ms) > 5e-3 * ms:
        raise ParameterError("fps", fps, f"1000 / frame_ms ({1000.0 / frame_ms:.4g}), or 0 "
                             "with frame_ms given")
    return ms


#: Options of the foveal buffer's own samples, and the value that leaves them off.
_BUFFER_ONLY = (("foveal_interleave", 1), ("foveal_disc_spp", 0), ("foveal_jitter", 0.0),
                ("foveal_taa", 1.0), ("foveal_still_spp", 0))


def _check_combination(out: dict[str, Any]) -> None:
    """Checks of one option against another, and of the denoiser's requirements."""
    if out["sampling_law"] == "acuity" and out["acuity_floor"] > out["ray_budget"]:
        raise ParameterError("acuity_floor", out["acuity_floor"],
                             f"a number <= ray_budget ({out['ray_budget']:g})")
    if out["polar_cells"] != "log" and out["sampling_law"] != "polar":
        raise ParameterError("polar_cells", out["polar_cells"],
                             "'log' unless sampling_law = 'polar' (the only law with cells)")
    in_buffer = out["formation"] == "foveal" and out["foveal_space"] == "buffer"
    for name, neutral in _BUFFER_ONLY:
        if out[name] != neutral and not in_buffer:
            raise ParameterError(name, out[name], f"{neutral:g} unless formation = 'foveal' "
                                 "and foveal_space = 'buffer'")
    for name, unset in (("foveal_disc_iterations", -1), ("foveal_disc_iterations_moving", -1),
                        ("foveal_disc_sigma_luminance", 0.0), ("foveal_disc_denoiser", "same")):
        if out[name] != unset and (out["formation"] != "foveal"
                                   or out["foveal_disc"] != "denoised"):
            shown = repr(unset) if isinstance(unset, str) else f"{unset:g}"
            raise ParameterError(name, out[name], f"{shown} unless formation = 'foveal' "
                                 "and foveal_disc = 'denoised'")
    if out["foveal_contrast"] > 0.0 and out["formation"] != "foveal":
        raise ParameterError("foveal_contrast", out["foveal_contrast"],
                             "0 unless formation = 'foveal'")
    if out["formation"] == "foveal":
        # Its cells are the pixels the polar law traces (the flat law's: an even grid of
        # them, kept on the buffer's samples), and it keeps radiance throughout.
        if out["sampling_law"] == "flat" and out["foveal_space"] != "buffer":
            raise ParameterError("sampling_law", "flat", "'polar' with formation = 'foveal' "
                                 "and foveal_space = 'film' ('flat' needs foveal_space = "
                                 "'buffer')")
        if out["sampling_law"] not in ("polar", "flat"):
            raise ParameterError("sampling_law", out["sampling_law"],
                                 "'polar' or 'flat' with formation = 'foveal'")
        if out["tonemap_samples"]:
            raise ParameterError("tonemap_samples", True, "False with formation = 'foveal'")
        if out["foveal_space"] == "buffer":
            # Nothing full-resolution exists to read: no film G-buffer, no film history.
            why = "with foveal_space = 'buffer' (set foveal_space = 'film' to use it)"
            if out["foveal_upsampling"] == "joint":
                raise ParameterError("foveal_upsampling", out["foveal_upsampling"],
                                     f"'bilinear' or 'cubic' {why}")
            if out["emission_edges"]:
                raise ParameterError("emission_edges", True, f"False {why}")
            if out["edge_threshold"] > 0:
                raise ParameterError("edge_threshold", out["edge_threshold"], f"0 {why}")
    entry = denoisers()[out["denoiser"]]
    if out["tonemap_samples"]:
        # The history and the reconstruction then hold display values: demodulation and
        # a denoiser that models the noise of radiance (SVGF's variance) assume radiance.
        if out["demodulate"]:
            raise ParameterError("demodulate", True, "False with tonemap_samples = True")
        if not entry.display_values:
            ok = [n for n, d in denoisers().items() if d.display_values and n != "none"]
            raise ParameterError("denoiser", out["denoiser"], ", ".join(ok) + " or none with "
                                 "tonemap_samples = True")
    for name in ("denoiser", "foveal_disc_denoiser"):
        entry = denoisers().get(out[name])
        if entry is not None and entry.available is not None and not entry.available():
            raise ParameterError(name, out[name], f"{entry.requirement}, or another "
                                 "of " + ", ".join(denoisers()))


# -- what a gradient pass cannot differentiate ----------------------------------------------

def non_differentiable() -> dict[str, tuple[Callable[[dict], bool], str]]:
    """The options a gradient pass may refuse, from the schema.

    Options whose choices come from a registry come last: the pipeline's own options are
    reported first.

    Returns
    -------
    rules : dict
        Option -> (predicate on the validated options that holds where a gradient pass cannot
        differentiate the frame, what it needs instead).
    """
    opts = [o for o in _SCHEMA if o.differentiable is not True]
    opts.sort(key=lambda o: callable(o.choices))
    return {o.name: (lambda options, o=o: not o.is_differentiable(
        options.get(o.name, o.default)), o.gradient) for o in opts}


#: option -> (predicate on the validated options, what a differentiable run needs), in
#: registration order: the schema's rules (:func:`non_differentiable`: ``tonemap_samples``,
#: and a denoiser registered with ``differentiable=False``), then any registered after.
NON_DIFFERENTIABLE: dict[str, tuple[Callable[[dict], bool], str]] = dict(non_differentiable())


def register_non_differentiable(option: str, predicate: Callable[[dict], bool],
                                allowed: str) -> None:
    """Declare that options for which ``predicate(options)`` holds make a frame
    non-differentiable, e.g. ``register_non_differentiable("exposure", lambda o:
    o["exposure"] > 3, "<= 3 for gradients")``. The product's own rules live in the option
    schema.

    Parameters
    ----------
    option : str
        The option named in the refusal (a later registration under the same name replaces it).
    predicate : callable
        ``predicate(options) -> bool`` on the validated options: True when the frame cannot be
        differentiated.
    allowed : str
        What a differentiable run needs, quoted in the error.
    """
    NON_DIFFERENTIABLE[option] = (predicate, allowed)


def refusal(options: dict[str, Any]) -> ParameterError | None:
    """The one-line error for the first option that makes the frame non-differentiable, or
    None when nothing does.

    Parameters
    ----------
    options : dict
        The validated options, as the registered predicates read them.

    Returns
    -------
    error : ParameterError or None
        The error for the first registered rule whose predicate holds, in registration order;
        None when no rule does.
    """
    for name, (predicate, allowed) in NON_DIFFERENTIABLE.items():
        if predicate(options):
            return ParameterError(name, options.get(name), allowed)
    return None


def check_differentiable(options: dict[str, Any]) -> None:
    """Raise :func:`refusal`'s error, if any.

    Parameters
    ----------
    options : dict
        The validated options.

    Raises
    ------
    ParameterError
        When an option makes the frame non-differentiable.
    """
    error = refusal(options)
    if error is not None:
        raise error


# -- docs -----------------------------------------------------------------------------------

def parameter_table() -> str:
    """The ``.. pluginparameters::`` table of the integrator's docstring, from the schema
    (registered methods included).

    Returns
    -------
    table : str
        The reStructuredText table.
    """
    lines = [".. pluginparameters::", ""]
    for o in _SCHEMA:
        text = o.doc if o.doc is not None else o.help[0].upper() + o.help[1:]
        grad = "" if o.differentiable is True else f"; gradients: {o.gradient}"
        lines += [f" * - {o.name}", f"   - {XML_TYPES[o.kind]}",
                  f"   - {text}. Allowed: {o.range_text()}; default ``{o.default_text()}``"
                  + grad]
    lines += [" * - (nested)", "   - |integrator|",
              "   - Any sampling integrator (default ``path``); XML allows it unnamed", ""]
    return "\n".join(lines)


def from_properties(props) -> tuple[dict[str, Any], Any]:
    """The options and the nested integrator of an XML ``<integrator type="foveated">``.

    Parameters
    ----------
    props : mi.Properties
        Each parameter must be an option of :data:`SCHEMA` (a ``<point>`` becomes ``(x, y)``),
        and at most one child a sampling integrator.

    Returns
    -------
    options : dict
        The options given.
    nested : mi.SamplingIntegrator or None
        None when the XML names none.
    """
    import mitsuba as mi
    options: dict[str, Any] = {}
    nested = None
    for name in props.keys():
        if props.type(name) == mi.Properties.Type.Object:
            obj = props.get(name)
            if not isinstance(obj, mi.SamplingIntegrator):
                raise ParameterError(f"nested integrator {name!r}", type(obj).__name__,
                                     "a sampling integrator such as 'path'")
            if nested is not None:
                raise ParameterError(f"nested integrator {name!r}", type(obj).__name__,
                                     "a single nested integrator")
            nested = obj
        elif name in SCHEMA:
            v = props.get(name)
            if SCHEMA[name].kind == "point":      # an XML <point>: x and y
                v = (float(v[0]), float(v[1]))
            options[name] = v
        else:
            raise unknown_option(name, props.get(name), "a known parameter")
    return options, nested


def gradient_refusal(options: dict[str, Any]) -> ParameterError | None:
    """Why a gradient pass of a frame with these options would not be the gradient of the image
    shown.

    Parameters
    ----------
    options : dict
        The validated options.

    Returns
    -------
    error : ParameterError or None
        The one-line error to raise (None: it would be the gradient).
    """
    error = refusal(options)
    if error is None or error.name != "denoiser":
        return error
    # A gradient of another image than the one shown would mislead an optimisation.
    denoiser = error.value
    return ParameterError("denoiser", denoiser, f"a differentiable denoiser ({denoiser} "
                          "is not differentiable): preset='guided' (or denoiser='svgf', "
                          "'atrous' or 'none') for gradients")
