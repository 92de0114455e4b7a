"""A cell's ray through a point of the cell that moves every frame (``foveal_jitter``): each
cell's ray stays inside its cell, the disc's rays and a ray two samples read stay where they
were, the sequence covers a cell evenly, a still view's periphery keeps falling below what
the cells' centres hold, the trace replays what it traced, the gradient pass goes through the
primal's points, and bad input is refused in one line."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from still_cells import periphery_mse, still_frames

from foveated_mi.frame import buffer_space
from foveated_mi.frame.cells import gaze_position
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.options import validate_options
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError

SIZE = (96, 64)


def _samples(gaze=(0.5, 0.5), size=SIZE):
    o = validate_options({"preset": "vr"})
    lay = buffer_space.layout(*size, o["theta"], o["ray_budget"])
    g = gaze_position(gaze, *size)
    pixels, on = buffer_space.sample_pixels(lay, g, *size)
    return lay, g, pixels, on


def _points(lay, g, pixels, on, jitter, index, size=SIZE):
    """Each sample's ray, one ray per sample: its film point and cell coordinates."""
    rays = dr.arange(mi.UInt32, lay.size)
    shift = buffer_space.ray_shifts(lay, pixels, on, rays, lay.size, g, *size, jitter,
                                    buffer_space.jitter_phase(index))
    px = np.array(pixels)
    centre = np.stack([px % size[0] + 0.5, px // size[0] + 0.5], axis=1)
    point = centre + np.array(shift).T
    coords = np.array(lay.grid.coords_at(mi.Point2f(point[:, 0], point[:, 1]), g)).T
    return np.array(shift).T, point, coords


@pytest.mark.parametrize("jitter", [1.0, 0.5])
@pytest.mark.parametrize("gaze", [(0.5, 0.5), (0.2, 0.7)])
def test_each_cell_s_ray_goes_through_a_point_of_its_own_cell(jitter, gaze):
    lay, g, pixels, on = _samples(gaze)
    cells = np.zeros(lay.size, bool)
    cells[:lay.cells] = True
    on_ = np.array(on)
    idx = np.arange(lay.size)
    ring, angle = idx // lay.grid.width, idx % lay.grid.width
    for index in (0, 1, 7):
        shift, point, coords = _points(lay, g, pixels, on, jitter, index)
        inside = (point[:, 0] > 0) & (point[:, 0] < SIZE[0] - 1e-3) & \
            (point[:, 1] > 0) & (point[:, 1] < SIZE[1] - 1e-3)
        sel = cells & on_ & inside
        # Within jitter / 2 of the cell's centre along its angle and its ring (float32
        # positions of tens of pixels: 1e-3 of a cell).
        da = (coords[sel, 0] - (angle[sel] + 0.5) + lay.grid.width / 2) % lay.grid.width \
            - lay.grid.width / 2
        dr_ = coords[sel, 1] - (ring[sel] + 0.5)
        assert np.abs(da).max() <= jitter / 2 + 1e-3, np.abs(da).max()
        assert np.abs(dr_).max() <= jitter / 2 + 1e-3, np.abs(dr_).max()
        # The rays do move: not every cell's ray goes through its pixel's centre.
        assert np.abs(shift[sel]).max() > 0.25
        # The disc's pixels trace their pixels, as without the jitter.
        np.testing.assert_array_equal(shift[~cells], 0.0)


def test_a_ray_that_two_samples_read_keeps_its_place():
    lay, g, pixels, on = _samples()
    # Every pair of samples reads one ray: no ray has a single owner.
    rays = dr.arange(mi.UInt32, lay.size) // 2
    shift = buffer_space.ray_shifts(lay, pixels, on, rays, (lay.size + 1) // 2, g, *SIZE,
                                    1.0, buffer_space.jitter_phase(3))
    owners = np.bincount(np.array(rays)[np.array(on)], minlength=(lay.size + 1) // 2)
    s = np.array(shift).T
    np.testing.assert_array_equal(s[owners != 1], 0.0)


def test_the_sequence_covers_each_cell_evenly():
    lay, g, pixels, on = _samples()
    frames = 64
    offs = np.stack([_points(lay, g, pixels, on, 1.0, k)[2] for k in range(frames)])
    idx = np.arange(lay.cells)[np.array(on)[:lay.cells]][::37]
    ring, angle = idx // lay.grid.width, idx % lay.grid.width
    checked = 0
    for i, a, r in zip(idx, angle, ring):
        u = offs[:, i, 0] - a
        v = offs[:, i, 1] - r
        if not ((u > -0.01).all() and (u < 1.01).all()):
            continue          # a point clamped at the film's edge
        # R2 over 64 frames: each quarter of the cell holds a quarter of the points, within
        # the sequence's discrepancy (a few points of 64).
        q = np.histogram2d(u, v, bins=2, range=[[0, 1], [0, 1]])[0]
        assert np.abs(q - frames / 4).max() <= 4, q
        checked += 1
    assert checked >= len(idx) // 2, (checked, len(idx))


def _still(jitter, frames):
    images, _, ref, integ = still_frames(frames, foveal_jitter=jitter)
    return periphery_mse(images, ref, integ)


def test_a_still_view_keeps_converging_below_what_the_cells_centres_hold():
    frames = 32
    centres = _still(0.0, frames)
    jittered = _still(1.0, frames)
    # The centres hold their points' values from the first frame on; the jittered cells
    # gather the mean over each cell, and keep falling to below them.
    assert jittered[-1] < 0.9 * centres[-1], (jittered[-1], centres[-1])
    assert jittered[-1] < 0.9 * jittered[3], (jittered[3], jittered[-1])
    assert np.mean(jittered[24:]) < np.mean(jittered[8:16]), jittered


class Line(mi.SamplingIntegrator):
    """1 where the ray's film column lies in ``[lo, hi)`` pixels from the film's centre, on
    either side (a one-pixel vertical line each side), 0 elsewhere: no noise, no geometry."""

    def sample(self, scene, sampler, ray, medium=None, active=True):
        d = self.to_local @ ray.d
        u = dr.abs(d.x / d.z)
        on = (u >= self.lo) & (u < self.hi)
        return dr.select(on, mi.Spectrum(1.0), mi.Spectrum(0.0)), mi.Bool(True), []


def _line_frames(jitter, frames=32, size=(128, 96), column=19):
    import math
    from foveated_mi.scenes import apply_camera, camera_of
    W, H = size
    scene = load_scene("eye-exam", width=W, height=H, spp=1)
    apply_camera(scene, dict(camera_of(scene), fov=100.0))
    t = math.tan(math.radians(50.0))
    line = Line(mi.Properties())
    line.to_local = scene.sensors()[0].world_transform().inverse()
    line.lo, line.hi = column / (W / 2) * t, (column + 1) / (W / 2) * t
    integ = FoveatedIntegrator(nested=line, preset="vr", denoiser="none",
                               foveal_disc="resolved", foveal_jitter=jitter, max_history=0)
    images = [np.array(mi.render(scene, integrator=integ, seed=k)) for k in range(frames)]
    lay = buffer_space.layout(W, H, integ.options["theta"], integ.options["ray_budget"])
    return np.mean(images[frames // 2:], axis=0)[..., 0], lay.grid.cell_size(column + 0.5)


def test_a_thin_line_in_the_periphery_keeps_its_share_of_each_cell():
    # The line: film columns 83 and 44 of 128 (19.5 pixels from the centre, 20 degrees of
    # eccentricity through a 100-degree camera), across cells 2.2 pixels deep there.
    shown, w = _line_frames(1.0)
    centres, _ = _line_frames(0.0)
    rows = slice(44, 53)                     # the gaze's row, +- 4: the line crosses rings
    # A cell's mean holds the line's overlap with it over its depth w (the points are
    # uniform over the cell), less what the pixel's one-pixel footprint carries past the
    # cell's edge (at most half a pixel); the warp's hat between ring centres keeps at least
    # half of the ring that holds the pixel.
    bound = 0.5 / w * (1.0 - 0.5 / w)
    for col in (83, 44):
        peak = shown[rows, col - 1:col + 2].max(axis=1)
        assert peak.min() >= bound, (col, peak, bound)
        # Its whole contrast is kept across the row: the warp's hat sums to one over the
        # cell's depth (to within a pixel's share of it at each end).
        mass = shown[rows, col - 8:col + 9].sum(axis=1)
        np.testing.assert_allclose(mass, 1.0, atol=1.0 / w)
        # The cells' centres alone miss it in some rows.
        assert centres[rows, col - 1:col + 2].max(axis=1).min() < bound


def test_the_replayed_trace_gives_the_traced_images_and_compiles_nothing_after_frame_two():
    scene = load_scene("voxel-city", width=96, height=64, spp=2,
                       integrator={"type": "path", "max_depth": 3})
    kw = dict(preset="vr", nested=scene.integrator(), foveal_jitter=1.0)
    traced = FoveatedIntegrator(freeze=False, **kw)
    frozen = FoveatedIntegrator(freeze=True, **kw)
    plain = FoveatedIntegrator(freeze=True, preset="vr", nested=scene.integrator())
    for k in range(5):
        a = np.array(mi.render(scene, integrator=traced, seed=0))
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            b = np.array(mi.render(scene, integrator=frozen, seed=0))
            new = [h for h in dr.kernel_history([dr.KernelType.JIT])
                   if not h.get("cache_hit", True)]
        c = np.array(mi.render(scene, integrator=plain, seed=0))
        np.testing.assert_array_equal(a, b)
        if k >= 2:
            assert not new, len(new)
        if k >= 1:
            # From the second frame on the cells' points have moved off their centres.
            assert np.abs(b - c).max() > 0


def test_the_gradient_pass_goes_through_the_primal_s_points():
    from foveated_mi.frame.adjoint import NestedAdjoint
    scene = load_scene("voxel-city", width=96, height=64, spp=1,
                       integrator={"type": "path", "max_depth": 2})
    integ = FoveatedIntegrator(preset="vr", nested=scene.integrator(), foveal_jitter=1.0,
                               freeze=False)
    for k in range(3):
        mi.render(scene, integrator=integ, seed=k)
    frame = integ.views[0].primal.plan
    ro = frame.reordered
    n = frame.width * frame.height
    mask = dr.zeros(mi.Bool, n)
    dr.scatter(mask, True, ro.wavefront, True if ro.active is None else ro.active)
    pixels, sensor, layout = NestedAdjoint()._flat(frame, mask, "importance")
    # The flat sensor's shift of each traced pixel is the primal's shift of its ray.
    at = np.zeros((n, 2))
    wf, sh = np.array(ro.wavefront), np.array(frame.ray_shift).T
    act = np.ones(len(wf), bool) if ro.active is None else np.array(ro.active)
    at[wf[act]] = sh[act]
    got = np.array(sensor.shift).T[:dr.width(pixels)]
    np.testing.assert_allclose(got, at[np.array(pixels)], rtol=0, atol=0)
    assert np.abs(got).max() > 0.25


@pytest.mark.parametrize("bad,match", [
    ({"foveal_jitter": 0.5, "preset": "oidn"}, "foveal_jitter = 0.5 is invalid: expected 0 unless"),
    ({"foveal_jitter": 0.5, "preset": "vr", "foveal_space": "film"},
     "foveal_jitter = 0.5 is invalid: expected 0 unless"),
    ({"foveal_jitter": 1.5, "preset": "vr"}, "foveal_jitter = 1.5"),
    ({"foveal_jitter": -0.1, "preset": "vr"}, "foveal_jitter = -0.1"),
])
def test_bad_jitter_is_refused_in_one_line(bad, match):
    with pytest.raises(ParameterError, match=match) as e:
        validate_options(bad)
    assert "\n" not in str(e.value)


def test_without_history_every_cell_traces_its_centre():
    from foveated_mi.configure import jitter_of
    o = validate_options({"preset": "vr", "foveal_jitter": 1.0, "history": False})
    assert jitter_of(o) == 0.0
    assert jitter_of(validate_options({"preset": "vr", "foveal_jitter": 1.0})) == 1.0
