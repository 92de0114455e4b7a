"""What a study's uniform + history row costs: its frame against the full render, in one run.

The frame of the VR study at 8.4 pixels per degree (voxel-city 1152x648 across 100°, path
``max_depth`` 8, the camera turning 1/3° a frame): the ``foveated`` integrator with the
options of a study's uniform + history row (``sigma_p = 1``: every pixel traced, history on,
no denoiser; ``--preset``'s reconstruction and history, ``oidn`` as the VR studies name it),
at each ``--spp``, beside the nested integrator's full render of the same frame. Both are
forced inside their timed region (``dr.eval`` + ``dr.sync_thread``); medians over the frames
after ``--warmup``. ``reconstruct ms`` is the stage's time on a twin integrator with stage
timing on.

    python research/bench_uniform_history.py --out docs/results/uniform_history/after_1.json
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
# The head's orbit is the benchmark's (benchmarks/bench_overhead.py).
sys.path.append(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "benchmarks"))

import foveated_mi  # noqa: E402,F401
import mitsuba as mi  # noqa: E402

from bench_overhead import _orbit  # noqa: E402
from common import machine, md_table, median, timed, write_json  # noqa: E402
from foveated_mi.integrators.foveated import FoveatedIntegrator  # noqa: E402
from foveated_mi.scenes import apply_camera, camera_of, load_scene  # noqa: E402


def run(preset: str, spp: int, size: tuple[int, int], frames: int, warmup: int) -> dict:
    scene = load_scene("voxel-city", width=size[0], height=size[1], spp=spp,
                       integrator={"type": "path", "max_depth": 8})
    camera = dict(camera_of(scene), fov=100.0)
    apply_camera(scene, camera)
    nested = scene.integrator()
    opts = dict(preset=preset, nested=nested, sigma_p=1.0, history=True, denoiser="none")
    row, stage_timed = FoveatedIntegrator(**opts), FoveatedIntegrator(**opts, timing=True)
    full, frame, recon = [], [], []
    for k in range(warmup + frames):
        camera = _orbit(camera, 1.0 / 3.0)
        apply_camera(scene, camera)
        # Each render forced inside its timed region (mi.render returns lazily).
        t_full = timed(mi.render, scene, integrator=nested, spp=spp, seed=k)[1]
        t_row = timed(mi.render, scene, integrator=row, spp=spp, seed=k)[1]
        timed(mi.render, scene, integrator=stage_timed, spp=spp, seed=k)
        if k >= warmup:
            full.append(t_full)
            frame.append(t_row)
            recon.append(stage_timed.stats["timings_ms"].get("reconstruct", 0.0))
    return {"preset": preset, "spp": spp, "size": list(size), "full_ms": median(full),
            "frame_ms": median(frame), "x_full": median(frame) / median(full),
            "reconstruct_ms": median(recon), "frames": frames}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--preset", default="oidn")
    ap.add_argument("--spp", type=int, nargs="+", default=[1, 2, 4])
    ap.add_argument("--size", type=int, nargs=2, default=[1152, 648])
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    rows = [run(a.preset, s, tuple(a.size), a.frames, a.warmup) for s in a.spp]
    print(md_table(["preset", "spp", "full ms", "uniform + history ms", "x full",
                    "reconstruct ms"],
                   [[r["preset"], r["spp"], f"{r['full_ms']:.1f}", f"{r['frame_ms']:.1f}",
                     f"{r['x_full']:.3f}", f"{r['reconstruct_ms']:.1f}"] for r in rows]))
    write_json(a.out, {"machine": machine(), "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
