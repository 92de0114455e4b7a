"""The cells of the polar law's buffer (``polar_cells``): ``log`` by default, the grid of before;
``acuity`` cells whose radial size follows the minimum angle of resolution at the viewer's
pixels per degree, the same grid in every pass, the budget met, a frame that renders, and bad
input in one line."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from kernel_counts import compiled_by

from foveated_mi.configure import sampling_settings
from foveated_mi.frame import buffer_space
from foveated_mi.frame.cells import (_traced_pixels, cell_offset, fovea_radius, foveal_grid,
                                     sensor_ppd)
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.kernels.polar import polar_grid_of
from foveated_mi.options import validate_options
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError
from foveated_mi.viewer import pixels_per_degree

#: Guenter et al. 2012's minimum angle of resolution, as the task states it (not the module's
#: constants): omega(e) = OMEGA0 + SLOPE e, degrees.
OMEGA0, SLOPE = 1.0 / 48.0, 0.022
EPS32 = 2.0 ** -24


def _scene(size=(64, 48), fov=None):
    scene = load_scene("cornell-box", width=size[0], height=size[1], spp=1,
                       integrator={"type": "path", "max_depth": 3})
    if fov is not None:
        params = mi.traverse(scene)
        key = next(k for k in params.keys() if k.endswith("x_fov"))
        params[key] = fov
        params.update()
    return scene


def _frame(scene, **options):
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", **options)
    image = np.array(mi.render(scene, integrator=integ, seed=3))
    return integ, image


# -- the default ----------------------------------------------------------------------------

@pytest.mark.parametrize("size,budget,before", [
    # (angles, rings, pitch, fovea) of foveal_grid on the tree before the option existed.
    ((96, 64), 0.1, (38, 22, 1.430800850422232, 8.653323061113573)),
    ((64, 48), 0.25, (52, 30, 0.7249829200593696, 6.0)),
])
def test_the_default_cells_are_the_grid_of_before(size, budget, before):
    W, H = size
    o = validate_options({"preset": "vr", "ray_budget": budget})
    assert o["polar_cells"] == "log" and o["viewer_ppd"] == 0.0
    assert cell_offset(sampling_settings(o)) == 0.0
    g = foveal_grid(W, H, budget, fovea_radius(W, H, o["theta"]),
                    cell_offset(sampling_settings(o)))
    assert (g.width, g.height, g.pitch, g.fovea, g.offset) == (*before, 0.0)
    assert buffer_space.layout(W, H, o["theta"], budget) == \
        buffer_space.layout(W, H, o["theta"], budget, 0.0)


def test_log_cells_ignore_the_viewer_and_render_the_default_frame():
    scene = _scene()
    _, default = _frame(scene)
    _, explicit = _frame(scene, polar_cells="log", viewer_ppd=40.0)
    assert np.array_equal(default, explicit)


# -- acuity cells ---------------------------------------------------------------------------

def _ring_edges(grid, rings, W, H):
    """Film distance from the gaze of the inner and outer edge of each ring of ``rings`` (on
    the device, in float32, through the grid's own position_of), along angle 0.3 rad."""
    g = mi.Point2f(W / 2.0, H / 2.0)
    u = mi.Float(np.array([[k, k + 1] for k in rings], np.float32).ravel())
    v = dr.full(mi.Float, 0.3 * grid.width / (2 * math.pi), dr.width(u))
    p = grid.position_of(mi.Point2f(v, u), g)
    r = np.array(dr.norm(p - g), np.float64).reshape(-1, 2)
    return r[:, 0], r[:, 1] - r[:, 0], max(W, H)


def _intercept(r, w):
    """c of the line w = a (r + c) through two (inner edge, width) pairs."""
    return (w[0] * r[1] - w[1] * r[0]) / (w[1] - w[0])


def _edge_error(r, w, c, scale):
    """How far float32 moves a ring's edge: an exp (of an argument of a few units) times its
    distance plus c, minus c, turned by a cosine and a sine around a gaze ``scale`` pixels from
    the origin and measured back from it; 16 roundings of the largest term bound it."""
    return 16 * EPS32 * (r + w + c + scale)


def _intercept_tolerance(r, w, c, scale):
    """How far the edges' float32 errors move the intercept (a width errs by two edges')."""
    e = [_edge_error(ri, wi, c, scale) for ri, wi in zip(r, w)]
    den = abs(w[1] - w[0])
    return (abs(r[1] + c) * 2 * e[0] + abs(r[0] + c) * 2 * e[1] + w[1] * e[0] + w[0] * e[1]) / den


@pytest.mark.parametrize("ppd", [8.0, 30.0])
def test_acuity_cells_grow_with_eccentricity_at_the_acuity_slope(ppd):
    W, H = 96, 64
    o = validate_options({"preset": "vr", "polar_cells": "acuity", "viewer_ppd": ppd})
    c = cell_offset(sampling_settings(o))
    assert c == pytest.approx(OMEGA0 / SLOPE * ppd, rel=1e-12)
    grid = foveal_grid(W, H, o["ray_budget"], fovea_radius(W, H, o["theta"]), c)
    assert grid.offset == c
    # Two rings outside the disc, one near it, one far out, still on the film.
    u0 = int(math.ceil(grid._u_of_r(np.float64(grid.fovea)))) + 1
    u1 = int(math.floor(grid._u_of_r(np.float64(0.45 * H))))
    assert u1 >= u0 + 2
    r, w, scale = _ring_edges(grid, (u0, u1), W, H)
    # A cell's radial size, in degrees, is a (e + omega0 / m) = (a / m) omega(e): the line's
    # intercept in pixels is omega0 / m degrees at the viewer's pixels per degree.
    tol = _intercept_tolerance(r, w, c, scale)
    assert tol < 0.05 * c
    assert abs(_intercept(r, w) - OMEGA0 / SLOPE * ppd) <= tol, (_intercept(r, w), tol)
    # The slope: rings pitch / (r0 + c) apart in log(r + c), so a ring at eccentricity e
    # (degrees) spans (e + omega0 / m) (exp(pitch / (r0 + c)) - 1) degrees.
    e = r / ppd
    slope = math.expm1(grid.pitch / (grid.fovea + c))
    np.testing.assert_allclose(w / ppd, (e + OMEGA0 / SLOPE) * slope, rtol=0,
                               atol=2 * np.max(_edge_error(r, w, c, scale)) / ppd)


def test_log_cells_grow_in_proportion_to_the_distance():
    # The same measure on log-polar cells finds no intercept: the test above can fail.
    W, H = 96, 64
    grid = foveal_grid(W, H, 0.1, fovea_radius(W, H, 0.15))
    u0 = int(math.ceil(grid._u_of_r(np.float64(grid.fovea)))) + 1
    u1 = int(math.floor(grid._u_of_r(np.float64(0.45 * H))))
    r, w, scale = _ring_edges(grid, (u0, u1), W, H)
    assert abs(_intercept(r, w)) <= _intercept_tolerance(r, w, 0.0, scale)
    assert _intercept_tolerance(r, w, 0.0, scale) < 0.05 * OMEGA0 / SLOPE * 8.0


def test_the_sensors_pixels_per_degree_at_its_centre_set_the_offset():
    offsets = []
    for fov in (40.0, 100.0):
        scene = _scene((64, 48), fov=fov)
        sensor = scene.sensors()[0]
        integ, image = _frame(scene, polar_cells="acuity")
        ppd = pixels_per_degree(sensor, (0.5, 0.5))
        assert sensor_ppd(sensor) == ppd
        plan = integ.views[0].primal.plan
        formed = integ.views[0].primal.formation.settings
        offsets.append(plan.space.layout.grid.offset)
        assert offsets[-1] == pytest.approx(OMEGA0 / SLOPE * ppd, rel=1e-12)
        # The plan's samples and the formation's are one grid.
        assert plan.space.layout == formed.layout
        assert np.isfinite(image).all()
    # A wider field of view puts fewer pixels in a degree: a smaller offset.
    assert offsets[1] < 0.5 * offsets[0]


def test_a_new_field_of_view_is_measured_anew():
    scene = _scene((64, 48), fov=40.0)
    sensor = scene.sensors()[0]
    narrow = sensor_ppd(sensor)
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("x_fov"))
    params[key] = 100.0
    params.update()
    wide = sensor_ppd(sensor)
    assert wide == pixels_per_degree(sensor, (0.5, 0.5))
    assert wide < 0.5 * narrow


def test_the_traced_pixels_meet_the_budget_as_far_as_the_bisection_allows():
    W, H, budget = 96, 64, 0.1
    o = validate_options({"preset": "vr", "polar_cells": "acuity", "viewer_ppd": 12.0})
    c = cell_offset(sampling_settings(o))
    r0 = fovea_radius(W, H, o["theta"])
    grid = foveal_grid(W, H, budget, r0, c)
    target = budget * W * H
    # The bisection returns the finest cells at or under the budget: a hair finer is over it.
    assert _traced_pixels(grid, W, H) <= target
    finer = polar_grid_of(W, H, r0, grid.pitch * (1 - 1e-9), offset=c)
    assert _traced_pixels(finer, W, H) > target
    # A frame's rays, in the buffer and on the film, as in the vr preset's test of its budget.
    for space in ("buffer", "film"):
        integ, image = _frame(_scene((W, H)), polar_cells="acuity", viewer_ppd=12.0,
                              ray_budget=budget, foveal_space=space)
        rays = integ.stats["rays"]
        assert abs(rays - target) <= max(0.02 * target, grid.height), (space, rays, target)
        assert np.isfinite(image).all()


# -- frames ---------------------------------------------------------------------------------

@pytest.mark.parametrize("options", [
    {"foveal_space": "buffer"},
    {"foveal_space": "film"},
    {"formation": "film"},          # the polar law's map under the film formation
])
def test_a_frame_with_acuity_cells_renders(options):
    scene = _scene((64, 48))
    integ, image = _frame(scene, polar_cells="acuity", **options)
    assert image.shape == (48, 64, 3) and np.isfinite(image).all()
    assert float(np.mean(image)) > 0.0
    # The traced pixels are the map's: the cells' pixels and the disc.
    assert integ.stats["rays"] > 0


def test_a_moving_gaze_compiles_nothing_from_frame_3():
    scene = _scene()
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", polar_cells="acuity")
    compiled = []
    for k in range(6):
        integ.gaze = (0.3 + 0.07 * k, 0.6 - 0.05 * k)
        compiled.append(compiled_by(lambda: np.array(mi.render(scene, integrator=integ,
                                                               seed=k))))
    assert compiled[3:] == [0, 0, 0], compiled


# -- bad input ------------------------------------------------------------------------------

@pytest.mark.parametrize("options,name", [
    ({"polar_cells": "square"}, "polar_cells"),
    ({"polar_cells": 1}, "polar_cells"),
    ({"polar_cells": "acuity", "viewer_ppd": -1.0}, "viewer_ppd"),
    ({"polar_cells": "acuity", "viewer_ppd": float("nan")}, "viewer_ppd"),
    ({"polar_cells": "acuity", "viewer_ppd": float("inf")}, "viewer_ppd"),
    ({"polar_cells": "acuity", "viewer_ppd": 1e6}, "viewer_ppd"),
    ({"polar_cells": "acuity", "viewer_ppd": "many"}, "viewer_ppd"),
    ({"preset": "guided", "polar_cells": "acuity"}, "polar_cells"),
])
def test_bad_input_is_one_line(options, name):
    with pytest.raises(ParameterError) as e:
        validate_options({"preset": "vr", **options})
    assert e.value.name == name and "\n" not in str(e.value)


def test_acuity_cells_without_a_viewer_need_a_sensor():
    law = sampling_settings(validate_options({"preset": "vr", "polar_cells": "acuity"}))
    with pytest.raises(ParameterError) as e:
        cell_offset(law)
    assert e.value.name == "viewer_ppd" and "\n" not in str(e.value)
