"""Image formation: the passes after the trace, as one registered function of the shading buffer.

A *formation* turns a frame's sparse shading buffer into its image. It registers beside its
code, as ``mi.register_integrator`` does::

    register_formation("film", form_film)

and is chosen by the option ``formation``. It is called as ``fn(shading, inp, o, timer,
grad_pass)`` (``inp``: :class:`FormationInput`, ``o``: the options) and returns a
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
options as the formation reads them (its ``view``), and which buffers exist; the buffers, the history
and the fill's seed are inputs. A key not seen before records again (the most recent
``RECORDINGS`` are kept). The replay serves frames that are not differentiated, with stage
timing off (timing synchronises between passes) and a denoiser registered as ``replayable``
(OIDN runs on the host between kernels). Option ``freeze = false`` traces every frame.
"""
from __future__ import annotations

import gc
from contextlib import contextmanager
from typing import Any, Callable, NamedTuple

import drjit as dr
import mitsuba as mi

from ..kernels.grid import Grid
from ..postprocess import DENOISERS
from ..timing import StageTimer
from ..validate import check_choice
from . import reproject as _reproject
from . import sampling as _sampling
from ..kernels.buffers import GBuffer
from .shading import ShadingBuffer

#: Recorded configurations kept by a :class:`FrozenFormation` (least recently used dropped).
RECORDINGS = 8


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
    #: ``(pixels, on, rays)`` of the foveal buffer's samples when it keeps nothing on the
    #: film (:mod:`foveated_mi.frame.buffer_space`); the shading buffer, G-buffer,
    #: reprojection and history are then on the samples
    samples: tuple | None = None


class Formed(NamedTuple):
    """A formation's result."""
    image: mi.Color3f                     #: the frame's radiance, one value per film pixel
    buffers: dict[str, Any]               #: named buffers (flat arrays or None) on its grid
    history: dict[str, Any] | None        #: ``mean``, ``count``, ``moment2`` per film pixel
    #: (or per sample, where the plan is on samples)
    #: the image interleaved (RGB per pixel, as the frame returns it), where a replay wrote
    #: it so; ``image`` is then a lazy view of it
    flat: mi.Float | None = None


class Formation(NamedTuple):
    """A registered formation (see :func:`register_formation`)."""
    fn: Callable[..., Formed]
    grid: Callable[[int, int, dict], Grid]
    view: Callable[[int, int, dict], dict]
    stats: Callable[[dict], dict]
    counted: tuple[str, ...]
    on_film: tuple[str, ...]
    grids: Callable[[int, int, dict], dict]


#: Formation name -> :class:`Formation`, in registration order.
FORMATIONS: dict[str, Formation] = {}


def register_formation(name: str, fn: Callable[..., Formed], *,
                       grid: Callable[[int, int, dict], Grid] | None = None,
                       view: Callable[[int, int, dict], dict] | None = None,
                       stats: Callable[[dict], dict] | None = None,
                       counted: tuple[str, ...] = (), on_film: tuple[str, ...] = (),
                       grids: Callable[[int, int, dict], dict] | None = None) -> None:
    """Make ``fn`` the formation ``name`` (the option value ``formation = name``).

    ``grid(width, height, o)``: the grid of its buffers (default: the film's).
    ``view(width, height, o)``: the options as the formation reads them, host values only
    (default: all of them). It is all that ``fn`` receives as ``o``, and the frozen replay's
    key, so it holds exactly what decides the formation's kernels: a value left out of it
    cannot be read, and a value in it that changes every frame (the gaze) records again.
    ``stats(buffers)``: counters of the frame read from its buffers (device arrays, read
    when the stats are read); ``counted``: the buffers they count, evaluated together with
    the frame's other counted buffers (one launch). ``on_film``: the buffers it returns on
    the film's grid when its own grid is another (the image always is). ``grids(width,
    height, o)``: buffer name -> grid for those on a third grid, the plan's included (a
    formation whose plan keeps its G-buffer on its own samples)."""
    FORMATIONS[name] = Formation(
        fn, grid if grid is not None else (lambda width, height, o: Grid.film(width, height)),
        view if view is not None else (lambda width, height, o: dict(o)),
        stats if stats is not None else (lambda buffers: {}), tuple(counted), tuple(on_film),
        grids if grids is not None else (lambda width, height, o: {}))


def unregister_formation(name: str) -> None:
    """Remove the formation ``name`` (tests; a frame that uses it no longer validates)."""
    FORMATIONS.pop(name, None)


def form(shading: ShadingBuffer, inp: FormationInput, o: dict[str, Any], timer: StageTimer,
         grad_pass: bool = False) -> Formed:
    """The image of one frame by the formation of ``o["formation"]``, which sees the options
    through its ``view``."""
    check_choice("formation", o["formation"], FORMATIONS)
    entry = FORMATIONS[o["formation"]]
    return entry.fn(shading, inp, entry.view(inp.width, inp.height, o), timer, grad_pass)


def replayable(o: dict[str, Any], timer: StageTimer) -> bool:
    """Whether :class:`FrozenFormation` may form a frame that is not differentiated (module
    docstring)."""
    return bool(o["freeze"]) and not timer.enabled and DENOISERS[o["denoiser"]].replayable


def _fields(t) -> dict | None:
    return None if t is None else dict(t._asdict())


def _record(arrays: dict, key: dict) -> dict:
    """The frozen body: rebuilds the frame's named buffers and forms the image."""
    h = arrays["history"]
    history = None if h is None else _reproject.History(
        mean=h["mean"], count=h["count"], moment2=h["moment2"], depth=None, camera=None,
        width=key["width"], height=key["height"])
    inp = FormationInput(GBuffer(**arrays["gbuffer"]),
                         _reproject.ReprojectionMap(**arrays["reprojection"]), history,
                         key["width"], key["height"], key["spp"], arrays["fill_seed"],
                         arrays["emission_edges"], arrays["gaze"],
                         None if arrays["samples"] is None else tuple(arrays["samples"]))
    fn = FORMATIONS[key["formation"]].fn
    formed = fn(ShadingBuffer(**arrays["shading"]), inp, key["options"], StageTimer(False))
    # The image leaves the recording interleaved, as the frame returns it: the last pass
    # writes it so, with no copy after the replay (its planes are read lazily, if at all).
    # (The frame's outputs name the image "image" themselves.)
    buffers = {k: v for k, v in formed.buffers.items() if k != "image"}
    return {"buffers": buffers, "history": formed.history, "flat": dr.ravel(formed.image)}


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
        self._frozen = dr.freeze(_record, limit=RECORDINGS, warn_after=4 * RECORDINGS,
                                 auto_opaque=False)

    @property
    def recordings(self) -> int:
        """How many times the passes were traced and recorded so far."""
        return self._frozen.n_recordings

    def __call__(self, shading: ShadingBuffer, inp: FormationInput, o: dict[str, Any]
                 ) -> Formed:
        h = inp.history
        arrays = {
            "shading": _fields(shading), "gbuffer": _fields(inp.gbuffer),
            "reprojection": _fields(inp.reprojection),
            "history": None if h is None else {"mean": h.mean, "count": h.count,
                                               "moment2": h.moment2},
            "fill_seed": _sampling.opaque_seed(inp.fill_seed),
            "emission_edges": inp.emission_edges, "gaze": inp.gaze,
            "samples": None if inp.samples is None else list(inp.samples),
        }
        entry = FORMATIONS[o["formation"]]
        key = {"formation": o["formation"], "width": inp.width, "height": inp.height,
               "spp": inp.spp, "options": entry.view(inp.width, inp.height, o)}
        with _no_collection():          # a collection inside a recording aborts (above)
            out = self._frozen(arrays, key)
        image = dr.unravel(mi.Color3f, out["flat"])
        return Formed(image, {**out["buffers"], "image": image}, out["history"], out["flat"])
