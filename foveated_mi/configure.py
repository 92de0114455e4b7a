"""The validated options compiled once into the frame's typed settings.

As a Mitsuba plugin reads its properties once into typed attributes, the integrator compiles
its validated options (:func:`foveated_mi.options.validate_options`) here, once per change,
into the frozen settings of :mod:`foveated_mi.frame.settings`: one set per pass, each holding
only what its pass reads. This module is the only place that reads the options by name for
the frame: no pass in :mod:`foveated_mi.frame` takes them.

A formation's own settings are compiled by its *reader*, ``reader(width, height, o)``: the
built-in formations' readers are below (:data:`READERS`); a formation registered elsewhere
passes its own to :func:`~foveated_mi.frame.formation.register_formation`.
"""
from __future__ import annotations

from typing import Any, Callable

from .frame import buffer_space as _buffer_space
from .frame.film import FilmSettings, jfa_bound
from .frame.formation import FORMATIONS, FormationSettings, OptionValues
from .frame.foveal import FovealSettings
from .frame.cells import cell_offset, foveal_grid, fovea_radius, sensor_ppd
from .frame.settings import (DenoiseSettings, DomainSettings, FrameSettings, HistorySettings,
                             LaunchSettings, PlanSettings, ReconstructionSettings,
                             SamplingSettings, TraceSettings)
from .frame.space import SPACES
from .postprocess import DENOISERS
from .options import DEFAULTS, SCHEMA, IgnoredOptionWarning, still_rate
from .validate import check_choice

Options = dict[str, Any]


def _frozen(v: Any) -> Any:
    return tuple(v) if isinstance(v, list) else v


# -- the passes before the trace, and the trace ------------------------------------------------

def interleave_of(o: Options) -> int:
    """``foveal_interleave``, which needs a history: a cell shows its history between its
    turns. Without one, every cell is traced each frame (1).

    Parameters
    ----------
    o : dict
        The validated options.

    Returns
    -------
    n : int
        The interleave the plan and the formation use.
    """
    return int(o["foveal_interleave"]) if o["history"] else 1


def jitter_of(o: Options) -> float:
    """``foveal_jitter`` of validated options ``o``; 0 without a history, whose mean over
    each cell is what the jitter builds."""
    return float(o["foveal_jitter"]) if o["history"] else 0.0


def sampling_settings(o: Options) -> SamplingSettings:
    """The sampling law's settings of validated options ``o``.

    Parameters
    ----------
    o : dict
        The validated options; the sampling law's are read.

    Returns
    -------
    settings : SamplingSettings
        The sampling law and the rays it forces.
    """
    return SamplingSettings(
        law=o["sampling_law"], theta=float(o["theta"]), theta_deg=float(o["theta_deg"]),
        sigma_p=float(o["sigma_p"]), ray_budget=float(o["ray_budget"]),
        acuity_floor=float(o["acuity_floor"]), edge_threshold=float(o["edge_threshold"]),
        edge_detector=o["edge_detector"], emission_edges=bool(o["emission_edges"]),
        map_seed=int(o["map_seed"]), polar_cells=o["polar_cells"],
        viewer_ppd=float(o["viewer_ppd"]), interleave=interleave_of(o),
        jitter=jitter_of(o))


def frame_settings(o: Options) -> FrameSettings:
    """The settings of the passes up to the trace, read from validated options ``o`` once
    per change of the options.

    Parameters
    ----------
    o : dict
        The validated options; the plan's and the trace's are read.

    Returns
    -------
    settings : FrameSettings
        The plan's settings (with the sample space the formation declares,
        :func:`formation_space`) and the trace pass's.
    """
    plan = PlanSettings(
        sampling_settings(o), LaunchSettings(o["reorder"], int(o["block_height"]),
                                            int(o["foveal_disc_spp"]),
                                            *still_rate(o["foveal_still_spp"])),
        HistorySettings(bool(o["history"]), o["reprojection"],
                        float(o["reprojection_tolerance"]),
                        float(o["max_history"]) or float(DEFAULTS["max_history"])),
        space=formation_space(o),
        materials=bool(o["demodulate"] or o["emission_edges"]
                       or any(DENOISERS[n].materials for n in denoisers_used(o))),
        pixel_filter=o["pixel_filter"])
    trace = TraceSettings(float(o["clamp"]), o["pixel_filter"], bool(o["tonemap_samples"]),
                          o["tonemap"], float(o["exposure"]))
    return FrameSettings(plan, trace)


# -- the parts the formations share ------------------------------------------------------------

def domain_settings(o: Options) -> DomainSettings:
    """The domain settings of validated options ``o``.

    Parameters
    ----------
    o : dict
        The validated options; the value domains' are read.

    Returns
    -------
    settings : DomainSettings
        ``demodulate``, ``tonemap_samples``, ``tonemap``, ``exposure`` and ``clamp``.
    """
    return DomainSettings(bool(o["demodulate"]), bool(o["tonemap_samples"]), o["tonemap"],
                          float(o["exposure"]), float(o["clamp"]))


def denoisers_used(o: Options) -> tuple[str, ...]:
    """The registered denoisers a frame of validated options ``o`` runs: ``denoiser``, and the
    foveal disc's own (``foveal_disc_denoiser``) where it is set."""
    disc = o.get("foveal_disc_denoiser", "same")
    return (o["denoiser"],) if disc in ("same", o["denoiser"]) else (o["denoiser"], disc)


def denoise_settings(o: Options) -> DenoiseSettings:
    """The denoiser of validated options ``o``, with the options it reads.

    Parameters
    ----------
    o : dict
        The validated options; ``denoiser`` and what it reads are read.

    Returns
    -------
    settings : DenoiseSettings
        The denoiser's name, the options its registration reads (lists as tuples), and whether
        it is active for them.
    """
    entry = DENOISERS[o["denoiser"]]
    params = {k: o[k] for k in entry.reads}
    active = entry.active is None or bool(entry.active(params))
    return DenoiseSettings(o["denoiser"], tuple((k, _frozen(v)) for k, v in params.items()),
                           active)


def reconstruction_settings(o: Options) -> ReconstructionSettings:
    """The reconstruction method of validated options ``o``, with its parameters.

    Parameters
    ----------
    o : dict
        The validated options; ``reconstruction``, ``jfa``, ``max_radius``, ``sampling_law``
        and ``sigma_p`` are read, with the method's own.

    Returns
    -------
    settings : ReconstructionSettings
        The method, whether every pixel is traced, ``jfa``, ``max_radius``, the method's
        keyword parameters (lists as tuples) and the samples it averages per pixel (None where
        it declares none).
    """
    from .reconstruct import RECONSTRUCTIONS
    method = RECONSTRUCTIONS[o["reconstruction"]]
    params = tuple((kw, _frozen(o[name])) for kw, name in method.options.items())
    # Only Eq. 1's law reads sigma_p: at 1 it traces every pixel (in film units or degrees);
    # the acuity and polar laws trace their budget whatever sigma_p says.
    every_pixel = o["sampling_law"] == "kwon" and float(o["sigma_p"]) >= 1.0
    return ReconstructionSettings(o["reconstruction"], every_pixel, o["jfa"],
                                  int(o["max_radius"]), params,
                                  None if method.averages is None else o[method.averages])


# -- options that nothing reads ----------------------------------------------------------------

#: Sampling law -> the options of :func:`sampling_settings` that only some laws read, and the
#: laws that read them (:mod:`foveated_mi.frame.sampling`: ``sampling_pass``, and
#: ``jfa_bound`` of :mod:`foveated_mi.frame.film`).
LAW_OPTIONS: dict[str, tuple[str, ...]] = {
    "theta": ("kwon", "polar"), "sigma_p": ("kwon",), "theta_deg": ("kwon",),
    "ray_budget": ("acuity", "polar", "flat"), "acuity_floor": ("acuity",)}

#: Options that only the ``film`` formation reads (:func:`film_settings`, through
#: :func:`reconstruction_settings`), beside each reconstruction method's own.
FILM_OPTIONS = ("reconstruction", "jfa", "max_radius")

#: Options that only the ``foveal`` formation reads (:func:`foveal_settings`) and that no
#: check of :func:`~foveated_mi.options.validate_options` refuses elsewhere.
FOVEAL_OPTIONS = ("foveal_upsampling", "foveal_space", "foveal_disc")

#: Options of the foveal formation's full-resolution disc, which ``sampling_law = "flat"``
#: does not have (:mod:`foveated_mi.kernels.flat`).
DISC_OPTIONS = ("foveal_disc", "foveal_disc_spp", "foveal_disc_iterations",
                "foveal_disc_iterations_moving", "foveal_disc_sigma_luminance",
                "foveal_disc_denoiser")

#: Options that only denoisers read (their registrations' ``reads``), beside the moving
#: frame's colour test, which replaces ``sigma_luminance``.
DENOISER_OPTIONS = ("atrous_iterations", "sigma_color", "sigma_normal", "sigma_position",
                    "sigma_luminance", "sigma_luminance_moving", "oidn_quality")

#: Where each setting is found (the hint of a warning).
_WHERE = {"kwon": "preset 'paper'", "polar": "preset 'vr'", "film": "preset 'paper', "
          "'guided' or 'oidn'", "foveal": "preset 'vr'"}


def _among(key: str, values) -> str:
    names = " or ".join(repr(v) for v in values)
    hints = [_WHERE[v] for v in values if v in _WHERE]
    return f"{key} {names}" + (f" (e.g. {hints[0]})" if hints else "")


def _unread_by_law(o: Options) -> dict[str, tuple[str, str]]:
    """Option -> (what excludes it, what reads it) for the sampling law's options."""
    unread = {}
    law = o["sampling_law"]
    for name, laws in LAW_OPTIONS.items():
        if law not in laws:
            unread[name] = (f"sampling_law {law!r}", _among("sampling_law", laws))
    if law == "kwon" and float(o["theta_deg"]) > 0:
        unread["theta"] = (f"theta_deg = {o['theta_deg']:g}", "sampling_law 'kwon' with "
                           "theta_deg = 0, or 'polar'")
    if law == "polar" and o["polar_cells"] != "acuity":
        unread["viewer_ppd"] = (f"polar_cells {o['polar_cells']!r}",
                                "polar_cells 'acuity' (sampling_law 'polar')")
    elif law != "polar":
        unread["viewer_ppd"] = (f"sampling_law {law!r}", "polar_cells 'acuity' (sampling_law "
                                "'polar', e.g. preset 'vr')")
    if law == "flat" and o["formation"] == "foveal":
        # An even buffer has no full-resolution disc.
        for name in DISC_OPTIONS:
            unread[name] = ("sampling_law 'flat', which has no disc",
                            "sampling_law 'polar' (e.g. preset 'vr')")
    return unread


def _unread_by_formation(o: Options) -> dict[str, tuple[str, str]]:
    """As :func:`_unread_by_law`, for the formation's and the reconstruction's options."""
    from .reconstruct import RECONSTRUCTIONS
    unread = {}
    formation = o["formation"]
    method_options = list(dict.fromkeys(n for r in RECONSTRUCTIONS.values()
                                        for n in r.options.values()))
    if formation != "film":
        for name in (*FILM_OPTIONS, *method_options):
            unread[name] = (f"formation {formation!r}", _among("formation", ("film",)))
        return unread
    used = RECONSTRUCTIONS[o["reconstruction"]].options.values()
    for name in method_options:
        if name not in used:
            readers = [m for m, r in RECONSTRUCTIONS.items() if name in r.options.values()]
            unread[name] = (f"reconstruction {o['reconstruction']!r}",
                            _among("reconstruction", readers))
    for name in FOVEAL_OPTIONS:
        unread[name] = (f"formation {formation!r}", _among("formation", ("foveal",)))
    return unread


def _unread_by_denoiser(o: Options) -> dict[str, tuple[str, str]]:
    """As :func:`_unread_by_law`, for the denoisers' options (their registrations' reads)."""
    used = denoisers_used(o)
    read = {n for d in used for n in DENOISERS[d].reads}
    if "sigma_luminance" in read:
        read.add("sigma_luminance_moving")
    unread = {}
    for name in DENOISER_OPTIONS:
        if name not in read:
            readers = [d for d, e in DENOISERS.items() if name in e.reads
                       or (name == "sigma_luminance_moving" and "sigma_luminance" in e.reads)]
            unread[name] = ("denoiser " + " and ".join(repr(d) for d in used),
                            _among("denoiser", readers))
    return unread


def ignored_options(given: Options, o: Options) -> dict[str, str]:
    """The options given explicitly that the frame of validated options ``o`` does not read,
    each with a one-line warning.

    An option that the preset sets but the user did not is never listed; nor is one that
    :func:`~foveated_mi.options.validate_options` refuses where it has no effect; nor any
    when ``given`` holds every option (options already resolved, passed on).

    Parameters
    ----------
    given : dict
        The options the user set.
    o : dict
        The validated options.

    Returns
    -------
    warnings : dict
        Option -> ``"NAME = VALUE has no effect under preset 'P' (WHAT); it is read by
        ..."``, in the order of ``given``.
    """
    if set(SCHEMA) - {"gaze", "timing"} <= set(given):
        return {}       # every option, resolved (a study's task): what the user set is unknown
    unread = {**_unread_by_denoiser(o), **_unread_by_formation(o), **_unread_by_law(o)}
    out = {}
    for name, value in given.items():
        if name in unread:
            why, reader = unread[name]
            shown = f"{value:g}" if isinstance(value, float) else repr(value)
            out[name] = (f"{name} = {shown} has no effect under preset {o['preset']!r} "
                         f"({why}); it is read by {reader}")
    return out


def warn_ignored(given: dict[str, Any], options: dict[str, Any],
                 warned: set[str] = frozenset()) -> set[str]:
    """Warn (:class:`IgnoredOptionWarning`, one line each) of the options given that nothing
    reads under the others (:func:`ignored_options`), but those in
    ``warned``.

    Parameters
    ----------
    given : dict
        The options the user set.
    options : dict
        The validated options.
    warned : set of str, optional
        The warnings already given (the last call's result): not repeated.

    Returns
    -------
    warnings : set of str
        Every warning that holds now, for the next call.
    """
    import warnings
    now = set(ignored_options(given, options).values())
    for text in sorted(now - set(warned)):
        warnings.warn(text, IgnoredOptionWarning, stacklevel=4)   # the integrator's caller
    return now


# -- the built-in formations' readers ----------------------------------------------------------

def film_settings(width: int, height: int, o: Options) -> FilmSettings:
    """The film formation's settings. The sampling law enters only through the Jump Flooding
    bound (host scalars, no sync), so a moving gaze rarely changes them.

    Parameters
    ----------
    width, height : int
        The film's size.
    o : dict
        The validated options, with the frame's gaze (``o["gaze"]``).

    Returns
    -------
    settings : FilmSettings
        The formation's settings (hashable: its recording's key).
    """
    return FilmSettings(float(o["max_history"]), domain_settings(o), reconstruction_settings(o),
                        denoise_settings(o),
                        jfa_bound(width, height, sampling_settings(o), o["gaze"]),
                        moving_denoise_settings(o), float(o["max_history_moving"]))


def foveal_settings(width: int, height: int, o: Options) -> FovealSettings:
    """The foveal formation's settings.

    Parameters
    ----------
    width, height : int
        The film's size in pixels, which sizes its buffer.
    o : dict
        The validated options (``theta``, ``ray_budget``, ``polar_cells``, ``foveal_space``,
        ...), with ``viewer_ppd`` measured for ``acuity`` cells (:func:`viewer_options`).

    Returns
    -------
    settings : FovealSettings
        Its settings, with the samples' layout and the buffer's grid for this film.
    """
    offset = cell_offset(sampling_settings(o))
    lay = _buffer_space.layout(width, height, o["theta"], o["ray_budget"], offset,
                               interleave_of(o),
                               "flat" if o["sampling_law"] == "flat" else "polar")
    grid = lay.grid if o["foveal_space"] == "buffer" else foveal_grid(
        width, height, float(o["ray_budget"]), fovea_radius(width, height, o["theta"]),
        offset)
    disc, disc_moving = disc_denoise_settings(o), disc_denoise_settings(o, moving=True)
    return FovealSettings(float(o["max_history"]), domain_settings(o), denoise_settings(o),
                          o["foveal_upsampling"], o["foveal_space"], o["foveal_disc"], lay,
                          grid, float(o["foveal_taa"]), float(o["foveal_contrast"]), disc,
                          None if disc_moving == disc else disc_moving,
                          moving_denoise_settings(o), float(o["max_history_moving"]))


def moving_options(o: Options) -> Options:
    """The options a frame whose camera moved reads: ``sigma_luminance_moving`` in place of
    ``sigma_luminance`` where it is set.

    Parameters
    ----------
    o : dict
        The validated options.

    Returns
    -------
    options : dict
        ``o`` itself, or a copy with the moving frame's colour test.
    """
    if float(o["sigma_luminance_moving"]) <= 0.0:
        return o
    return {**o, "sigma_luminance": o["sigma_luminance_moving"]}


def moving_denoise_settings(o: Options) -> DenoiseSettings | None:
    """The denoiser of a frame whose camera moved, where it differs from a still frame's.

    Parameters
    ----------
    o : dict
        The validated options.

    Returns
    -------
    settings : DenoiseSettings or None
        :func:`denoise_settings` of :func:`moving_options`; None where it is the still
        frame's (``sigma_luminance_moving`` unset, or a denoiser that does not read it).
    """
    moving = denoise_settings(moving_options(o))
    return None if moving == denoise_settings(o) else moving


def disc_denoise_settings(o: Options, moving: bool = False) -> DenoiseSettings:
    """The denoiser of the foveal disc's patch: the frame's, with ``foveal_disc_iterations``
    and ``foveal_disc_sigma_luminance`` in place of the buffer's levels and colour test where
    they are set.

    Parameters
    ----------
    o : dict
        The validated options.
    moving : bool, optional
        The denoiser of a frame whose camera moved: ``foveal_disc_iterations_moving`` levels
        where set, and the moving frame's colour test (:func:`moving_options`).

    Returns
    -------
    settings : DenoiseSettings
        As :func:`denoise_settings` gives for the disc's values of those options.
    """
    levels = o["foveal_disc_iterations"]
    if moving:
        if o["foveal_disc_iterations_moving"] >= 0:
            levels = o["foveal_disc_iterations_moving"]
        o = moving_options(o)
    disc = dict(o)
    if levels >= 0:
        disc["atrous_iterations"] = levels
    if o["foveal_disc_sigma_luminance"] > 0.0:
        disc["sigma_luminance"] = o["foveal_disc_sigma_luminance"]
    if o["foveal_disc_denoiser"] != "same":
        disc["denoiser"] = o["foveal_disc_denoiser"]
    return denoise_settings(disc)


def viewer_options(o: Options, sensor) -> Options:
    """The options a frame's formation reads through ``sensor``: with ``polar_cells =
    "acuity"`` and ``viewer_ppd = 0``, ``viewer_ppd`` is the sensor's pixels per degree at the
    film's centre (:func:`~foveated_mi.frame.cells.sensor_ppd`, the value the plan's
    sampling map uses), so that the formation's cells are the map's.

    Parameters
    ----------
    o : dict
        The validated options (a view's).
    sensor : mi.Sensor
        The frame's sensor.

    Returns
    -------
    options : dict
        ``o`` itself, or a copy with ``viewer_ppd`` measured.
    """
    if o["polar_cells"] != "acuity" or float(o["viewer_ppd"]) > 0.0:
        return o
    return {**o, "viewer_ppd": sensor_ppd(sensor)}


def every_option(width: int, height: int, o: Options) -> OptionValues:
    """The settings of a formation that declares no reader: every option, read by name.

    Parameters
    ----------
    width, height : int
        The film's size (unused).
    o : dict
        The validated options, every one of which is kept.

    Returns
    -------
    settings : OptionValues
        Every option (lists as tuples), sorted by name.
    """
    return OptionValues(tuple(sorted((k, _frozen(v)) for k, v in o.items())))


#: Built-in formation -> (its settings reader, its sample-space reader; None: the film's).
READERS: dict[str, tuple[Callable[[int, int, Options], Any],
                         Callable[[Options], str] | None]] = {
    "film": (film_settings, None),
    "foveal": (foveal_settings, lambda o: o["foveal_space"]),
}


def formation_settings(o: Options, width: int, height: int) -> FormationSettings:
    """The settings of the formation of validated options ``o`` on a ``width`` x ``height``
    film.

    Parameters
    ----------
    o : dict
        The validated options (``o["formation"]`` names the formation).
    width, height : int
        The film's size.

    Returns
    -------
    settings : FormationSettings
        The formation's name and its own settings, by its registration's reader, else the
        built-in one (:data:`READERS`), else every option.
    """
    name = check_choice("formation", o["formation"], FORMATIONS)
    reader = FORMATIONS[name].settings or READERS.get(name, (every_option,))[0]
    return FormationSettings(name, reader(width, height, o))


def formation_space(o: Options) -> str:
    """The sample space the formation of validated options ``o`` forms from.

    Parameters
    ----------
    o : dict
        The validated options (``o["formation"]`` names the formation).

    Returns
    -------
    space : str
        One of :data:`~foveated_mi.frame.space.SPACES`: ``'film'`` or ``'buffer'``.
    """
    name = check_choice("formation", o["formation"], FORMATIONS)
    reader = FORMATIONS[name].space or READERS.get(name, (None, None))[1]
    return check_choice("formation space", "film" if reader is None else reader(o), SPACES)
