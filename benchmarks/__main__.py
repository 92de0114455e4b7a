"""Run a benchmark of the suite: ``python -m benchmarks NAME [its flags]``.

``python -m benchmarks --list`` lists the suite; ``python -m benchmarks NAME --help`` gives a
benchmark's flags. Every benchmark is a module of this folder with ``main(argv)``, listed in
:data:`SUITE`; each builds its command line with :func:`common.parser` (``--variant`` and
``--out``, shared), sets its variant with :func:`common.setup`, and writes its results
(``--out``) through :func:`common.write_json`, which adds the machine, its CPU model, the
commit, the date and the variant under ``run``. ``make bench`` runs the default set
(:data:`DEFAULT`).
"""
from __future__ import annotations

import importlib
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

#: name -> what it measures (one line; its module's docstring says more).
SUITE = {
    "bench_backward": "time and peak memory of one gradient step",
    "bench_camera_move": "history after a camera move against a fresh first frame",
    "bench_equal_time": "equal time: foveated presets against uniform path tracing",
    "bench_history_gain": "history gain of the paper preset on a still view",
    "bench_live_view": "the live view's frame rate and gaze latency",
    "bench_overhead": "what a foveated frame costs besides its rays, stage by stage",
    "bench_quality": "reconstruction quality against the full render",
    "bench_reconstruct": "reconstruction speed against the number of sites",
    "bench_reorder": "full render against each reorder mode",
    "bench_stereo_frame": "a headset's two eyes against one eye and uniform stereo",
    "bench_still_view": "a still view: the PSNR only rises while gaze and camera hold",
    "bench_temporal": "temporal reuse under a steady gaze",
    "fingerprint": "fingerprints of the product's output, to compare before and after",
    "long_run": "a small moving-gaze sequence for many frames",
    "peak_memory": "peak memory of one large frame",
    "suite_compile": "the kernels each test of a cold run compiles",
}
#: What ``make bench`` runs.
DEFAULT = ("bench_reorder", "bench_reconstruct", "bench_quality", "bench_temporal")


def run(name: str, argv: list[str]) -> int:
    """The benchmark ``name`` with its flags ``argv``; 2 (and one line) for a name not in
    :data:`SUITE`."""
    if name not in SUITE:
        sys.stderr.write(f"benchmarks: error: name = {name!r} is invalid: expected one of "
                         + ", ".join(SUITE) + " (python -m benchmarks --list)\n")
        return 2
    if HERE not in sys.path:        # the benchmarks import their shared helpers as ``common``
        sys.path.insert(0, HERE)
    return importlib.import_module(name).main(argv) or 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if argv else 2
    if argv[0] == "--list":
        width = max(map(len, SUITE))
        print("\n".join(f"{n:<{width}}  {what}" for n, what in SUITE.items()))
        return 0
    return run(argv[0], argv[1:])


if __name__ == "__main__":
    sys.exit(main())
