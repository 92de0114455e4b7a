"""Kernels per frame: from frame 3 on a still or moving frame compiles nothing, launches the
same number of kernels every frame, and no more than the frame-time benchmark reports
(``benchmarks/bench_overhead.py``, README "Frame time": 27 / 30 for `paper` still / moving at
1024², 47 for `guided`; here `guided` also traces the light's edges: 43 / 48, and on a
moving camera its exclusive history reads add the one scatter that claims each previous
pixel, and the test of the sky around silhouettes one more: 50; ``vr`` 44 / 49 here, its
disc denoised as well as its cells, each by SVGF at 4 levels (36 / 41 at 2 levels, the
preset's before; 27 / 33 with ``foveal_disc = "resolved"``, as
``voxel-static-vr`` / ``voxel-moving-vr`` reported before): its replayed trace hands the
develop its samples in launches of their own)."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import apply_camera, camera_of, load_scene

#: The most JIT kernels one frame may launch, per preset (measured as in the docstring).
BUDGET = {"paper": 30, "guided": 50, "vr": 49}


@pytest.mark.parametrize("preset", ["paper", "guided", "vr"])
@pytest.mark.parametrize("moving", [False, True], ids=["still", "moving"])
def test_frames_launch_a_steady_budget_of_kernels(preset, moving):
    scene = load_scene("cornell-box", width=48, height=40, spp=1,
                       integrator={"type": "path", "max_depth": 3})
    integ = FoveatedIntegrator(preset=preset, nested=scene.integrator())
    cam = camera_of(scene)
    launched, compiled = [], []
    for k in range(6):
        if moving:
            cam = {**cam, "origin": [cam["origin"][0] + 0.02, *cam["origin"][1:]]}
            apply_camera(scene, cam)
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            np.array(mi.render(scene, integrator=integ, spp=1, seed=k))
            hist = dr.kernel_history([dr.KernelType.JIT])
        launched.append(len(hist))
        compiled.append(sum(1 for h in hist if not h.get("cache_hit", True)))
    steady = launched[3:]
    assert all(0 < n <= BUDGET[preset] for n in steady), launched
    assert len(set(steady)) == 1, launched
    assert compiled[3:] == [0, 0, 0], compiled
