"""A still view of the foveal buffer with no noise but the rays' places: what its cells
resolve over frames (the interleaved and the jittered cells' tests)."""
import drjit as dr
import mitsuba as mi
import numpy as np

from foveated_mi.frame import buffer_space
from foveated_mi.frame.foveal import SEAM
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import load_scene


class Albedo(mi.SamplingIntegrator):
    """The diffuse albedo at the primary hit (0 on a miss): no noise but the ray's place in
    its pixel, so that a still view's error is the cells' resolution alone."""

    def sample(self, scene, sampler, ray, medium=None, active=True):
        si = scene.ray_intersect(mi.Ray3f(ray), active)
        ok = si.is_valid() & active
        return dr.select(ok, mi.Spectrum(si.bsdf().eval_diffuse_reflectance(si, ok)), 0.0), \
            mi.Bool(True), []


def still_frames(frames: int, size=(128, 96), **options):
    """``frames`` frames of a still view of the eye chart, undenoised, their history
    uncapped: the images, each frame's rays, a 64-spp reference and the integrator."""
    scene = load_scene("eye-exam", width=size[0], height=size[1], spp=1)
    integ = FoveatedIntegrator(nested=Albedo(mi.Properties()), preset="vr", denoiser="none",
                               foveal_disc="resolved", max_history=0, **options)
    images, rays = [], []
    for k in range(frames):
        images.append(np.array(mi.render(scene, integrator=integ, seed=k)))
        rays.append(integ.stats["rays"])
    ref = np.array(mi.render(scene, integrator=Albedo(mi.Properties()), spp=64, seed=7))
    return images, rays, ref, integ


def periphery_mse(images, ref, integ) -> list[float]:
    """Each image's mean squared error outside the disc and its seam (gaze at the centre)."""
    W, H = ref.shape[1], ref.shape[0]
    r0 = buffer_space.layout(W, H, integ.options["theta"], integ.options["ray_budget"]).grid.fovea
    yy, xx = np.mgrid[0:H, 0:W]
    out = np.hypot(xx + 0.5 - W / 2, yy + 0.5 - H / 2) > r0 + SEAM
    return [float(np.mean((im[out] - ref[out]) ** 2)) for im in images]
