"""The foveal buffer's own samples (``foveal_space = "buffer"``, the ``vr`` preset's default):
the grid without rings inside the disc keeps those outside, every sample finds itself at its
own film position, a gaze move reads the disc pixels the two discs share, a still view
projects nothing, a moving head keeps its history without the frame getting worse than a
fresh one, and what needs a full-resolution buffer is refused in one line."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from kernel_counts import compiled_by

from foveated_mi.frame import buffer_space
from foveated_mi.frame.cells import foveal_grid, fovea_radius, gaze_position
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.metrics import psnr
from foveated_mi.options import validate_options
from foveated_mi.render import to_display
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError


def _layout(width, height, **options):
    o = validate_options({"preset": "vr", **options})
    return buffer_space.layout(width, height, o["theta"], o["ray_budget"])


@pytest.mark.parametrize("size,budget", [((96, 64), 0.1), ((160, 90), 0.25), ((40, 90), 0.1)])
def test_the_grid_without_inner_rings_keeps_every_ring_outside_the_disc(size, budget):
    W, H = size
    r0 = fovea_radius(W, H, 0.15)
    full = foveal_grid(W, H, budget, r0)
    outer = full.outside_fovea()
    assert outer.skip > 0 and outer.height == full.height - outer.skip
    assert outer.width == full.width
    # The same cells outside: cell i of the outer grid is cell i + skip rows of the full one.
    g = mi.Point2f(W * 0.4, H * 0.6)
    i = dr.arange(mi.UInt32, outer.size)
    a = np.array(outer.film_position(i, g))
    b = np.array(full.film_position(i + outer.skip * outer.width, g))
    # Positions of at most the diagonal, from a log and an exp in float32.
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-5 * np.hypot(W, H))
    # Ring 0 straddles the disc's edge: no ring lies wholly inside it.
    inner_edge = outer._r_of_u(np.float64(0.0))
    assert inner_edge <= r0 < outer._r_of_u(np.float64(1.0))


@pytest.mark.parametrize("gaze", [(0.5, 0.5), (0.1, 0.85), (0.0, 0.0), (0.99, 0.3)])
def test_every_sample_finds_itself_at_its_own_film_position(gaze):
    W, H = 96, 64
    lay = _layout(W, H)
    g = gaze_position(gaze, W, H)
    pixels, on = buffer_space.sample_pixels(lay, g, W, H)
    idx = dr.arange(mi.UInt32, lay.size)
    is_cell = idx < lay.cells
    centre = lay.grid.film_position(dr.select(is_cell, idx, 0), g)
    y = pixels // W
    px = mi.Point2f(mi.Float(pixels - y * W) + 0.5, mi.Float(y) + 0.5)
    # A disc sample at its pixel's centre, a cell at its own centre.
    at = dr.select(is_cell, centre, px)
    j, inside, _ = buffer_space.sample_at(lay, at, g)
    on, j, inside, cell = (np.array(v) for v in (on, j, inside, is_cell))
    disc = on & ~cell
    np.testing.assert_array_equal(j[disc], np.flatnonzero(disc))
    assert inside[on].all()
    # A cell's centre lies in that cell, except within the disc, which holds it instead.
    gx, gy = gaze[0] * W, gaze[1] * H
    c = np.array(centre)
    outside = on & cell & (np.hypot(c[0] - gx, c[1] - gy) > lay.grid.fovea + 1.0)
    assert outside.sum() > 50
    np.testing.assert_array_equal(j[outside], np.flatnonzero(outside))
    # The disc's samples are the film's pixels whose centre lies within r0 of the gaze,
    # each once (at the film's edge, the part of the disc on the film).
    pix = np.array(pixels)[disc]
    yy, xx = np.mgrid[0:H, 0:W]
    # float32 on the device against float64 here: a centre within 1e-4 px of the circle may
    # fall either way.
    d = np.hypot(xx + 0.5 - gx, yy + 0.5 - gy).ravel()
    assert len(set(pix.tolist())) == len(pix)
    assert set(np.flatnonzero(d <= lay.grid.fovea - 1e-4)) <= set(pix.tolist())
    assert set(pix.tolist()) <= set(np.flatnonzero(d <= lay.grid.fovea + 1e-4))
    assert disc.sum() > 10


def _scene(size=(64, 48)):
    return load_scene("cornell-box", width=size[0], height=size[1], spp=1,
                      integrator={"type": "path", "max_depth": 3})


def test_a_gaze_move_reads_the_disc_pixels_both_discs_hold():
    W, H = 64, 48
    scene = _scene((W, H))
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", denoiser="none",
                               theta=0.3, ray_budget=0.3)
    integ.gaze = (0.45, 0.5)
    mi.render(scene, integrator=integ, seed=0)
    before = set(np.flatnonzero(integ.buffer("sampling_map").ravel()).tolist())
    integ.gaze = (0.55, 0.45)
    mi.render(scene, integrator=integ, seed=1)
    lay = buffer_space.layout(W, H, integ.options["theta"], integ.options["ray_budget"])
    pixel = integ.buffer("sample_pixel")[0]
    on = integ.buffer("sample_on")[0].astype(bool)
    count = integ.buffer("history_count")[0]
    disc = on & (np.arange(lay.size) >= lay.cells)
    shared = disc & np.isin(pixel, list(before))
    # The camera is still: every disc pixel traced in both frames holds both samples, one
    # traced in this frame only holds one.
    gx, gy = 0.45 * W, 0.5 * H
    yy, xx = np.divmod(pixel, W)
    was_disc = np.hypot(xx + 0.5 - gx, yy + 0.5 - gy) <= lay.grid.fovea
    assert (shared & was_disc).sum() > 100
    np.testing.assert_array_equal(count[shared & was_disc], 2.0)
    np.testing.assert_array_equal(count[disc & ~shared], 1.0)


def test_a_still_view_projects_nothing_and_a_gaze_move_does(monkeypatch):
    scene = _scene()
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr")
    calls = []
    real = buffer_space.reprojection_map
    monkeypatch.setattr(buffer_space, "reprojection_map",
                        lambda *a, **k: calls.append(1) or real(*a, **k))
    for k in range(4):
        mi.render(scene, integrator=integ, seed=k)
    # The first frame has no history, the second reads it through a projection... and
    # from then on a still camera and gaze reuse the samples' G-buffer and map.
    assert len(calls) == 1, calls
    assert integ.stats["history_hits"] > 0
    integ.gaze = (0.3, 0.4)
    mi.render(scene, integrator=integ, seed=9)
    assert len(calls) == 2


def test_a_still_view_builds_its_launch_once_and_a_gaze_or_layout_change_again(monkeypatch):
    from foveated_mi.frame import buffer_plan
    scene = _scene()
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr")
    calls = []
    real = buffer_plan._reorder.launch_of_pixels
    monkeypatch.setattr(buffer_plan._reorder, "launch_of_pixels",
                        lambda *a, **k: calls.append(a[4]) or real(*a, **k))
    images = [np.array(mi.render(scene, integrator=integ, seed=k)) for k in range(3)]
    assert calls == ["tiles"]
    integ.gaze = (0.3, 0.4)
    mi.render(scene, integrator=integ, seed=3)
    integ.reorder = "compact"
    mi.render(scene, integrator=integ, seed=4)
    assert calls == ["tiles", "tiles", "compact"]
    # The reused launch traces what a fresh one does: the same frames, bit for bit.
    monkeypatch.setattr(buffer_plan._reorder, "launch_of_pixels", real)
    fresh = FoveatedIntegrator(nested=scene.integrator(), preset="vr")
    for k, image in enumerate(images):
        fresh.views[0].planner._samples_cache = None
        np.testing.assert_array_equal(np.array(mi.render(scene, integrator=fresh, seed=k)),
                                      image)


def _look(origin):
    return mi.ScalarTransform4f().look_at(origin=origin, target=[0, 0, 0], up=[0, 1, 0])


def test_a_moving_camera_under_a_still_gaze_keeps_its_samples_launch(monkeypatch):
    """The samples' pixels, and so the launch, depend on the gaze alone: a camera that moves
    under a still gaze casts a new G-buffer at them but builds no launch, and traces the
    frames that a launch built afresh every frame traces, bit for bit."""
    from foveated_mi.frame import buffer_plan
    scene = _scene()
    params = mi.traverse(scene)
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr")
    calls = []
    real = buffer_plan._reorder.launch_of_pixels
    monkeypatch.setattr(buffer_plan._reorder, "launch_of_pixels",
                        lambda *a, **k: calls.append(1) or real(*a, **k))

    def frames(integrator, drop: bool, gazes):
        out = []
        for k, gaze in enumerate(gazes):
            a = np.radians(0.6 * k)
            params["sensor.to_world"] = _look([3.9 * np.sin(a), 0.0, 3.9 * np.cos(a)])
            params.update()
            integrator.gaze = gaze
            if drop:
                integrator.views[0].planner._samples_cache = None
            out.append(np.array(mi.render(scene, integrator=integrator, seed=k)))
        return out

    gazes = [(0.5, 0.5)] * 4 + [(0.3, 0.4)] * 2
    images = frames(integ, False, gazes)
    assert len(calls) == 2, calls          # the first gaze, then the second
    assert integ.stats["history_hits"] > 0
    fresh = FoveatedIntegrator(nested=scene.integrator(), preset="vr")
    for image, again in zip(images, frames(fresh, True, gazes)):
        np.testing.assert_array_equal(again, image)
    assert len(calls) == 2 + len(gazes)


@pytest.mark.parametrize("interleave", [1, 2])
def test_a_moving_head_keeps_its_history_and_the_frame_is_no_worse_than_a_fresh_one(interleave):
    """A camera orbiting 0.6 degrees a frame with the gaze drifting: the samples find their
    surfaces again (most read history), and the frame is no worse than a fresh integrator's
    first frame of the same view (the history never costs quality), with the cells traced
    in turn too."""
    size = 64
    scene = _scene((size, size))
    params = mi.traverse(scene)
    # Cells in turn were screened with the buffer's filter before (2 levels, 4 deviations;
    # an option, off): with the preset's since, one seed's frame here is 0.1 dB below fresh.
    pin = {} if interleave == 1 else {"atrous_iterations": 2, "sigma_luminance": 4.0}
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr",
                               foveal_interleave=interleave, **pin)
    for k in range(10):
        a = np.radians(0.6 * k)
        params["sensor.to_world"] = _look([3.9 * np.sin(a), 0.0, 3.9 * np.cos(a)])
        params.update()
        integ.gaze = (0.5 + 0.01 * k, 0.5)
        img = np.array(mi.render(scene, integrator=integ, seed=k))
    hits = integ.stats["history_hits"]
    on = integ.buffer("sample_on")[0].astype(bool)
    assert hits > 0.6 * on.sum(), (hits, on.sum())
    fresh = FoveatedIntegrator(nested=scene.integrator(), preset="vr", gaze=integ.gaze,
                               foveal_interleave=interleave, **pin)
    first = np.array(mi.render(scene, integrator=fresh, seed=9))
    ref = to_display(np.array(mi.render(scene, integrator=scene.integrator(), spp=256,
                                        seed=99)))
    gain = psnr(ref, to_display(img), 1.0) - psnr(ref, to_display(first), 1.0)
    assert gain > 0.0, gain


def _cut_frame(**options):
    """Three frames of a still view, then the frame after a camera cut: its image and the
    integrator."""
    scene = _scene()
    params = mi.traverse(scene)
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", **options)
    for k in range(3):
        mi.render(scene, integrator=integ, seed=k)
    params["sensor.to_world"] = mi.ScalarTransform4f().look_at(
        origin=[0, 0, 3.9], target=[0, 0, 10], up=[0, 1, 0])
    params.update()
    return np.array(mi.render(scene, integrator=integ, seed=5)), integ


@pytest.mark.parametrize("options", [{}, {"foveal_interleave": 2}, {"foveal_jitter": 1.0}],
                         ids=["cells", "interleave", "jitter"])
def test_a_camera_cut_reads_no_history(options):
    image, integ = _cut_frame(**options)
    assert integ.stats["history_hits"] == 0
    on = integ.buffer("sample_on")[0].astype(bool)
    assert (integ.buffer("history_count")[0][on] <= 1.0).all()
    # Nor does it show what the samples showed before the cut (foveal_taa).
    blended, integ = _cut_frame(foveal_taa=0.3, **options)
    assert integ.stats["history_hits"] == 0
    np.testing.assert_array_equal(blended, image)


@pytest.mark.parametrize("bad,match", [
    ({"foveal_upsampling": "joint"}, r"foveal_upsampling = 'joint' is invalid: expected "
                                     r"'bilinear' or 'cubic' with foveal_space = 'buffer'"),
    ({"emission_edges": True}, r"emission_edges = True is invalid: expected False with "
                               r"foveal_space = 'buffer'"),
    ({"edge_threshold": 0.1}, r"edge_threshold = 0\.1 is invalid: expected 0 with "
                              r"foveal_space = 'buffer'"),
    ({"foveal_space": "screen"}, r"foveal_space = 'screen' is invalid"),
])
def test_what_needs_the_full_resolution_buffer_is_refused_in_one_line(bad, match):
    with pytest.raises(ParameterError, match=match) as e:
        FoveatedIntegrator(preset="vr", **bad)
    assert "\n" not in str(e.value)
    if "foveal_space" not in bad:
        FoveatedIntegrator(preset="vr", foveal_space="film", **bad)   # there it works


def _plane_samples(sensor, lay, gaze, W, H, z, normal):
    """The samples' G-buffer of the plane at height ``z`` with the given normal."""
    from foveated_mi.kernels.buffers import GBuffer
    from foveated_mi.kernels.pixels import primary_rays
    pixels, on = buffer_space.sample_pixels(lay, gaze, W, H)
    y = pixels // W
    ray = primary_rays(sensor, pixels - y * W, y, W, H)
    t = (z - ray.o.z) / ray.d.z
    p = ray.o + t * ray.d
    n = mi.Normal3f(*normal) + dr.zeros(mi.Normal3f, lay.size)
    return GBuffer(position=mi.Point3f(p), normal=n, depth=dr.norm(p - ray.o), hit=on,
                   direction=mi.Vector3f(ray.d)), on


@pytest.mark.parametrize("z,normal,hits", [(0.0, (0, 0, 1), True), (0.5, (0, 0, 1), False),
                                           (0.0, (1, 0, 0), False)])
def test_a_sample_reads_its_history_only_on_the_surface_it_saw(z, normal, hits):
    """A still camera over the plane z = 0: the same plane reads every sample's history; a
    plane in front of it (a disocclusion's foreground) or a surface facing elsewhere reads
    none."""
    from foveated_mi.frame.reproject import History, camera_state
    W = H = 32
    sensor = mi.load_dict({"type": "perspective", "fov": 60, "to_world":
                           mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0],
                                                          up=[0, 1, 0]),
                           "film": {"type": "hdrfilm", "width": W, "height": H}})
    lay = _layout(W, H)
    gaze = gaze_position((0.5, 0.5), W, H)
    seen, on = _plane_samples(sensor, lay, gaze, W, H, 0.0, (0, 0, 1))
    n = lay.size
    history = History(mean=dr.zeros(mi.Color3f, n), count=dr.full(mi.Float, 1.0, n),
                      moment2=dr.zeros(mi.Float, n), depth=dr.select(on, seen.depth, dr.inf),
                      camera=camera_state(sensor), width=W, height=H, layout=lay,
                      position=seen.position, normal=seen.normal, gaze=gaze)
    now, _ = _plane_samples(sensor, lay, gaze, W, H, z, normal)
    m = buffer_space.reprojection_map(now, on, history, lay, W, H, mode="nearest")
    hit, on = np.array(m.hit), np.array(on)
    assert on.sum() > 100
    if hits:
        assert hit[on].all() and not hit[~on].any()
    else:
        assert not hit.any()


def test_a_denoiser_that_sees_a_plain_image_gets_the_buffer_padded_across_its_seam():
    """A registered denoiser that knows no neighbour rule (as a network) blurs each row of the
    image it is given with its left and right neighbours, clamped at the image's edges. In
    the foveal buffer it must see across the seam at angle 0: the result equals the wrapped
    blur of the buffer, the seam's columns included."""
    from foveated_mi.postprocess import registry
    from foveated_mi.postprocess.registry import register_denoiser

    def row_blur(ctx):
        idx = dr.arange(mi.UInt32, ctx.width * ctx.height)
        y = idx // ctx.width
        x = mi.Int32(idx - y * ctx.width)
        acc = dr.zeros(mi.Color3f, dr.width(idx))
        for dx in (-1, 0, 1):
            q = y * ctx.width + mi.UInt32(dr.clip(x + dx, 0, ctx.width - 1))
            acc += dr.gather(mi.Color3f, ctx.image, q)
        return acc / 3.0

    register_denoiser("row_blur", row_blur, differentiable=False, domain="irradiance")
    try:
        scene = _scene()
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", denoiser="none",
                                   history=False)
        mi.render(scene, integrator=integ, seed=3)
        cells = integ.buffer("cells")
        blurred = FoveatedIntegrator(nested=scene.integrator(), preset="vr",
                                     denoiser="row_blur", history=False)
        mi.render(scene, integrator=blurred, seed=3)
        out = blurred.buffer("filtered")
    finally:
        registry.unregister_denoiser("row_blur")
    expected = (np.roll(cells, 1, axis=1) + cells + np.roll(cells, -1, axis=1)) / 3.0
    ok = np.isfinite(expected).all(-1)
    assert ok[:, 0].sum() > 3 and ok[:, -1].sum() > 3
    # Three terms summed and a division in float32 (values of order 1).
    np.testing.assert_allclose(out[ok], expected[ok], rtol=4e-7 * 4, atol=1e-6)


@pytest.mark.skipif(not __import__("foveated_mi.denoise", fromlist=["x"]).oidn_available(),
                    reason="pyoidn not installed")
def test_oidn_runs_in_the_buffer():
    scene = _scene((96, 64))
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", denoiser="oidn")
    image = np.array(mi.render(scene, integrator=integ, seed=1))
    assert np.isfinite(image).all()
    cells = integ.buffer("cells")
    filtered = integ.buffer("filtered")
    assert filtered.shape == cells.shape          # on the buffer's grid, cropped back
    ok = integ.buffer("cell_mask").astype(bool)
    assert np.isfinite(filtered[ok]).all()
    assert not np.allclose(filtered[ok], cells[ok])   # it filtered something


def test_a_moving_head_and_gaze_compile_nothing_from_frame_3():
    scene = _scene()
    params = mi.traverse(scene)
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr")
    compiled = []
    for k in range(6):
        a = np.radians(0.5 * k)
        params["sensor.to_world"] = _look([3.9 * np.sin(a), 0.0, 3.9 * np.cos(a)])
        params.update()
        integ.gaze = (0.4 + 0.05 * k, 0.5 - 0.03 * k)
        compiled.append(compiled_by(lambda: np.array(mi.render(scene, integrator=integ,
                                                               seed=k))))
    assert compiled[3:] == [0, 0, 0], compiled


@pytest.mark.parametrize("mode", ["compact", "tiles", "rows_blocks"])
@pytest.mark.parametrize("size", [(61, 37), (64, 48)])
def test_the_launch_of_a_set_of_pixels_is_the_launch_of_its_map(mode, size):
    """Built from the pixels (in tile order directly for ``tiles``), the launch and the map
    are those of :func:`reorder` on the map the pixels make, repeats traced once."""
    from foveated_mi.frame.reorder import launch_of_pixels, reorder
    W, H = size
    rng = np.random.default_rng(7)
    pixels = mi.UInt32(rng.integers(0, W * H, 900).astype(np.uint32))   # with repeats
    on = mi.Bool(rng.random(900) < 0.8)
    ro, smap = launch_of_pixels(pixels, on, W, H, mode)
    expected = np.zeros(W * H, bool)
    expected[np.array(pixels)[np.array(on)]] = True
    np.testing.assert_array_equal(np.array(smap), expected)
    ref = reorder(mi.Bool(expected), W, H, mode)
    np.testing.assert_array_equal(np.array(ro.wavefront), np.array(ref.wavefront))
    assert (ro.active is None) == (ref.active is None)


@pytest.mark.parametrize("mode", ["tiles", "compact", "rows_blocks", "none"])
@pytest.mark.parametrize("pixel_filter,spp", [("splat", 2), ("importance", 1), ("importance", 3)])
def test_the_shading_buffer_on_the_samples_is_the_films_read_at_their_pixels(
        mode, pixel_filter, spp):
    """Developed straight onto the samples (nothing film-sized on the way), each sample holds
    bit for bit what the film-sized buffer holds at its pixel, in every launch layout
    (including those with idle lanes); a sample off the film holds nothing."""
    from foveated_mi.frame.pixel_filter import FilterSampler
    from foveated_mi.frame.reorder import launch_of_pixels
    from foveated_mi.frame.shading import develop, trace_wavefront
    W, H = 61, 37
    scene = _scene((W, H))
    sensor = scene.sensors()[0]
    lay = _layout(W, H, ray_budget=0.2)
    pixels, on = buffer_space.sample_pixels(lay, gaze_position((0.3, 0.6), W, H), W, H)
    ro, _ = launch_of_pixels(pixels, on, W, H, mode)
    rays = buffer_space.sample_rays(pixels, on, ro.wavefront, ro.active, W * H)
    fs = FilterSampler(sensor.film(), importance=pixel_filter == "importance")
    traced = trace_wavefront(scene, sensor, scene.integrator(), ro.wavefront, W, H, spp=spp,
                             seed=5, active=ro.active, filter_sampler=fs)
    film = develop(traced, ro.wavefront, spp, sensor.film(), pixel_filter)
    mine = develop(traced, ro.wavefront, spp, sensor.film(), pixel_filter, at=(rays, on))
    p, o = np.array(pixels), np.array(on)
    assert 0 < o.sum() < o.size
    for a, b in zip(mine, film):
        a, b = np.array(a), np.array(b)
        np.testing.assert_array_equal(a[..., o], b[..., p[o]])
        assert not a[..., ~o].any()
    assert np.array(mine.mask)[o].all()
