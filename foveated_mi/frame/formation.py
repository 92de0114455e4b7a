"""Image formation: the passes after the trace, as one registered function of the shading buffer.

A *formation* turns a frame's sparse shading buffer into its image. It registers beside its
code, as ``mi.register_integrator`` does::

    register_formation("film", form_film, stats=film_stats)

and is chosen by the option ``formation``. It is called as ``fn(shading, inp, settings,
timer, grad_pass)`` (``inp``: :class:`FormationInput`; ``settings``: its own, compiled once from the options
by its reader, :func:`foveated_mi.configure.formation_settings`) and returns a
:class:`Formed`: the image on the film, its named buffers on the formation's own grid
(:class:`~foveated_mi.kernels.grid.Grid`, declared at registration), and the history the next
frame reads. The integrator, the gradient pass (:mod:`foveated_mi.frame.adjoint`), the
frozen replay below, ``buffer()`` and the stats work from what a formation returns and
declares, so a new formation is one function plus one registry line. Every weight inside a
formation must come from the G-buffer, the sampling map or detached values, so that the
image is a fixed function of the traced values, which the gradient pass differentiates.

**Frozen replay.** Python traces every kernel of these passes again each frame; on a GPU that
tracing costs more than the kernels run (``benchmarks/bench_overhead.py`` reports both).
:class:`FrozenFormation` records a formation once per configuration with ``dr.freeze`` and
afterwards launches the recorded kernels on the frame's buffers without tracing them. A
recording is keyed on what decides the kernels: the formation, the film size, ``spp``, the
formation's settings, which buffers exist, and whether the G-buffer holds; the buffers, the
history, the fill's seed and what the formation kept of a still view's G-buffer are inputs.
A key not seen before records again (the most recent ``RECORDINGS`` are kept). The replay
serves frames that are not differentiated, with stage timing off (timing synchronises
between passes) and a denoiser registered as ``replayable`` (OIDN runs on the host between
kernels). Option ``freeze = false`` traces every frame.
"""
from __future__ import annotations

import gc
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple

import drjit as dr
import mitsuba as mi

from ..kernels.grid import Grid
from ..postprocess import DENOISERS
from ..timing import StageTimer
from . import reproject as _reproject
from . import sampling as _sampling
from ..kernels.buffers import GBuffer
from .shading import ShadingBuffer
from .space import space_of

#: Recorded configurations kept by a :class:`FrozenFormation` (least recently used dropped).
#: A frame budget visits a few dozen (a rung x moving or still x a still view settling: 27-45
#: in 400 frames at 576x324); with fewer kept it records some of them again, a frame of many
#: times the budget each time. What a recording holds is small: with the C library's mmap
#: threshold fixed (``MALLOC_MMAP_THRESHOLD_=131072``) holding 27 grew resident memory by
#: 15 MiB over 200 frames (docs/results.md, "Long runs and memory").
RECORDINGS = 64


class FormationInput(NamedTuple):
    """What a formation reads of a frame besides its shading buffer (film-sized buffers)."""
    gbuffer: GBuffer
    reprojection: _reproject.ReprojectionMap
    history: _reproject.History | None
    width: int
    height: int
    spp: int
    fill_seed: Any                        #: the stochastic fill's seed (int or mi.UInt32)
    emission_edges: mi.Bool | None = None
    gaze: mi.Point2f | None = None        #: the gaze's film position in pixels (opaque)
    #: where the shading buffer, G-buffer, reprojection and history live: the film's pixels,
    #: or the foveal buffer's samples (:mod:`foveated_mi.frame.space`)
    space: Any = None
    #: the foveal disc's samples per pixel where below ``spp`` (``foveal_disc_spp``): each
    #: sample's history then weighs the samples it traced; 0: every one ``spp``
    disc_spp: int = 0
    #: what the formation kept of this G-buffer on an earlier frame (its ``Formed.kept``),
    #: given back while the G-buffer holds (a still view); None: nothing kept
    kept: dict | None = None
    #: the G-buffer is the last frame's and holds: what the formation derives from it alone
    #: may be returned as ``Formed.kept``, to be given back next frame
    keep: bool = False
    #: the camera moved since the view's last frame, whose history this frame reprojects
    #: (a host value: a formation may run lighter passes where motion hides their loss)
    moving: bool = False


class Formed(NamedTuple):
    """A formation's result."""
    image: mi.Color3f                     #: the frame's radiance, one value per film pixel
    buffers: dict[str, Any]               #: named buffers (flat arrays or None) on its grid
    history: dict[str, Any] | None        #: ``mean``, ``count``, ``moment2`` per film pixel
    #: (or per sample, where the plan is on samples)
    #: the image interleaved (RGB per pixel, as the frame returns it), where a replay wrote
    #: it so; ``image`` is then a lazy view of it
    flat: mi.Float | None = None
    #: what it derived from the G-buffer alone (``FormationInput.keep``), for the next
    #: frames while the G-buffer holds; None: nothing
    kept: dict | None = None


class Formation(NamedTuple):
    """A registered formation (see :func:`register_formation`)."""
    fn: Callable[..., Formed]
    grid: Callable[[int, int, Any], Grid]
    #: ``reader(width, height, options)``; None: :mod:`foveated_mi.configure` reads it
    settings: Callable[[int, int, dict], Any] | None
    stats: Callable[[dict], dict]
    counted: tuple[str, ...]
    on_film: tuple[str, ...]
    grids: Callable[[int, int, Any], dict]
    space: Callable[[dict], str] | None   #: ``reader(options)``; None: as ``settings``


@dataclass(frozen=True)
class FormationSettings:
    """The formation a frame runs and its own settings (hashable: its recording's key)."""
    name: str
    settings: Any

    @property
    def entry(self) -> Formation:
        return FORMATIONS[self.name]


@dataclass(frozen=True)
class OptionValues:
    """The settings of a formation that declares none: every option, read by name."""
    items: tuple

    def __getitem__(self, name: str) -> Any:
        return dict(self.items)[name]


#: Formation name -> :class:`Formation`, in registration order.
FORMATIONS: dict[str, Formation] = {}


def register_formation(name: str, fn: Callable[..., Formed], *,
                       grid: Callable[[int, int, Any], Grid] | None = None,
                       settings: Callable[[int, int, dict], Any] | None = None,
                       stats: Callable[[dict], dict] | None = None,
                       counted: tuple[str, ...] = (), on_film: tuple[str, ...] = (),
                       grids: Callable[[int, int, Any], dict] | None = None,
                       space: Callable[[dict], str] | None = None) -> None:
    """Make ``fn`` the formation ``name`` (the option value ``formation = name``).

    Parameters
    ----------
    name : str
        The option value that chooses it.
    fn : callable
        ``fn(shading, inp, settings, timer, grad_pass) -> Formed``.
    grid : callable, optional
        ``grid(width, height, settings)``, the grid of its buffers (default: the film's).
    settings : callable, optional
        ``settings(width, height, o)``, its settings compiled from the validated options ``o``
        (and the frame's gaze, ``o["gaze"]``): a frozen, hashable value, all that ``fn``
        receives of the options and its recording's key, so it holds exactly what decides its
        kernels (a value in it that changes every frame records again). Default: the built-in
        formation's reader in :mod:`foveated_mi.configure`, else every option
        (:class:`OptionValues`).
    stats : callable, optional
        ``stats(buffers)``, counters read from its buffers (device arrays, read when the stats
        are read). Default: none.
    counted : tuple of str, optional
        The buffers its stats count, evaluated with the frame's other counted buffers (one
        launch).
    on_film : tuple of str, optional
        The buffers it returns on the film's grid when its own grid is another (the image
        always is).
    grids : callable, optional
        ``grids(width, height, settings)``, buffer name -> grid for those on a third grid, the
        plan's included (a formation whose plan keeps its G-buffer on its own samples).
    space : callable, optional
        ``space(o)``, the sample space it forms from (:data:`~.space.SPACES`): ``"film"`` (the
        default, or the built-in formation's reader), or ``"buffer"``, the foveal buffer's
        samples, which the plan then makes instead of the film's pixels (:mod:`.space`).
    """
    FORMATIONS[name] = Formation(
        fn, grid if grid is not None else (lambda width, height, s: Grid.film(width, height)),
        settings, stats if stats is not None else (lambda buffers: {}), tuple(counted),
        tuple(on_film), grids if grids is not None else (lambda width, height, s: {}), space)


def unregister_formation(name: str) -> None:
    """Remove the formation ``name`` (tests; a frame that uses it no longer validates).

    Parameters
    ----------
    name : str
        The formation's name; one not registered is ignored.
    """
    FORMATIONS.pop(name, None)


def form(shading: ShadingBuffer, inp: FormationInput, fs: FormationSettings, timer: StageTimer,
         grad_pass: bool = False) -> Formed:
    """The image of one frame by the formation ``fs`` names, with its settings.

    Parameters
    ----------
    shading : ShadingBuffer
        The frame's shading buffer.
    inp : FormationInput
        What the formation reads of the frame besides its shading buffer.
    fs : FormationSettings
        The formation and its settings.
    timer : StageTimer
        The frame's stage timer.
    grad_pass : bool, optional
        Whether this is a gradient pass.

    Returns
    -------
    formed : Formed
        The image, the named buffers and the history.
    """
    return fs.entry.fn(shading, inp, fs.settings, timer, grad_pass)


def replayable(freeze: bool, denoisers: tuple[str, ...], timer: StageTimer) -> bool:
    """Whether :class:`FrozenFormation` may form a frame that is not differentiated (module
    docstring): ``freeze`` on, no stage timing, and denoisers registered ``replayable``.

    Parameters
    ----------
    freeze : bool
        The option ``freeze``.
    denoisers : tuple of str
        The registered denoisers the frame runs (:func:`~foveated_mi.configure.denoisers_used`).
    timer : StageTimer
        The frame's stage timer (replay needs it disabled).

    Returns
    -------
    replayable : bool
        Whether the frame may be replayed.
    """
    return bool(freeze) and not timer.enabled and all(DENOISERS[d].replayable for d in denoisers)


def _fields(t) -> dict | None:
    return None if t is None else dict(t._asdict())


def _form_frame(arrays: dict, key: dict) -> dict:
    """The frozen body: rebuilds the frame's named buffers and forms the image."""
    h = arrays["history"]
    history = None if h is None else _reproject.History(
        mean=h["mean"], count=h["count"], moment2=h["moment2"], depth=None, camera=None,
        width=key["width"], height=key["height"], shown=h["shown"])
    inp = FormationInput(GBuffer(**arrays["gbuffer"]),
                         _reproject.ReprojectionMap(**arrays["reprojection"]), history,
                         key["width"], key["height"], key["spp"], arrays["fill_seed"],
                         arrays["emission_edges"], arrays["gaze"],
                         space_of(key["space"], arrays["space"]), key["disc_spp"],
                         arrays["kept"], key["keep"], key["moving"])
    fn = FORMATIONS[key["formation"]].fn
    formed = fn(ShadingBuffer(**arrays["shading"]), inp, key["settings"], StageTimer(False))
    # The image leaves the recording interleaved, as the frame returns it: the last pass
    # writes it so, with no copy after the replay (its planes are read lazily, if at all).
    # (The frame's outputs name the image "image" themselves.)
    buffers = {k: v for k, v in formed.buffers.items() if k != "image"}
    return {"buffers": buffers, "history": formed.history, "flat": dr.ravel(formed.image),
            "kept": formed.kept}


@contextmanager
def _no_collection():
    """Python's cyclic garbage collector held off while Dr.Jit may be recording.

    Dr.Jit 1.5 imports a NumPy array on the LLVM backend without a copy and frees it through
    ``jit_enqueue_host_func``, which a ``dr.freeze`` recording refuses by raising inside a
    callback that must not throw: ``RecordThreadState::enqueue_host_func(): this function
    cannot be recorded!``, then ``std::terminate``. Any such array in an unreachable cycle
    (a user's, a test's, an earlier frame's) is freed by whichever allocation triggers the
    collector, so a collection during a recording aborts the process. What becomes garbage
    meanwhile is collected after the call."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


class FrozenFormation:
    """A formation recorded once per configuration and replayed (module docstring)."""

    def __init__(self):
        # Every input opaque, so that no recording depends on an input's value: with
        # auto_opaque, Dr.Jit folds a literal input (a buffer of zeros) into the recording
        # and records again when that literal changes.
        self._frozen = dr.freeze(_form_frame, limit=RECORDINGS, warn_after=4 * RECORDINGS,
                                 auto_opaque=False)

    @property
    def recordings(self) -> int:
        """How many times the passes were traced and recorded so far."""
        return self._frozen.n_recordings

    def __call__(self, shading: ShadingBuffer, inp: FormationInput, fs: FormationSettings
                 ) -> Formed:
        h = inp.history
        arrays = {
            "shading": _fields(shading), "gbuffer": _fields(inp.gbuffer),
            "reprojection": _fields(inp.reprojection),
            "history": None if h is None else {"mean": h.mean, "count": h.count,
                                               "moment2": h.moment2, "shown": h.shown},
            "fill_seed": _sampling.opaque_seed(inp.fill_seed),
            "emission_edges": inp.emission_edges, "gaze": inp.gaze,
            "space": inp.space.arrays(), "kept": inp.kept,
        }
        key = {"formation": fs.name, "width": inp.width, "height": inp.height,
               "spp": inp.spp, "settings": fs.settings, "space": inp.space.key(),
               "disc_spp": inp.disc_spp, "keep": inp.keep, "moving": inp.moving}
        # Dr.Jit 1.5 took two keys that differed only in a host value after the settings
        # (nested dataclasses) for one recording: the whole key's hash, first, tells them
        # apart (tests/test_frozen_trace.py, a camera move's disc levels).
        key = {"hash": hash(tuple(key.values())), **key}
        with _no_collection():          # a collection inside a recording aborts (above)
            out = self._frozen(arrays, key)
        image = dr.unravel(mi.Color3f, out["flat"])
        return Formed(image, {**out["buffers"], "image": image}, out["history"], out["flat"],
                      out["kept"])
