"""Garbage holding a NumPy-backed Dr.Jit array, left for Python's cyclic collector while
frames record their image formation (``dr.freeze``). Each frame is a new integrator, so each
records; the collector's threshold sweeps so that, without a guard, some collection lands
inside a recording, where Dr.Jit 1.5 aborts the process on freeing such an array.

Exit status 0 and the last line ``collections inside a recording: 0`` when the guard holds."""
import gc, sys
import numpy as np
import drjit as dr
import mitsuba as mi
import foveated_mi
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import load_scene
from foveated_mi.frame.formation import _form_frame
from foveated_mi.frame.trace import _trace_frame

# The frozen bodies, by their code objects: a rename fails the import, never this check.
RECORDED = (_form_frame.__code__, _trace_frame.__code__)

scene = load_scene("cornell-box", width=32, height=32, spp=1,
                   integrator={"type": "path", "max_depth": 2})
inside = []
def watch(phase, info):
    if phase == "start":
        f = sys._getframe(1)
        while f is not None:
            if f.f_code in RECORDED:
                inside.append(info["generation"]); break
            f = f.f_back
gc.callbacks.append(watch)
gc.disable()
for threshold in (25, 50, 100, 200, 400, 800, 1600, 3200, 6400, 12800):
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="paper")
    # Garbage the collector will find: a cycle holding an array that maps NumPy memory.
    cycle = [mi.Float(np.arange(16, dtype=np.float32))]
    cycle.append(cycle)
    del cycle
    gc.set_threshold(threshold, 1, 1)
    gc.enable()
    np.array(mi.render(scene, integrator=integ, seed=1))
    gc.disable()
    gc.collect()
print("collections inside a recording:", len(inside))
