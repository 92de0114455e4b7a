"""The ``vr`` preset: rays at the cells of a log-polar buffer, denoising there, one warp.

Its ray count meets the budget, a moving gaze compiles nothing, a budget of the whole film
converges to the full render, the fovea shows its own traced pixels, any gaze and aspect ratio
covers the film, and a bad combination gets one line."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from kernel_counts import compiled_by
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError


def _scene(size=(64, 48), spp=1, integrator=None):
    return load_scene("cornell-box", width=size[0], height=size[1], spp=spp,
                      integrator=integrator or {"type": "path", "max_depth": 3})


@pytest.mark.parametrize("budget", [0.1, 0.25])
@pytest.mark.parametrize("size", [(96, 64), (160, 90)])
def test_the_ray_count_meets_the_budget(budget, size):
    scene = _scene(size)
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", ray_budget=budget)
    mi.render(scene, integrator=integ, seed=0)
    # The buffer is sized on the traced pixels with the gaze at the film's centre; the count
    # moves by a column of cells: 2 % of the budget, or one column on the smallest film.
    rays = integ.stats["rays"]
    grid_rings = integ.buffer("cells").shape[0]
    target = budget * size[0] * size[1]
    assert abs(rays - target) <= max(0.02 * target, grid_rings), (rays, target)


def test_a_moving_gaze_compiles_nothing_from_frame_3():
    scene = _scene()
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr")
    compiled = []
    for k in range(6):
        integ.gaze = (0.3 + 0.07 * k, 0.6 - 0.05 * k)
        compiled.append(compiled_by(lambda: np.array(mi.render(scene, integrator=integ,
                                                               seed=k))))
    assert compiled[3:] == [0, 0, 0], compiled


def test_the_whole_film_as_budget_is_the_frame_that_traces_every_pixel():
    # Every pixel traced: the fovea covers the film and shows its own pixels, the very
    # samples of the film formation tracing every pixel with the same launch and seed.
    scene = _scene((48, 40), spp=2)
    same = dict(denoiser="none", history=False, pixel_filter="importance", reorder="compact",
                edge_threshold=0.0)
    # theta = 2: the full-resolution disc covers the whole film.
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", ray_budget=1.0,
                               theta=2.0, **same)
    image = np.array(mi.render(scene, integrator=integ, spp=2, seed=4))
    assert integ.stats["ray_fraction"] == 1.0
    every = FoveatedIntegrator(nested=scene.integrator(), preset="paper", sigma_p=1.0, **same)
    plain = np.array(mi.render(scene, integrator=every, spp=2, seed=4))
    np.testing.assert_array_equal(image, plain)


def test_a_budget_beyond_the_finest_cells_gets_them_and_one_warning():
    """The whole film as budget with the preset's disc: no log-polar buffer reaches it short
    of cells a tiny fraction of a pixel (89 million of them at 1152x648), so the buffer stops
    at cells of MIN_PITCH at the disc's edge, one warning names the budget and what the frame
    traces, and the frame traces that."""
    import re
    import warnings
    from foveated_mi.frame import buffer_space, cells
    cells.foveal_grid.cache_clear()          # it warns once per film, budget and disc
    scene = _scene((64, 48), spp=1)
    with pytest.warns(UserWarning, match=r"ray_budget = 1\.0 is above the 0\.\d+ of the film") \
            as caught:
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", ray_budget=1.0)
        image = np.array(mi.render(scene, integrator=integ, seed=1))
    said = [str(w.message) for w in caught if "is above the" in str(w.message)]
    assert len(said) == 1, said
    reach = float(re.search(r"traces ([0-9.]+) of it", said[0]).group(1))
    lay = buffer_space.layout(64, 48, integ.options["theta"], 1.0)
    assert lay.grid.pitch == cells.MIN_PITCH
    # Sized on the host in float64, placed on the device in float32 (as the budget's test).
    assert 0.5 < reach < 1.0
    assert integ.stats["ray_fraction"] == pytest.approx(reach, rel=0.02)
    assert np.isfinite(image).all()
    with warnings.catch_warnings():
        warnings.simplefilter("error")             # once: the next frame says nothing
        mi.render(scene, integrator=integ, seed=2)


def test_the_error_falls_as_the_budget_rises():
    scene = _scene((64, 48), spp=4)
    ref = np.array(mi.render(scene, integrator=scene.integrator(), spp=256, seed=9))
    err = []
    for budget in (0.1, 0.3, 0.7):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", ray_budget=budget,
                                   history=False)
        image = np.array(mi.render(scene, integrator=integ, spp=4, seed=1))
        err.append(float(np.mean((image - ref) ** 2)))
    assert err[0] > err[1] > err[2], err


@pytest.mark.parametrize("gaze", [(0.5, 0.5), (0.0, 0.0), (0.97, 0.99)])
@pytest.mark.parametrize("size", [(64, 48), (40, 90)])
def test_every_pixel_gets_a_value_at_any_gaze_and_aspect(gaze, size):
    scene = _scene(size, spp=2)
    plain = np.array(mi.render(scene, integrator=scene.integrator(), spp=64, seed=1))
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", gaze=gaze)
    image = np.array(mi.render(scene, integrator=integ, spp=2, seed=3))
    assert np.isfinite(image).all()
    # Wherever the scene shows something, the frame does: a pixel left black there is one
    # the warp did not reach.
    lit = plain.sum(-1) > 1e-3
    assert lit.mean() > 0.3
    assert (image.sum(-1)[lit] > 0).mean() > 0.99


def test_the_fovea_shows_its_own_traced_pixels():
    scene = _scene((64, 48), spp=2)
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", history=False,
                               foveal_space="film", foveal_disc="resolved")
    image = np.array(mi.render(scene, integrator=integ, seed=5))
    shading = integ.buffer("shading")
    yy, xx = np.mgrid[0:48, 0:64]
    from foveated_mi.frame.foveal import SEAM
    from foveated_mi.frame.cells import foveal_grid, fovea_radius
    grid = foveal_grid(64, 48, integ.options["ray_budget"],
                       fovea_radius(64, 48, integ.options["theta"]))
    assert grid.fovea == fovea_radius(64, 48, integ.options["theta"])
    r = np.hypot(xx + 0.5 - 32, yy + 0.5 - 24)
    inner = r <= grid.fovea - SEAM
    assert inner.sum() > 10
    np.testing.assert_array_equal(image[inner], shading[inner])
    # Kept on the buffer's samples, the disc shows the same traced values: its own samples.
    in_buffer = FoveatedIntegrator(nested=scene.integrator(), preset="vr", history=False,
                                   foveal_disc="resolved")
    assert in_buffer.options["foveal_space"] == "buffer"
    same = np.array(mi.render(scene, integrator=in_buffer, seed=5))
    np.testing.assert_array_equal(same[inner], shading[inner])
    assert not np.array_equal(same[~inner], image[~inner])    # the cells differ outside


@pytest.mark.parametrize("space", ["buffer", "film"])
def test_the_buffer_and_its_grid_are_exported(space):
    scene = _scene((64, 48))
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", foveal_space=space)
    mi.render(scene, integrator=integ, seed=0)
    cells = integ.buffer("cells")
    assert cells.ndim == 3 and cells.shape[2] == 3 and cells.shape[:2] != (48, 64)
    assert integ.buffer("cell_mask").shape == cells.shape[:2]
    assert integ.stats["formation"] == "foveal" and integ.stats["sampling_law"] == "polar"
    if space == "film":
        assert integ.buffer("shading").shape == (48, 64, 3)
        return
    # On the samples: the cells, then the disc's square patch, each at its film pixel.
    from foveated_mi.frame.buffer_space import layout
    lay = layout(64, 48, integ.options["theta"], integ.options["ray_budget"])
    assert cells.shape[:2] == (lay.grid.height, lay.grid.width)
    assert integ.buffer("shading").shape == (1, lay.size, 3)
    pixel, on = integ.buffer("sample_pixel")[0], integ.buffer("sample_on")[0].astype(bool)
    # The shading buffer is on the samples too: every sample on the film holds its traced
    # value, and no sample off it does.
    traced = integ.buffer("traced")[0].astype(bool)
    assert traced.shape == (lay.size,) and (traced == on).all()
    # The launch traced exactly the samples' pixels.
    launched = integ.buffer("sampling_map").astype(bool).ravel()
    assert launched.shape == (64 * 48,)
    assert set(np.flatnonzero(launched)) == set(pixel[on].tolist())


def _ref_at(ref, integ, space):
    """The reference at what holds history: the traced pixels, or the samples on the film."""
    if space == "film":
        traced = integ.buffer("traced").astype(bool)
        return integ.buffer("shading")[traced], ref[traced], integ.buffer("history_count")[traced]
    on = integ.buffer("sample_on")[0].astype(bool)
    pixel = integ.buffer("sample_pixel")[0][on]
    return (integ.buffer("shading")[0][on], ref.reshape(-1, 3)[pixel],
            integ.buffer("history_count")[0][on])


@pytest.mark.parametrize("space", ["buffer", "film"])
def test_a_still_view_accumulates_history_in_the_traced_pixels(space):
    scene = _scene((64, 48), spp=1)
    ref = np.array(mi.render(scene, integrator=scene.integrator(), spp=512, seed=9))
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", denoiser="none",
                               foveal_space=space)
    err, rates = [], []
    for k in range(8):
        mi.render(scene, integrator=integ, spp=1, seed=k)
        mine, theirs, count = _ref_at(ref, integ, space)
        err.append(float(np.mean((mine - theirs) ** 2)))
        rates.append(integ.stats["history_hit_rate"])
    # The traced pixels' Monte Carlo error falls as samples accumulate (8 frames: about 1/8).
    assert err[-1] < 0.4 * err[0], err
    # A still gaze traces the same pixels every frame: each holds all 8 frames' samples.
    assert count.min() == 8.0
    if space == "buffer":
        # From the second frame every sample on the film finds its history: the rate is a
        # share of the samples reprojected, not of the film's pixels.
        s = integ.stats
        assert rates[0] == 0.0 and set(rates[1:]) == {1.0}, rates
        assert s["history_hits"] == s["reprojected"] < s["pixels"]


@pytest.mark.parametrize("bad,match", [
    ({"formation": "foveal", "sampling_law": "kwon"},
     r"sampling_law = 'kwon' is invalid: expected 'polar' or 'flat' with formation = 'foveal'"),
    ({"preset": "vr", "tonemap_samples": True},
     r"tonemap_samples = True is invalid: expected False with formation = 'foveal'"),
    ({"preset": "vr", "ray_budget": 0.0}, r"ray_budget = 0\.0 is invalid"),
    ({"preset": "vr", "sigma_luminance_moving": -1.0},
     r"sigma_luminance_moving = -1\.0 is invalid: expected a finite number >= 0"),
    ({"preset": "vr", "max_history_moving": 0.5},
     r"max_history_moving = 0\.5 is invalid: expected 0 \(as still\) or a number in \[1, 1e9\]"),
])
def test_bad_combinations_get_one_line(bad, match):
    with pytest.raises(ParameterError, match=match) as e:
        FoveatedIntegrator(**bad)
    assert "\n" not in str(e.value)


def test_a_disc_larger_than_the_budget_is_traced_whole_with_a_warning():
    scene = _scene((64, 48))
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", theta=0.5,
                               ray_budget=0.1)
    with pytest.warns(UserWarning, match=r"ray_budget = 0\.1 is below the 0\.\d+ of the film "
                                         r"that the full-resolution disc \(theta\) traces"):
        image = np.array(mi.render(scene, integrator=integ, seed=0))
    assert np.isfinite(image).all()
    # The disc (θ = 0.5 of half the diagonal: 20 px) and a few coarse cells: above the budget.
    assert integ.stats["ray_fraction"] > 0.3


def test_the_joint_warp_is_bilinear_on_one_surface_and_stops_at_an_edge():
    from foveated_mi.frame.foveal import warp
    from foveated_mi.kernels.polar import polar_grid_of
    from foveated_mi.kernels.taps import Surface
    W, H = 32, 24
    grid = polar_grid_of(W, H, 3.0, 2.0)
    gaze = mi.Point2f(W / 2, H / 2)
    rng = np.random.default_rng(0)
    cells = mi.Color3f(*(mi.Float(rng.random(grid.size).astype(np.float32)) for _ in range(3)))
    valid = dr.full(mi.Bool, True, grid.size)
    plane = lambda n: Surface.of(mi.Vector3f(0, 0, 1) + dr.zeros(mi.Vector3f, n),  # noqa: E731
                                 dr.zeros(mi.Vector3f, n), dr.full(mi.Bool, True, n))
    bilinear = np.array(warp(cells, valid, grid, gaze, W, H))
    joint = np.array(warp(cells, valid, grid, gaze, W, H, (plane(W * H), plane(grid.size))))
    # One surface everywhere: every edge-stopping weight is exp(0) = 1.
    np.testing.assert_array_equal(joint, bilinear)
    # Cells on the sky lend nothing to a pixel on a surface (where a surface cell is near).
    on = rng.random(grid.size) < 0.5
    sky = Surface.of(mi.Vector3f(0, 0, 1) + dr.zeros(mi.Vector3f, grid.size),
                     dr.zeros(mi.Vector3f, grid.size), mi.Bool(on))
    mixed = np.array(warp(cells, valid, grid, gaze, W, H, (plane(W * H), sky)))
    assert np.isfinite(mixed).all() and not np.array_equal(mixed, bilinear)
    # Every pixel's value is then a convex mix of the surface cells alone, where it has one.
    only = np.array(warp(dr.select(mi.Bool(on), cells, 0.0), mi.Bool(on), grid, gaze, W, H))
    near = np.array(warp(mi.Color3f(1.0) + dr.zeros(mi.Color3f, grid.size), mi.Bool(on), grid,
                         gaze, W, H))[0] > 0
    # Four weighted terms, their sum and a division, in float32 (values below 1).
    np.testing.assert_allclose(mixed[:, near], only[:, near], rtol=0, atol=tolerances.gamma(8))


def _disc_masks(integ, W, H, margin):
    """Film pixels well inside the disc (the seam's blend excluded) and well outside it."""
    from foveated_mi.frame.foveal import SEAM
    from foveated_mi.frame.buffer_space import layout
    r0 = layout(W, H, integ.options["theta"], integ.options["ray_budget"]).grid.fovea
    yy, xx = np.mgrid[0:H, 0:W]
    r = np.hypot(xx + 0.5 - W / 2, yy + 0.5 - H / 2)
    return r <= r0 - SEAM, r > r0 + margin


@pytest.mark.parametrize("space", ["buffer", "film"])
def test_a_denoised_disc_changes_the_disc_only_and_brings_it_nearer_the_reference(space):
    W, H = 64, 48
    scene = _scene((W, H), spp=1)
    ref = np.array(mi.render(scene, integrator=scene.integrator(), spp=1024, seed=99))
    images, err = {}, {}
    for disc in ("resolved", "denoised"):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", history=False,
                                   foveal_space=space, foveal_disc=disc)
        frames = [np.array(mi.render(scene, integrator=integ, spp=1, seed=s)) for s in range(4)]
        inner, outer = _disc_masks(integ, W, H, 1.0)
        images[disc] = frames
        err[disc] = np.mean([np.mean((f[inner] - ref[inner]) ** 2) for f in frames])
    assert inner.sum() > 20 and outer.sum() > 1000
    # Outside the disc nothing changes: the same rays, the same cells, the same warp.
    for a, b in zip(images["resolved"], images["denoised"]):
        np.testing.assert_array_equal(a[outer], b[outer])
    # Inside it, SVGF on the disc's 1-spp pixels: the 1-spp noise (about all of the
    # resolved disc's error) falls by far more than the filter's bias adds.
    assert err["denoised"] < 0.7 * err["resolved"], err


@pytest.mark.parametrize("space", ["buffer", "film"])
def test_a_disc_without_a_denoiser_shows_its_resolved_pixels(space):
    W, H = 64, 48
    scene = _scene((W, H), spp=2)
    out = []
    for disc in ("resolved", "denoised"):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", denoiser="none",
                                   foveal_space=space, foveal_disc=disc)
        out.append([np.array(mi.render(scene, integrator=integ, seed=s)) for s in range(2)])
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)


def test_oidn_denoises_the_disc_as_a_plain_image():
    from foveated_mi.denoise import oidn_available
    if not oidn_available():
        pytest.skip("pyoidn not installed")
    W, H = 96, 64
    scene = _scene((W, H), spp=1)
    images = {}
    for disc in ("resolved", "denoised"):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", denoiser="oidn",
                                   history=False, foveal_disc=disc)
        images[disc] = np.array(mi.render(scene, integrator=integ, seed=3))
    inner, outer = _disc_masks(integ, W, H, 1.0)
    assert np.isfinite(images["denoised"]).all()
    np.testing.assert_array_equal(images["resolved"][outer], images["denoised"][outer])
    assert not np.allclose(images["resolved"][inner], images["denoised"][inner])


def test_the_disc_s_own_filter_changes_the_disc_only():
    # The disc's levels apart from the cells': 0 shows its resolved pixels, the cells'
    # own levels the preset's frame; anything else changes the disc and nothing outside it.
    W, H = 64, 48
    scene = _scene((W, H), spp=1)

    def frames(**o):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", history=False, **o)
        return integ, [np.array(mi.render(scene, integrator=integ, seed=s)) for s in range(2)]

    integ, default = frames()
    levels = integ.options["atrous_iterations"]
    assert levels > 1 and integ.options["foveal_disc_iterations"] == -1
    for a, b in zip(default, frames(foveal_disc_iterations=levels)[1]):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(frames(foveal_disc="resolved")[1], frames(foveal_disc_iterations=0)[1]):
        np.testing.assert_array_equal(a, b)
    inner, outer = _disc_masks(integ, W, H, 1.0)
    for o in ({"foveal_disc_iterations": 1}, {"foveal_disc_sigma_luminance": 1.0}):
        for a, b in zip(default, frames(**o)[1]):
            np.testing.assert_array_equal(a[outer], b[outer])
            assert not np.array_equal(a[inner], b[inner]), o


def _turning_frames(scene, turn: float, n: int = 3, **options):
    """``n`` frames of a view whose camera turns by ``turn`` degrees a frame about the scene
    (0: a still camera, set once), and its integrator."""
    params = mi.traverse(scene)
    integ = FoveatedIntegrator(nested=scene.integrator(), **options)
    out = []
    for k in range(n):
        if k == 0 or turn:
            a = np.radians(turn * k)
            params["sensor.to_world"] = mi.ScalarTransform4f().look_at(
                origin=[3.9 * np.sin(a), 0.0, 3.9 * np.cos(a)], target=[0, 0, 0],
                up=[0, 1, 0])
            params.update()
        out.append(np.array(mi.render(scene, integrator=integ, seed=k)))
    return integ, out


def test_a_moving_camera_s_disc_takes_its_own_levels():
    # foveal_disc_iterations_moving (the preset's: 2) holds where the camera moved since the
    # last frame: that frame is the one foveal_disc_iterations renders at that count, since
    # the history holds the samples before any filter. A still camera, and the first frame,
    # keep the still levels (-1: those in every frame); outside the disc nothing changes.
    W, H = 64, 48
    scene = _scene((W, H), spp=1)

    def frames(turn: float, **o):
        return _turning_frames(scene, turn, preset="vr", **o)

    assert FoveatedIntegrator(preset="vr").options["foveal_disc_iterations_moving"] == 2
    integ, default = frames(0.6, foveal_disc_iterations_moving=-1)
    _, moving = frames(0.6, foveal_disc_iterations_moving=1)
    _, one = frames(0.6, foveal_disc_iterations=1, foveal_disc_iterations_moving=-1)
    np.testing.assert_array_equal(moving[0], default[0])
    inner, outer = _disc_masks(integ, W, H, 1.0)
    for k in (1, 2):
        np.testing.assert_array_equal(moving[k], one[k])
        np.testing.assert_array_equal(moving[k][outer], default[k][outer])
        assert not np.array_equal(moving[k][inner], default[k][inner]), k
    for a, b in zip(frames(0.0, foveal_disc_iterations_moving=-1)[1],
                    frames(0.0, foveal_disc_iterations_moving=1)[1]):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("base", [{"preset": "vr"},
                                  {"preset": "vr", "foveal_space": "film"},
                                  {"preset": "paper", "denoiser": "svgf"}],
                         ids=["vr", "vr-film", "film-svgf"])
@pytest.mark.parametrize("still,preset,given,value,differs", [
    # The colour test: from the first moving frame on.
    ("sigma_luminance", (8.0, 6.0), 5.0, 1.0, 1),
    # The history's cap: by the third frame a history of one sample a frame holds more
    # than two (a first frame holds only its own samples, whatever the cap).
    ("max_history", (32.0, 8.0), 16.0, 2.0, 2),
], ids=["colour-test", "history-cap"])
def test_a_moving_camera_takes_its_own_setting(base, still, preset, given, value, differs):
    # <still>_moving holds where the camera moved since the last frame, on the cells and the
    # disc alike: that frame is the one <still> renders at that value, since the history
    # holds the samples before any filter. A still camera, and the first frame, keep the
    # still setting.
    moving_name = f"{still}_moving"
    scene = _scene((64, 48), spp=1)

    def frames(turn: float, **o):
        return _turning_frames(scene, turn, **base, **o)[1]

    vr = FoveatedIntegrator(preset="vr").options
    assert (vr[still], vr[moving_name]) == preset
    # A setting given holds in every frame, the preset's moving one yielding to it.
    assert FoveatedIntegrator(preset="vr", **{still: given}).options[moving_name] == 0.0
    default = frames(0.6)
    moving = frames(0.6, **{moving_name: value})
    one = frames(0.6, **{still: value})
    np.testing.assert_array_equal(moving[0], default[0])
    for k in (1, 2):
        np.testing.assert_array_equal(moving[k], one[k])
    for k in range(differs, 3):
        assert not np.array_equal(moving[k], default[k]), k
    for a, b in zip(frames(0.0), frames(0.0, **{moving_name: value})):
        np.testing.assert_array_equal(a, b)


def test_the_disc_s_own_denoiser_changes_the_disc_only():
    # 'same' is the frame's denoiser; 'none' shows the disc's resolved pixels; OIDN changes
    # the disc alone and, on its 1-spp pixels, brings it nearer a converged reference.
    from foveated_mi.denoise import oidn_available
    W, H = 64, 48
    scene = _scene((W, H), spp=1)
    ref = np.array(mi.render(scene, integrator=scene.integrator(), spp=1024, seed=99))

    def frames(**o):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", history=False, **o)
        return integ, [np.array(mi.render(scene, integrator=integ, seed=s, spp=1))
                       for s in range(3)]

    integ, default = frames()
    assert integ.options["foveal_disc_denoiser"] == "same"
    for a, b in zip(default, frames(foveal_disc_denoiser=integ.options["denoiser"])[1]):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(frames(foveal_disc="resolved")[1], frames(foveal_disc_denoiser="none")[1]):
        np.testing.assert_array_equal(a, b)
    if not oidn_available():
        pytest.skip("pyoidn not installed")
    inner, outer = _disc_masks(integ, W, H, 1.0)
    _, resolved = frames(foveal_disc="resolved")
    _, oidn = frames(foveal_disc_denoiser="oidn")
    for a, b in zip(default, oidn):
        np.testing.assert_array_equal(a[outer], b[outer])
        assert not np.allclose(a[inner], b[inner])
    err = {k: np.mean([np.mean((f[inner] - ref[inner]) ** 2) for f in v])
           for k, v in (("resolved", resolved), ("oidn", oidn))}
    # As the SVGF disc's test: the 1-spp noise falls by far more than the network's bias adds.
    assert err["oidn"] < 0.7 * err["resolved"], err


def test_the_frame_reads_what_each_of_its_denoisers_needs():
    # The disc's own denoiser counts as the frame's: OIDN reads the G-buffer's materials and
    # runs on the host, so such a frame carries materials and forms without replay.
    from foveated_mi.configure import denoisers_used, frame_settings
    from foveated_mi.denoise import oidn_available
    from foveated_mi.frame.formation import replayable
    from foveated_mi.postprocess import DENOISERS
    from foveated_mi.timing import StageTimer
    if not oidn_available():
        pytest.skip("pyoidn not installed")
    plain = FoveatedIntegrator(preset="vr").options
    disc = FoveatedIntegrator(preset="vr", foveal_disc_denoiser="oidn").options
    assert denoisers_used(plain) == ("svgf",)
    assert denoisers_used(FoveatedIntegrator(preset="vr", foveal_disc_denoiser="svgf").options) \
        == ("svgf",)
    assert denoisers_used(disc) == ("svgf", "oidn")
    assert not DENOISERS["svgf"].materials and DENOISERS["oidn"].materials
    assert not frame_settings(plain).plan.materials and frame_settings(disc).plan.materials
    timer = StageTimer(False)
    assert replayable(True, denoisers_used(plain), timer)
    assert not replayable(True, denoisers_used(disc), timer)


def test_a_disc_denoiser_that_cuts_gradients_is_refused_for_them():
    from foveated_mi.options import check_differentiable
    check_differentiable({"foveal_disc_denoiser": "same"})
    check_differentiable({"foveal_disc_denoiser": "svgf"})
    with pytest.raises(ParameterError) as e:
        check_differentiable({"foveal_disc_denoiser": "oidn"})
    assert "\n" not in str(e.value) and "foveal_disc_denoiser" in str(e.value)


@pytest.mark.parametrize("options", [
    {"preset": "vr", "foveal_disc": "resolved", "foveal_disc_iterations": 2},
    {"preset": "vr", "foveal_disc": "resolved", "foveal_disc_iterations_moving": 2},
    {"preset": "vr", "foveal_disc_iterations_moving": -2},
    {"preset": "guided", "foveal_disc_sigma_luminance": 2.0},
    {"preset": "vr", "foveal_disc_iterations": 17},
    {"preset": "vr", "foveal_disc": "resolved", "foveal_disc_denoiser": "svgf"},
    {"preset": "vr", "foveal_disc_denoiser": "bogus"}])
def test_the_disc_s_own_filter_outside_a_denoised_disc_gets_one_line(options):
    name = next(k for k in options if k.startswith("foveal_disc_"))
    with pytest.raises(ParameterError, match=name) as e:
        FoveatedIntegrator(**options)
    assert "\n" not in str(e.value)


def test_a_bad_foveal_disc_gets_one_line():
    with pytest.raises(ParameterError, match=r"foveal_disc = 'blurred' is invalid") as e:
        FoveatedIntegrator(preset="vr", foveal_disc="blurred")
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("space", ["buffer", "film"])
@pytest.mark.parametrize("denoiser", ["svgf", "atrous"])
def test_the_filter_skips_the_cells_off_the_film(space, denoiser, monkeypatch):
    # A gaze near a corner leaves many cells off the film, which hold no value and which the
    # warp never reads. The buffer's filter skips them: they keep no value, and the cells on
    # the film are filtered as with every cell visited, except that a filter that fills a
    # cell without a value from its neighbours (à-trous) no longer carries such a value from
    # beyond the film's edge into the next level (as on the film, where edge taps are
    # dropped). SVGF fills nothing, so its frames are the same bit for bit.
    from foveated_mi.frame import foveal
    scene = _scene((64, 48), spp=1)
    real = foveal._denoise

    def run():
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", foveal_space=space,
                                   denoiser=denoiser, gaze=(0.15, 0.2))
        images = [np.array(mi.render(scene, integrator=integ, seed=s)) for s in range(3)]
        return images, integ.buffer("filtered"), integ.buffer("cell_mask").astype(bool)

    images, skipped, on = run()
    monkeypatch.setattr(foveal, "_denoise",
                        lambda image, res, cgb, grid, o, grad_pass, region=None, ds=None,
                        kept=None, keep=False:
                        real(image, res, cgb, grid, o, grad_pass, None, ds, kept, keep))
    everywhere, filtered, _ = run()
    assert 0 < on.sum() < on.size * 3 // 4
    assert all(np.isfinite(a).all() for a in images)
    assert not np.isfinite(skipped[~on]).any()
    if denoiser == "svgf":
        for a, b in zip(images, everywhere):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(skipped[on], filtered[on])
    else:
        assert np.isfinite(filtered[~on]).any()


def test_the_preset_denoises_its_disc_where_the_frame_is_noisy():
    """At 1 spp of a path-traced box the disc's own pixels are noise: the preset's denoised
    disc lies closer to a converged frame than the resolved one, seed after seed."""
    scene = _scene((64, 48), integrator={"type": "path", "max_depth": 4})
    reference = np.array(mi.render(scene, spp=256, seed=99))
    yy, xx = np.mgrid[0:48, 0:64]
    assert FoveatedIntegrator(preset="vr").options["foveal_disc"] == "denoised"
    errors = {}
    for disc in ("denoised", "resolved"):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", history=False,
                                   foveal_disc=disc)
        fovea = None
        errors[disc] = []
        for seed in range(3):
            image = np.array(mi.render(scene, integrator=integ, spp=1, seed=seed))
            if fovea is None:
                from foveated_mi.frame.cells import fovea_radius
                r0 = fovea_radius(64, 48, integ.options["theta"])
                fovea = np.hypot(xx + 0.5 - 32, yy + 0.5 - 24) <= r0 - 2
            errors[disc].append(np.mean((image[fovea] - reference[fovea]) ** 2))
    assert all(d < r for d, r in zip(errors["denoised"], errors["resolved"])), errors


def test_the_buffer_s_filter_weighs_the_noise_of_the_values_it_filters():
    """With ``demodulate`` the cells are filtered as irradiance E = L / a, and SVGF's colour
    weight scales with the noise of E: the samples' per-sample variance of L over their count,
    over a's luminance squared, as on the film. Its mean and second moment must be read in one
    domain: E's mean against L's second moment gives m2 - E^2 < 0 where a < 1, no variance,
    and a filter that keeps every cell's noise."""
    from types import SimpleNamespace
    from foveated_mi.frame import foveal
    from foveated_mi.frame.settings import DenoiseSettings, DomainSettings
    from foveated_mi.kernels.buffers import GBuffer, Resolved
    from foveated_mi.kernels.grid import Grid
    w, h = 8, 6
    n = w * h
    radiance, per_sample, count, albedo = 0.3, 0.02, 8.0, 0.5
    res = Resolved(mi.Color3f(dr.full(mi.Float, radiance, n)), dr.full(mi.Bool, True, n),
                   dr.full(mi.Float, count, n), dr.zeros(mi.Bool, n),
                   dr.full(mi.Float, radiance ** 2 + per_sample, n))
    gb = GBuffer(dr.zeros(mi.Point3f, n), mi.Normal3f(dr.zeros(mi.Float, n),
                 dr.zeros(mi.Float, n), dr.ones(mi.Float, n)), dr.ones(mi.Float, n),
                 dr.full(mi.Bool, True, n), mi.Vector3f(0, 0, 1),
                 mi.Color3f(dr.full(mi.Float, albedo, n)), dr.zeros(mi.Color3f, n))
    settings = SimpleNamespace(
        denoise=DenoiseSettings("svgf", (("atrous_iterations", 1), ("sigma_luminance", 4.0),
                                         ("demodulate", True)), True),
        domain=DomainSettings(True, False, "reinhard", 0.0, np.inf))
    out = foveal._denoise(res.shading / albedo, res, gb, Grid(w, h), settings, False)
    # s^2 = (m2 - mu^2) n / (n - 1), over n samples, over lum(a)^2; m2 - mu^2 cancels
    # (0.11 - 0.09 = 0.02: a condition of 10 on a handful of roundings).
    want = per_sample / (count - 1.0) / albedo ** 2
    tolerances.assert_within(out.variance.numpy(), want,
                             want * tolerances.gamma(10 * 10), "variance of E")
