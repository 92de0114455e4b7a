"""Image formation: the passes after the trace, as one function of the shading buffer.

:func:`form_image` runs history resolve (Fig. 4), reconstruction (§3.4) and post-processing
(§3.5) on a frame's sparse shading buffer. Every weight in them comes from the G-buffer, the
sampling map or detached values, so the image is a fixed function of the traced values: the
gradient pass (:mod:`foveated_mi.frame.adjoint`) differentiates this same function.

**Frozen replay.** Python traces every kernel of these passes again each frame. On a GPU that
tracing costs more than the kernels run (``benchmarks/bench_overhead.py`` reports both: at
1024² on an H200 a ``paper`` frame's kernels ran 1.1 ms of its 6.6 ms,
``docs/results/cuda/run_c0cc6d7/overhead.json``). :class:`FrozenFormation`
records the passes once per configuration with ``dr.freeze`` and afterwards launches the
recorded kernels on the frame's buffers without tracing them. A recording is keyed on what
decides the kernels: the film size, ``spp``, the options these passes read, the Jump Flooding
bound (the sampling law's largest gap rounded up to a power of two, so a moving gaze rarely
changes it) and which buffers exist (a history, an albedo, emission edges). The gaze and θ
enter only through that bound, so they are not part of the key; the buffers, the history and
the fill's seed are inputs. A key not seen before records again (the most recent
``RECORDINGS`` are kept).

The replay serves frames that are not differentiated, with stage timing off (timing needs a
synchronisation between passes) and a denoiser registered as ``replayable`` (OIDN runs on the
host between kernels). Option ``freeze = false`` traces every frame.
"""
from __future__ import annotations

import gc
from contextlib import contextmanager
from typing import Any, NamedTuple

import drjit as dr
import mitsuba as mi

from ..postprocess import DENOISERS
from ..timing import StageTimer
from . import reproject as _reproject
from . import sampling as _sampling
from .gbuffer import GBuffer
from .post import post_pass
from .reconstruction import reconstruction_pass
from .shading import ShadingBuffer

#: Recorded configurations kept by a :class:`FrozenFormation` (least recently used dropped).
RECORDINGS = 8

#: Options these passes never read, or read only through the Jump Flooding bound: not part of
#: a recording's key (a new gaze must not record again). They are left out of the options the
#: recording sees, so a pass that read one would fail to record, not replay a stale value.
_NOT_KEYED = ("gaze", "theta", "timing", "map_seed", "reorder", "block_height", "edge_threshold",
              "edge_detector", "reprojection_tolerance", "reprojection", "freeze",
              "theta_deg", "sampling_law", "ray_budget", "acuity_floor")


class FormationInput(NamedTuple):
    """What the image formation reads of a frame besides its shading buffer."""
    gbuffer: GBuffer
    reprojection: _reproject.ReprojectionMap
    history: _reproject.History | None
    width: int
    height: int
    spp: int
    fill_seed: Any                        #: the stochastic fill's seed (int or mi.UInt32)
    emission_edges: mi.Bool | None = None


def jfa_bound(width: int, height: int, o: dict[str, Any]) -> int | None:
    """The longest Jump Flooding step a frame needs: the sampling law's largest gap between
    sites, rounded up to a power of two (what :func:`~foveated_mi.reconstruct.jump_flood`
    does with it anyway); None where the law bounds nothing."""
    if o["sampling_law"] == "acuity":
        gap = _sampling.gap_bound(width, height, o["acuity_floor"])
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


def form_image(shading: ShadingBuffer, inp: FormationInput, o: dict[str, Any],
               timer: StageTimer, grad_pass: bool = False, max_gap: Any = "law"
               ) -> tuple[mi.Color3f, dict[str, Any]]:
    """History resolve, reconstruction and post-processing of one frame: ``(image, buffers)``.

    ``shading.value`` holds the radiance estimate of each traced pixel; ``max_gap``: the Jump
    Flooding bound, ``"law"`` for :func:`jfa_bound` of the options (None: no bound)."""
    gb, width, height = inp.gbuffer, inp.width, inp.height
    if max_gap == "law":
        # No jump longer than the sampling law's largest gap (host scalars, no sync).
        max_gap = jfa_bound(width, height, o)
    if o["demodulate"] and inp.emission_edges is not None:
        # At an emitter's edge the emission seen at the pixel's centre is not its footprint's
        # (a partial cover of the light): subtracting it could leave negative irradiance,
        # which the reconstruction would spread. Such pixels are divided by the albedo only.
        gb = gb._replace(emission=dr.select(inp.emission_edges, 0.0, gb.emission))
    # History resolve (Fig. 4): this frame's samples blended with the reprojected history.
    resolved = _reproject.resolve(shading.value, shading.mask, inp.spp, inp.reprojection,
                                  inp.history, o["max_history"], shading.moment2)
    timer.mark("trace", resolved.shading, resolved.mask, resolved.count)
    # Reconstruction (§3.4): nearest sites, Voronoi fill and interpolation.
    recon = reconstruction_pass(resolved, gb, width, height, o, seed=inp.fill_seed,
                                emission_edges=inp.emission_edges, max_gap=max_gap)
    timer.mark("reconstruct", recon.nearest, recon.filled, recon.interpolated)
    # Post-processing (§3.5): the registered denoiser, the albedo multiplied back.
    post = post_pass(recon, resolved, gb, width, height, o, grad_pass)
    timer.mark("post", post.image)
    buffers = {"traced": shading.mask, "resolved": resolved, "nearest": recon.nearest,
               "filled": post.filled, "interpolated": post.interpolated,
               "tonemapped": post.tonemapped, "filtered": post.filtered,
               "variance": post.variance, "image": post.image}
    return post.image, buffers


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
                         arrays["emission_edges"])
    image, buffers = form_image(ShadingBuffer(**arrays["shading"]), inp, key["options"],
                                StageTimer(False), max_gap=key["jfa_bound"])
    buffers = dict(buffers, resolved=_fields(buffers["resolved"]))
    return {"image": image, "buffers": buffers}


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
    """:func:`form_image` recorded once per configuration and replayed (module docstring)."""

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
                 ) -> tuple[mi.Color3f, dict[str, Any]]:
        h = inp.history
        arrays = {
            "shading": _fields(shading), "gbuffer": _fields(inp.gbuffer),
            "reprojection": _fields(inp.reprojection),
            "history": None if h is None else {"mean": h.mean, "count": h.count,
                                               "moment2": h.moment2},
            "fill_seed": _sampling.opaque_seed(inp.fill_seed),
            "emission_edges": inp.emission_edges,
        }
        key = {"width": inp.width, "height": inp.height, "spp": inp.spp,
               "jfa_bound": jfa_bound(inp.width, inp.height, o),
               "options": {k: v for k, v in o.items() if k not in _NOT_KEYED}}
        with _no_collection():          # a collection inside a recording aborts (above)
            out = self._frozen(arrays, key)
        buffers = dict(out["buffers"])
        buffers["resolved"] = _reproject.Resolved(**buffers["resolved"])
        return out["image"], buffers
