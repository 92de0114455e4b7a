"""A uniform frame (every pixel traced, ``sigma_p = 1``) runs no reconstruction where the
method leaves a traced pixel its own value: the paper's interpolations, and the stochastic
fill of the ``oidn`` preset. Its image is the same, and it launches the kernels of a frame
without a fill (Jump Flooding and the fill's candidates cost a uniform frame nothing)."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.reconstruct import RECONSTRUCTIONS, Guide, jump_flood, reconstruct


def _scene(w=48, h=36):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=w, height=h)
    return mi.load_dict(d)


def test_the_stochastic_fill_keeps_every_traced_pixel():
    """What lets the pass skip it: with every pixel a site, its image is its input."""
    w, h = 24, 16
    rng = np.random.default_rng(2)
    c = rng.random((w * h, 3)).astype(np.float32)
    shading = mi.Color3f(*(mi.Float(c[:, i]) for i in range(3)))
    sites = dr.full(mi.Bool, True, w * h)
    normal = mi.Vector3f(0.0, 0.0, 1.0) + dr.zeros(mi.Vector3f, w * h)
    guide = Guide(normal=normal, position=dr.zeros(mi.Vector3f, w * h),
                  hit=dr.full(mi.Bool, True, w * h), weight=dr.ones(mi.Float, w * h))
    out = reconstruct("stochastic", shading, sites, jump_flood(sites, w, h), w, h,
                      guide=guide, seed=7)
    np.testing.assert_array_equal(np.array(dr.ravel(out)), np.array(dr.ravel(shading)))
    assert RECONSTRUCTIONS["stochastic"].keeps_sites
    assert not RECONSTRUCTIONS["guided"].keeps_sites      # it averages noisy sites
    assert all(m.keeps_sites for m in RECONSTRUCTIONS.values() if not m.guided)


def _frame_kernels(integ, scene, frames=4):
    """The last of ``frames`` frames' image, and the kernels it launched."""
    for k in range(frames - 1):
        mi.render(scene, integrator=integ, spp=1, seed=k)
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        img = mi.render(scene, integrator=integ, spp=1, seed=frames)
        dr.eval(img)
        n = len(dr.kernel_history([dr.KernelType.JIT]))
    return np.array(img), n


@pytest.mark.parametrize("history", [False, True])
def test_a_uniform_oidn_frame_runs_no_fill(history):
    scene = _scene()
    opts = dict(nested=scene.integrator(), preset="oidn", sigma_p=1.0, history=history,
                denoiser="none")
    fill, n_fill = _frame_kernels(FoveatedIntegrator(**opts), scene)
    plain, n_plain = _frame_kernels(FoveatedIntegrator(**opts, reconstruction="sibson"), scene)
    np.testing.assert_array_equal(fill, plain)
    assert n_fill == n_plain
    # A sparse frame of the same preset does fill: the kernels the uniform one does not run.
    sparse, n_sparse = _frame_kernels(FoveatedIntegrator(**{**opts, "sigma_p": 0.8}), scene)
    assert n_sparse > n_fill
