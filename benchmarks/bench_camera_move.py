"""History after a camera move: PSNR of the frames after the move against a fresh first frame.

Mitsuba's Cornell box at SIZE², 1 spp per traced pixel, θ 0.1, σp 0.8, nested ``path``
(``max_depth`` 4). N frames of a still view, then the camera moves (:data:`MOVES`; by default
to ``look_at(origin=[0.9, 0.6, 2.2], target=[0, 0, 0])``, ``params.update()``) and four more
frames render. Each figure is PSNR against a converged render of the new view (REF_SPP), on
display values (:func:`foveated_mi.render.to_display`) and on linear values clipped to
[0, 1]. ``fresh`` is a new integrator's first frame of the new view with the same seed.

    python benchmarks/bench_camera_move.py --presets guided oidn --history 1 4 32 \
        --seeds 5 6 7 --out docs/results/camera_move.json
    python benchmarks/bench_camera_move.py ... --reprojection nearest \
        --out docs/results/camera_move_nearest.json

``--reprojection`` sets the option of that name (default: each preset's own).
"""
from __future__ import annotations

import functools
import sys

import numpy as np


import foveated_mi  # noqa: E402,F401  (a variant and the integrator on import)
import mitsuba as mi  # noqa: E402

from common import machine, md_table, parse_sets, parser, setup, write_json  # noqa: E402

#: The camera moves after the still frames: ``closer`` (the default: several pixels land in
#: one previous pixel), ``away`` (the box shrinks and the sky around it appears) and ``turn``.
MOVES = {
    "closer": dict(origin=[0.9, 0.6, 2.2], target=[0, 0, 0], up=[0, 1, 0]),
    "away": dict(origin=[0.3, 0.2, 5.5], target=[0, 0, 0], up=[0, 1, 0]),
    "turn": dict(origin=[0, 0, 3.9], target=[0.6, 0.3, 0], up=[0, 1, 0]),
}
AFTER = 4          # frames rendered after the move


def cornell(size: int):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=size, height=size)
    d["sensor"]["sampler"]["sample_count"] = 1
    d["integrator"] = {"type": "path", "max_depth": 4}
    return mi.load_dict(d)


@functools.lru_cache(maxsize=None)
def reference(size: int, spp: int, variant: str, move: str = "closer") -> np.ndarray:
    """The converged render of the moved view (cached per size, spp, variant and move)."""
    from foveated_mi.baselines import render_reference
    scene = cornell(size)
    params = mi.traverse(scene)
    params["sensor.to_world"] = mi.ScalarTransform4f().look_at(**MOVES[move])
    params.update()
    return render_reference(scene, spp=spp, seed=1234)


def psnr(img: np.ndarray, ref: np.ndarray) -> float:
    mse = float(np.mean((img - ref) ** 2))
    return float(10 * np.log10(1.0 / max(mse, 1e-20)))


def measures(img: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    from foveated_mi.render import to_display
    return {"display": psnr(to_display(img), to_display(ref)),
            "linear": psnr(np.clip(img, 0, 1), np.clip(ref, 0, 1))}


def camera_move(preset: str, still: int, seed: int, size: int = 64, ref_spp: int = 512,
                move: str = "closer", **options) -> dict:
    """One row: N = ``still`` still frames, the move, AFTER frames; fresh first frame."""
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    ref = reference(size, ref_spp, mi.variant(), move)
    opts = dict(preset=preset, theta=0.1, sigma_p=0.8, **options)

    def integrator():
        return FoveatedIntegrator(nested=mi.load_dict({"type": "path", "max_depth": 4}), **opts)

    scene = cornell(size)
    params = mi.traverse(scene)
    integ = integrator()
    for _ in range(still):
        np.array(mi.render(scene, integrator=integ, seed=seed))
    params["sensor.to_world"] = mi.ScalarTransform4f().look_at(**MOVES[move])
    params.update()
    after = [measures(np.array(mi.render(scene, integrator=integ, seed=seed)), ref)
             for _ in range(AFTER)]
    hit_rate = integ.stats["history_hit_rate"]
    fresh = measures(np.array(mi.render(scene, integrator=integrator(), seed=seed)), ref)
    row = {"preset": preset, "move": move, "still": still, "seed": seed, "size": size,
           "resolved_preset": integ.stats["preset"], "hit_rate_last": hit_rate}
    for m in ("display", "linear"):
        row[f"{m}_fresh"] = fresh[m]
        for k, a in enumerate(after):
            row[f"{m}_{k + 1}"] = a[m]
    return row


def main(argv=None) -> int:
    p = parser(__doc__)
    p.add_argument("--presets", nargs="+", default=["guided", "oidn"])
    p.add_argument("--history", nargs="+", type=int, default=[1, 4, 32])
    p.add_argument("--seeds", nargs="+", type=int, default=[5])
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--ref-spp", type=int, default=512)
    p.add_argument("--reprojection", choices=["exclusive", "nearest"])
    p.add_argument("--moves", nargs="+", default=["closer"], choices=list(MOVES))
    p.add_argument("--set", action="append", default=[], metavar="OPTION=VALUE",
                   help="an option of the foveated integrator for every row, over the "
                   "preset's (a Python literal, e.g. --set foveal_jitter=0.5); repeatable")
    a = p.parse_args(argv)
    setup(a)
    extra = {"reprojection": a.reprojection} if a.reprojection else {}
    extra.update(parse_sets(a.set))
    rows = [camera_move(pr, n, s, a.size, a.ref_spp, move=mv, **extra)
            for mv in a.moves for pr in a.presets for n in a.history for s in a.seeds]
    table = [[r["move"], r["preset"], r["still"], r["seed"], m, f"{r[f'{m}_1']:.2f}",
              " ".join(f"{r[f'{m}_{k}']:.2f}" for k in range(2, AFTER + 1)),
              f"{r[f'{m}_fresh']:.2f}", f"{r[f'{m}_1'] - r[f'{m}_fresh']:+.2f}",
              f"{r[f'{m}_3'] - r[f'{m}_fresh']:+.2f}"]
             for r in rows for m in ("display", "linear")]
    print(md_table(["move", "preset", "N", "seed", "measure", "first after the move",
                    "next frames", "fresh first frame", "first - fresh", "third - fresh"],
                   table))
    if a.out:
        write_json(a.out, {"machine": machine(), "reprojection": a.reprojection or "preset",
                           "options": extra, "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
