"""Peak memory of one 2048x2048 frame (film sizes up to 2048^2 within 24 GB).

    python benchmarks/peak_memory.py --size 2048 2048 [--out FILE]

Prints the process's peak resident memory (ru_maxrss) after a foveated frame of voxel-city,
with every reconstruction stage on (discrete_sibson, the heaviest, with --reconstruction).
"""
from __future__ import annotations

import json
import resource
import sys
import time

import mitsuba as mi
import numpy as np

from common import parser, setup, write_json


def main(argv=None) -> int:
    p = parser(__doc__)
    p.add_argument("--size", type=int, nargs=2, default=(2048, 2048))
    p.add_argument("--reconstruction", default="sibson")
    a = p.parse_args(argv)
    setup(a)
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.scenes import load_scene
    W, H = a.size
    scene = load_scene("voxel-city", width=W, height=H, spp=1,
                       integrator={"type": "path", "max_depth": 3})
    integ = FoveatedIntegrator(preset="paper", nested=scene.integrator(),
                               reconstruction=a.reconstruction)
    t0 = time.perf_counter()
    img = np.array(mi.render(scene, integrator=integ))
    dt = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # KiB -> GiB
    out = {"size": [W, H], "reconstruction": a.reconstruction, "seconds": dt,
           "peak_rss_gib": peak, "finite": bool(np.isfinite(img).all()),
           "ray_fraction": integ.stats["ray_fraction"], "variant": mi.variant()}
    print(json.dumps(out, indent=2))
    write_json(a.out, out)
    return 0 if out["finite"] and peak < 24 else 1


if __name__ == "__main__":
    sys.exit(main())
