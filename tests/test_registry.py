"""A denoiser registered in one line is known to the options, the CLI, the docs, the gradient
pass and the frame, without other edits; unregistered, it is gone again."""
import mitsuba as mi
import numpy as np
import pytest

import gradcheck
import tolerances
from foveated_mi.options import parameter_table, validate_options
from foveated_mi.postprocess import DENOISERS, register_denoiser, unregister_denoiser
from foveated_mi.validate import ParameterError
from gradcheck import Probe


CALLS = []


def identity_stage(ctx):
    CALLS.append(ctx.grad_pass)
    return ctx.image


@pytest.fixture
def identity():
    CALLS.clear()
    register_denoiser("identity", identity_stage, differentiable=True)
    yield "identity"
    unregister_denoiser("identity")


def _denoiser_row(table: str) -> str:
    return table.split(" * - denoiser\n", 1)[1].split(" * - ", 1)[0]


def test_validation_accepts_it_and_lists_it(identity):
    assert validate_options({"denoiser": identity})["denoiser"] == identity
    with pytest.raises(ParameterError) as e:
        validate_options({"denoiser": "no-such-denoiser"})
    msg = str(e.value)
    assert "\n" not in msg and "'identity'" in msg and "'svgf'" in msg


def test_cli_parses_and_lists_it(identity, capsys):
    from foveated_mi.cli import build_parser, frame_options
    args = build_parser().parse_args(["render", "cornell-box", "--denoiser", identity])
    assert frame_options(args)["denoiser"] == identity
    with pytest.raises(SystemExit):
        build_parser().parse_args(["render", "--help"])
    help_text = capsys.readouterr().out
    assert "--denoiser" in help_text and identity in help_text


def test_parameter_table_lists_it(identity):
    assert identity in _denoiser_row(parameter_table())


def test_a_frame_with_it_equals_the_unfiltered_frame(identity):
    images = {}
    for name in ("none", identity):
        sc = gradcheck.scene("path", sigma_p=0.5, denoiser=name)
        images[name] = np.array(mi.render(sc, seed=3, spp=2))
        assert sc.integrator().stats["denoiser"] == name
    assert np.isfinite(images["none"]).all() and images["none"].max() > 0
    assert np.array_equal(images[identity], images["none"])
    assert CALLS == [False]          # called once, by the primal frame


def test_the_gradient_pass_runs_it_and_learns_its_differentiability(identity):
    grads = {}
    for name in ("none", identity):
        grads[name] = Probe(gradcheck.scene("prb", denoiser=name), "albedo").reverse(0, 4)
    assert grads["none"] != 0 and np.isfinite(grads["none"])
    assert grads[identity] == pytest.approx(grads["none"], rel=1e-5)
    # Once: the primal frame, rendered for gradients, forms its image with the gradient
    # pass's graph kept (grad_pass), and the gradient pass traverses that graph.
    assert CALLS == [True]
    # The same denoiser registered as not differentiable: the gradient pass refuses it.
    register_denoiser(identity, lambda ctx: ctx.image, differentiable=False)
    with pytest.raises(ParameterError, match="identity is not differentiable"):
        Probe(gradcheck.scene("prb", denoiser=identity), "albedo").reverse(0, 4)


def test_unregistered_it_is_gone():
    register_denoiser("identity", lambda ctx: ctx.image, differentiable=True)
    unregister_denoiser("identity")
    assert "identity" not in DENOISERS
    assert "identity" not in _denoiser_row(parameter_table())
    with pytest.raises(ParameterError, match="denoiser = 'identity' is invalid"):
        validate_options({"denoiser": "identity"})


# -- the domain a denoiser declares -------------------------------------------------------

def _frame(denoiser, **options):
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.scenes import load_scene
    scene = load_scene("cornell-box", width=24, height=20, spp=1,
                       integrator={"type": "path", "max_depth": 2})
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="paper", denoiser=denoiser,
                               **options)
    image = np.array(mi.render(scene, integrator=integ, seed=1))
    return integ, image


@pytest.mark.parametrize("domain", ["radiance", "irradiance", "display"])
def test_a_denoiser_gets_the_values_of_the_domain_it_declares(domain):
    from foveated_mi.frame.domain import to_display
    from foveated_mi.configure import domain_settings
    seen = []

    def keep(ctx):
        seen.append(np.array(ctx.image))
        return ctx.image
    register_denoiser("keep", keep, differentiable=True, domain=domain, materials=True)
    try:
        integ, image = _frame("keep", demodulate=True)
    finally:
        unregister_denoiser("keep")
    got = seen[0].T.reshape(image.shape)
    radiance = integ.buffer("interpolated")        # the reconstruction, albedo multiplied back
    o = integ.options
    if domain == "radiance":
        expect = np.minimum(radiance, o["clamp"])
    elif domain == "display":
        expect = np.array(to_display(mi.Color3f(np.minimum(radiance, o["clamp"]).reshape(-1, 3).T),
                                     domain_settings(o))).T.reshape(image.shape)
    else:
        # Irradiance: neither the albedo nor the clamp applied yet.
        assert not np.allclose(got, np.minimum(radiance, o["clamp"]))
        return
    # The same operations on the same values: the tone map, evaluated in another kernel, may
    # round its dozen operations differently (gamma_16 of the value).
    np.testing.assert_allclose(got, expect, rtol=tolerances.gamma(16), atol=0)
    if domain == "radiance":
        # An identity leaves the frame as the reconstruction made it.
        np.testing.assert_array_equal(image, np.minimum(radiance, o["clamp"]))


def test_an_inactive_denoiser_is_not_called():
    calls = []
    register_denoiser("idle", lambda ctx: calls.append(1) or ctx.image, differentiable=True,
                      domain="display", active=lambda o: False)
    try:
        integ, image = _frame("idle")
    finally:
        unregister_denoiser("idle")
    assert calls == [] and integ.buffer("tonemapped") is None
    np.testing.assert_array_equal(image, integ.buffer("interpolated"))


def test_an_unknown_domain_is_refused_in_one_line():
    with pytest.raises(ParameterError, match=r"domain = 'hdr' is invalid: expected one of "
                                             r"'radiance', 'irradiance', 'display'"):
        register_denoiser("bad", lambda ctx: ctx.image, differentiable=True, domain="hdr")
    assert "bad" not in DENOISERS
