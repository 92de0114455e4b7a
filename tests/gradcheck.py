"""Helpers of the gradient tests: a scene, its parameters, estimates of one directional
derivative of a foveated image by central finite differences, reverse mode and forward mode.

The derivative checked is ``d/dt loss(image(pi + t v))`` at ``t = 0`` for a fixed random
pixel weighting ``loss = sum(weights * image)``, with the sampling map pinned
(``map_seed``) and history off, so that every render sees the same sampling map and sites.

:data:`OPTION_SETS` lists image-formation configurations; the generic tests run on each of
them. A stage added to a formation (:mod:`foveated_mi.frame.film`) should add its configurations
here.
"""
from __future__ import annotations

from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

#: Image-formation configurations (name, options) the generic gradient tests cover.
OPTION_SETS = [
    ("paper", {}),
    ("no_colour_weights", {"sigma_color": float("inf")}),
    ("strong_colour_weights", {"sigma_color": 0.1}),
    ("no_filter", {"atrous_iterations": 0}),
    ("voronoi", {"reconstruction": "voronoi"}),
    ("discrete_sibson", {"reconstruction": "discrete_sibson"}),
    ("fast_sibson", {"reconstruction": "fast_sibson"}),
    ("every_pixel", {"sigma_p": 1.0}),
    ("importance", {"pixel_filter": "importance"}),
    ("aces", {"tonemap": "aces", "exposure": 1.0}),
    ("guided_preset", {"preset": "guided"}),
    ("svgf", {"preset": "guided", "denoiser": "svgf"}),
    ("demodulate", {"demodulate": True}),
    ("stochastic", {"preset": "guided", "reconstruction": "stochastic", "denoiser": "svgf"}),
    ("svgf_every_pixel", {"preset": "guided", "denoiser": "svgf", "sigma_p": 1.0}),
    ("vr", {"preset": "vr"}),
    ("vr_atrous", {"preset": "vr", "denoiser": "atrous"}),
    ("vr_flat", {"preset": "vr", "sampling_law": "flat"}),
    ("flat", {"sampling_law": "flat", "ray_budget": 0.25}),
]

#: Variants of a formation in OPTION_SETS that change only weights or value domains: checked by
#: the dot-product test alone (the adjoint is the transpose), which the other tests' shared
#: code paths make enough.
TRANSPOSE_ONLY = [
    ("vr_demodulate", {"preset": "vr", "demodulate": True}),
    ("vr_joint", {"preset": "vr", "foveal_space": "film", "foveal_upsampling": "joint"}),
    ("vr_film", {"preset": "vr", "foveal_space": "film"}),
    ("vr_disc", {"preset": "vr", "foveal_disc": "denoised"}),
    ("vr_frame_ms", {"preset": "vr", "frame_ms": 40.0}),      # at the rung the budget chose
    ("vr_film_disc", {"preset": "vr", "foveal_space": "film", "foveal_disc": "denoised"}),
]

BALL_CENTRE = (0.3, -0.6, 0.3)
#: The ball's position on the film (normalised), where the translation tests look.
BALL_GAZE = (0.62, 0.73)


def scene(nested: str | dict, size: int = 32, rfilter: str = "gaussian", max_depth: int = 3,
          history: bool = False, map_seed: int = 11, **options) -> mi.Scene:
    """The Cornell box plus a blue ball (a separate shape, for visibility gradients)."""
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=size, height=size, rfilter={"type": rfilter})
    d["ball-bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.3, 0.7]}}
    d["ball"] = {"type": "sphere", "center": list(BALL_CENTRE), "radius": 0.35,
                 "bsdf": {"type": "ref", "id": "ball-bsdf"}}
    nest = dict(nested) if isinstance(nested, dict) else {"type": nested}
    nest.setdefault("max_depth", max_depth)
    # The paper's pipeline unless a case names a preset: the default preset may pick OIDN,
    # which a gradient pass leaves out.
    d["integrator"] = {"type": "foveated", "preset": "paper", "history": history,
                       "map_seed": map_seed, **options, "nested": nest}
    return mi.load_dict(d)


class Param(NamedTuple):
    key: str
    eps: float     #: finite-difference step


PARAMS = {
    "albedo": Param("red.reflectance.value", 0.05),          # interior gradient
    "emitter": Param("light.emitter.radiance.value", 1.0),   # the image is linear in it
    "translation": Param("ball.to_world", 0.02),             # visibility gradient (x axis)
}


class Probe:
    """Moves one parameter along a fixed direction: ``pi(t) = pi_0 + t v``."""

    def __init__(self, sc: mi.Scene, name: str, seed: int = 0):
        self.scene = sc
        self.params = mi.traverse(sc)
        self.param = PARAMS[name]
        value = self.params[self.param.key]
        self.base = type(value)(value)
        size = sc.sensors()[0].film().crop_size()
        rng = np.random.default_rng(seed)
        self.weights = mi.TensorXf(rng.random((size[1], size[0], 3)).astype(np.float32))

    def set(self, t) -> None:
        key = self.param.key
        if key.endswith("to_world"):
            m = mi.Matrix4f(self.base.matrix)
            m[0][3] = m[0][3] + t
            self.params[key] = mi.Transform4f(m)
        elif key.endswith("radiance.value"):
            self.params[key] = self.base + t
        else:
            self.params[key] = self.base + mi.Color3f(t, 0.0, 0.0)
        self.params.update()

    def loss(self, image) -> mi.Float:
        return dr.sum(dr.ravel(image * self.weights))

    def finite_difference(self, seed: int, spp: int, eps: float | None = None) -> float:
        """Central difference with common random numbers (the same seed on both sides)."""
        eps = self.param.eps if eps is None else eps
        out = []
        for s in (1.0, -1.0):
            self.set(mi.Float(s * eps))
            out.append(float(self.loss(mi.render(self.scene, self.params, seed=seed, spp=spp))[0]))
        self.set(mi.Float(0.0))
        return (out[0] - out[1]) / (2.0 * eps)

    def finite_difference_held(self, seed: int, spp: int, eps: float | None = None) -> float:
        """Central difference of the traced pixels' values (common random numbers), pushed
        through the image formation with every weight held at the primal frame's: the
        derivative the gradient pass computes, also where a weight depends on radiance
        (the à-trous colour weights)."""
        from foveated_mi.frame.adjoint import image_forward
        eps = self.param.eps if eps is None else eps
        integ = self.scene.integrator()
        values = []
        for s in (1.0, -1.0):
            self.set(mi.Float(s * eps))
            mi.render(self.scene, self.params, seed=seed, spp=spp)
            values.append(integ.formation()[1].value)
        self.set(mi.Float(0.0))
        mi.render(self.scene, self.params, seed=seed, spp=spp)
        form, shading = integ.formation()
        tangent = image_forward(form, shading.value, (values[0] - values[1]) / (2.0 * eps))
        return float(dr.sum(dr.ravel(tangent) * self.weights.array)[0])

    def reverse(self, seed: int, spp: int, integrator: mi.Integrator | None = None) -> float:
        """Reverse mode through ``mi.render`` (the scene's integrator, or ``integrator``)."""
        t = mi.Float(0.0)
        dr.enable_grad(t)
        self.set(t)
        image = mi.render(self.scene, self.params, seed=seed, spp=spp, integrator=integrator)
        dr.backward(self.loss(image))
        g = float(dr.grad(t)[0])
        self.set(mi.Float(0.0))
        return g

    def forward(self, seed: int, spp: int) -> float:
        t = mi.Float(0.0)
        dr.enable_grad(t)
        self.set(t)
        image = mi.render(self.scene, self.params, seed=seed, spp=spp)
        loss = self.loss(image)
        dr.forward(t)
        g = float(dr.grad(loss)[0])
        self.set(mi.Float(0.0))
        return g

    def pulled_back(self) -> mi.TensorXf:
        r"""The loss's weights pulled back through the last primal frame's image formation
        onto the film's pixels: :math:`\delta S = J_F^{\mathsf T} w`, zero at untraced pixels.
        The foveated image's derivative along :math:`v` is :math:`\sum_p \delta S(p)\,
        \partial S(p)/\partial\pi` (:mod:`foveated_mi.frame.adjoint`), so Mitsuba's own
        ``render_backward`` with this image as ``grad_in`` estimates the same derivative."""
        from foveated_mi.frame.adjoint import image_backward
        integ = self.scene.integrator()
        form, shading = integ.formation()
        w = dr.unravel(mi.Color3f, self.weights.array)
        delta = integ._primal.plan.space.to_pixels(image_backward(form, shading.value, w),
                                                   shading.mask)
        return mi.TensorXf(dr.ravel(delta), shape=self.weights.shape)

    def direct(self, integrator: mi.Integrator, grad_in: mi.TensorXf, seed: int, spp: int,
               mode: str = "reverse") -> float:
        """``integrator``'s own ``render_backward`` (``grad_in`` dotted with its gradient) or
        ``render_forward`` (its tangent dotted with ``grad_in``) on the scene's sensor, with the
        seed that ``mi.render(seed=seed)`` hands its gradient pass."""
        seed_grad = mi.sample_tea_32(seed, 1)[0]
        t = mi.Float(0.0)
        dr.enable_grad(t)
        self.set(t)
        if mode == "reverse":
            integrator.render_backward(self.scene, self.params, grad_in, 0, seed_grad, spp)
            g = float(dr.grad(t)[0])
        else:
            # The tangent carried onto the scene's parameters first: the integrator
            # propagates from them inside an isolated scope.
            dr.forward_from(t, dr.ADFlag.ClearEdges)
            tangent = integrator.render_forward(self.scene, self.params, 0, seed_grad, spp)
            g = float(dr.sum(dr.ravel(tangent) * grad_in.array)[0])
        self.set(mi.Float(0.0))
        return g


def mitsuba_integrator(nested: str, max_depth: int = 3, **attributes) -> mi.Integrator:
    """Mitsuba's own ``nested`` integrator, as :func:`scene` nests it (same ``max_depth``),
    with ``attributes`` set on it (a projective integrator's guiding settings)."""
    integ = mi.load_dict({"type": nested, "max_depth": max_depth})
    for k, v in attributes.items():
        setattr(integ, k, v)
    return integ


def rounding_allowance(terms: int, *values: float) -> float:
    """What float32 rounding alone may put between two evaluations of one sum of ``terms``
    contributions taken in different orders (atomic scatter-adds): Higham's bound, ``terms``
    times the unit roundoff times the sum of the contributions' magnitudes. That sum is not
    known; the largest of ``values`` stands for it. The bound being a worst case (rounding
    errors add up as a random walk, ``sqrt(terms)``), it still lies far above what rounding
    does, and far below what a wrong term does (a fraction of the value)."""
    return terms * 2.0 ** -24 * max(abs(v) for v in values)


def agreement(rev, fd) -> tuple[bool, str]:
    """The issue's criterion: mean reverse-mode estimate within 2 % of the mean finite
    difference, or within 3 standard errors (of the difference of the two means, each
    estimated from its repeats with different seeds). A standard error above 25 % of the
    value makes the check fail: it would then accept anything."""
    rev, fd = np.asarray(rev, float), np.asarray(fd, float)
    se = np.sqrt(rev.var(ddof=1) / rev.size + fd.var(ddof=1) / fd.size)
    diff = rev.mean() - fd.mean()
    ok = abs(diff) <= max(0.02 * abs(fd.mean()), 3.0 * se) and se <= 0.25 * abs(fd.mean())
    msg = (f"reverse {rev.mean():.5g} vs FD {fd.mean():.5g}: {diff / fd.mean() * 100:+.2f} %, "
           f"{abs(diff) / se if se > 0 else float('inf'):.2f} SE (SE {se / abs(fd.mean()) * 100:.2f} %)")
    return bool(ok), msg


def forward_and_reverse(fn, x0: np.ndarray, dx: np.ndarray, g: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """``(J dx, J^T g)`` of a map ``fn`` of one ``mi.Color3f`` at ``x0`` (each a (3, n)
    array): forward mode from tangent ``dx``, reverse mode from the loss ``<fn(x), g>``, for
    a dot-product test of a linear step (``tolerances.transpose_bound``)."""
    x = mi.Color3f(x0)
    dr.enable_grad(x)
    y = fn(x)
    dr.set_grad(x, mi.Color3f(dx))
    dr.forward_to(y)
    jdx = np.array(dr.grad(y))
    x = mi.Color3f(x0)
    dr.enable_grad(x)
    dr.backward_from(fn(x) * mi.Color3f(g))
    return jdx, np.array(dr.grad(x))
