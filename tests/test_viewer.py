"""The viewer in degrees: eccentricity from the sensor's own projection, Eq. 1 in degrees
(``theta_deg``) and the acuity law with its ray budget (:mod:`foveated_mi.viewer`)."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from foveated_mi import viewer
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.validate import ParameterError


def _sensor(fov, axis, w, h, target=(0, 0, 1)):
    return mi.load_dict({
        "type": "perspective", "fov": fov, "fov_axis": axis,
        "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=list(target),
                                                   up=[0, 1, 0]),
        "film": {"type": "hdrfilm", "width": w, "height": h}})


def _analytic(fov, axis, w, h, gaze):
    """Angles between pixel-centre rays and the gaze ray of a pinhole camera (camera space:
    film x runs against camera x in Mitsuba's convention, which the angle does not see)."""
    t = math.tan(math.radians(fov) / 2)
    tx, ty = (t, t * h / w) if axis == "x" else (t * w / h, t)
    ys, xs = np.mgrid[0:h, 0:w] + 0.5

    def ray(u, v):
        return np.stack(np.broadcast_arrays((1 - 2 * u) * tx, (1 - 2 * v) * ty, 1.0), -1)

    p, g = ray(xs / w, ys / h), ray(np.float64(gaze[0]), np.float64(gaze[1]))
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(p, g), axis=-1), (p * g).sum(-1)))


@pytest.mark.parametrize("axis", ["x", "y"])
def test_eccentricity_is_the_angle_to_the_gaze_ray(axis):
    w, h, gaze = 40, 24, (0.3, 0.7)
    ecc = viewer.pixel_eccentricity(_sensor(100.0, axis, w, h), gaze).numpy().reshape(h, w)
    assert np.abs(ecc - _analytic(100.0, axis, w, h, gaze)).max() < 0.01


def _scene(fov=90.0, target=(0, 0, 1)):
    return mi.load_dict({
        "type": "scene", "sensor": _sensor_dict(fov, target),
        "integrator": {"type": "path", "max_depth": 2},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.5}},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate(
            [0, -1, 0]).rotate([1, 0, 0], -90).scale(20)}})


def _sensor_dict(fov, target):
    return {"type": "perspective", "fov": fov, "fov_axis": "x",
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=list(target),
                                                       up=[0, 1, 0]),
            "sampler": {"type": "independent", "sample_count": 1},
            "film": {"type": "hdrfilm", "width": 48, "height": 32}}


#: Roundings behind one float32 primary-ray direction (the sensor's sample_ray: film point,
#: inverse projection, camera-to-world transform, normalisation) and behind the angle between
#: two of them (cross product, norm, dot, atan2), in units of the unit roundoff.
RAY_ROUNDINGS, ANGLE_ROUNDINGS = 32, 16


def _angle_error_deg() -> float:
    """Bound on the rounding of an eccentricity: both rays' directions, then the angle."""
    return math.degrees(2 * tolerances.gamma(RAY_ROUNDINGS) + tolerances.gamma(ANGLE_ROUNDINGS))


def _rays(scene, **options):
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="paper", history=False,
                               edge_threshold=0.0, **options)
    np.array(mi.render(scene, integrator=integ, seed=3))
    return integ.stats["rays"], integ.buffer("probability")


def test_theta_deg_follows_the_viewer_not_the_camera():
    opts = dict(theta_deg=10.0, sigma_p=0.5, gaze=(0.4, 0.6))
    rays, prob = _rays(_scene(90.0), **opts)
    turned, prob_t = _rays(_scene(90.0, target=(0.7, 0.3, 1)), **opts)
    # The same eccentricities up to the rounding of the rotated rays, so P up to its slope
    # dP/de = -2 w e P^2 times that rounding (plus P's own few roundings).
    sensor = _scene(90.0).sensors()[0]
    ecc = viewer.pixel_eccentricity(sensor, opts["gaze"]).numpy().reshape(32, 48)
    w = (1 / opts["sigma_p"] - 1) / opts["theta_deg"] ** 2
    bound = 2 * w * ecc * prob ** 2 * _angle_error_deg() + tolerances.gamma(8)
    assert np.all(np.abs(prob_t - prob) <= bound)
    # A pixel flips only where its uniform draw lies within that bound of P: on average
    # sum(bound) pixels, far below one.
    assert bound.sum() < 0.1 and abs(turned - rays) <= 2, (rays, turned, bound.sum())
    narrow, _ = _rays(_scene(45.0), **opts)
    assert narrow > 1.5 * rays, (rays, narrow)
    # P = sigma_p at theta_deg: the pixels within half a degree of it differ from sigma_p by
    # at most the law's slope over that half degree.
    ring = np.abs(ecc - 10.0) < 0.5
    slope = 2 * w * 10.5 / (w * 9.5 ** 2 + 1) ** 2
    assert ring.any() and np.all(np.abs(prob[ring] - 0.5) <= 0.5 * slope)


@pytest.mark.parametrize("budget", [0.05, 0.2, 0.5])
def test_acuity_law_meets_its_budget_and_falls_with_eccentricity(budget):
    scene = _scene(100.0)
    _, prob = _rays(scene, sampling_law="acuity", ray_budget=budget, acuity_floor=0.01,
                    gaze=(0.35, 0.55))
    assert abs(prob.mean() - budget) <= 0.02 * budget, prob.mean()
    ecc = viewer.pixel_eccentricity(scene.sensors()[0], (0.35, 0.55)).numpy().ravel()
    p = prob.ravel()[np.argsort(ecc)]
    assert np.all(np.diff(p) <= 0) and p.min() >= np.float32(0.01) and p.max() <= 1.0


def test_a_moving_gaze_in_degrees_compiles_nothing():
    scene = _scene(90.0)
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="guided",
                               sampling_law="acuity", ray_budget=0.2)
    compiled = []
    for k in range(5):
        integ.gaze = (0.3 + 0.05 * k, 0.5)
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            np.array(mi.render(scene, integrator=integ, seed=k))
            hist = dr.kernel_history([dr.KernelType.JIT])
        compiled.append(sum(1 for h in hist if not h.get("cache_hit", True)))
    assert compiled[3:] == [0, 0], compiled


@pytest.mark.parametrize("options, key", [
    ({"sampling_law": "acuity", "ray_budget": 0.05, "acuity_floor": 0.1}, "acuity_floor"),
    ({"theta_deg": -1.0}, "theta_deg"),
    ({"sampling_law": "foveal"}, "sampling_law"),
    ({"ray_budget": 0.0}, "ray_budget"),
])
def test_bad_viewer_options_are_one_line(options, key):
    with pytest.raises(ParameterError) as e:
        FoveatedIntegrator(**options)
    assert e.value.name == key and "\n" not in str(e.value)


def test_pixels_per_degree_at_the_centre_of_a_headset_film():
    """1150 px across 90°: the centre pixel spans atan(2 tan(45°) / 1150) (about 10 ppd)."""
    ppd = viewer.pixels_per_degree(_sensor(90.0, "x", 1150, 16))
    pixel = math.degrees(math.atan(2.0 / 1150))
    # the rounding of an angle of one pixel, relative to it
    assert abs(ppd - 1.0 / pixel) <= ppd * _angle_error_deg() / pixel


def test_regions_in_degrees():
    from foveated_mi.metrics import compare
    sensor = _sensor(90.0, "x", 48, 32)
    ecc = viewer.eccentricity_map(sensor, (0.25, 0.5))
    ref = np.full((32, 48, 3), 0.5)
    test = ref.copy()
    test[ecc >= 5.0] += 0.1        # only the periphery (beyond 5 degrees) is wrong
    out = compare(ref, test, eccentricity=ecc, fovea_deg=5.0, flip=False)
    assert out["psnr_fovea"] == math.inf and math.isfinite(out["psnr_periphery"])
    assert 0 < (ecc < 5.0).sum() < ecc.size
    with pytest.raises(ParameterError, match="eccentricity"):
        compare(ref, test, eccentricity=ecc[:4], flip=False)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_horizontal_fov_is_the_sensors(axis):
    w, h, fov = 48, 32, 100.0
    expect = fov if axis == "x" else 2 * math.degrees(math.atan(math.tan(math.radians(fov / 2))
                                                                 * w / h))
    assert abs(viewer.horizontal_fov(_sensor(fov, axis, w, h)) - expect) <= _angle_error_deg()


@pytest.mark.parametrize("sigma_p", [0.5, 1.0])
def test_the_acuity_law_fills_its_untraced_pixels_whatever_sigma_p(sigma_p):
    # sigma_p belongs to Eq. 1 alone: at 1 it traces every pixel there, but the acuity law
    # traces its budget whatever it says, so its frame must still be reconstructed.
    scene = _scene()
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="paper", history=False,
                               sampling_law="acuity", ray_budget=0.2, sigma_p=sigma_p,
                               atrous_iterations=0)
    image = np.array(mi.render(scene, integrator=integ, seed=3))
    assert integ.stats["ray_fraction"] < 0.5
    # Sky and floor are lit everywhere: no pixel of a reconstructed frame is black.
    assert np.count_nonzero(image.max(axis=-1) <= 0.0) == 0
