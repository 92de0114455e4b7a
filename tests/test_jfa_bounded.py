"""Jump flooding bounded by the sampling law's largest gap equals the full step sequence on maps
drawn from the law, and its fallback finds the nearest site where the bound was wrong."""
import numpy as np
import pytest

import drjit as dr
import mitsuba as mi

from foveated_mi.reconstruct.jfa import NO_SITE, jfa_steps, jump_flood
from foveated_mi.frame.sampling import largest_gap, sampling_map

W, H = 96, 64


@pytest.mark.parametrize("theta, sigma_p, gaze", [
    (0.1, 0.8, (0.5, 0.5)),       # the paper's defaults
    (0.1, 1e-6, (0.5, 0.5)),      # sigma_p -> 0: no bound, the full sequence
    (1e-4, 0.8, (0.3, 0.7)),      # tiny fovea: a single ray far from most pixels
    (50.0, 0.8, (0.5, 0.5)),      # huge fovea: nearly every pixel traced
    (0.2, 0.5, (1.4, -0.3)),      # gaze off-screen
])
@pytest.mark.parametrize("variant", ["jfa", "jfa+1"])
def test_bounded_equals_full_on_maps_of_the_law(theta, sigma_p, gaze, variant):
    gap = largest_gap(W, H, gaze=gaze, theta=theta, sigma_p=sigma_p)
    for seed in range(3):
        smap, _ = sampling_map(W, H, gaze=gaze, theta=theta, sigma_p=sigma_p, seed=seed)
        full = jump_flood(smap, W, H, variant).numpy()
        bounded = jump_flood(smap, W, H, variant, max_gap=gap).numpy()
        np.testing.assert_array_equal(bounded, full)


def test_bound_shortens_the_sequence_where_the_law_allows():
    gap = largest_gap(1024, 1024, gaze=(0.5, 0.5), theta=0.057, sigma_p=0.8)
    assert gap is not None and gap < 128
    assert len(jfa_steps(1024, 1024, "jfa", gap)) < len(jfa_steps(1024, 1024, "jfa"))
    assert largest_gap(W, H, gaze=(0.5, 0.5), theta=0.1, sigma_p=1e-6) is None
    assert largest_gap(W, H, gaze=(0.5, 0.5), theta=0.1, sigma_p=1.0) == 1.0


def _nearest_brute(mask: np.ndarray) -> np.ndarray:
    ys, xs = np.nonzero(mask)
    yy, xx = np.mgrid[0:mask.shape[0], 0:mask.shape[1]]
    d2 = (yy[..., None] - ys) ** 2 + (xx[..., None] - xs) ** 2
    return d2.min(-1)


def test_fallback_finds_sites_beyond_a_wrong_bound():
    # One site in a corner and a claimed gap of 3 px: the bounded passes cannot reach most
    # pixels; the ring search must still give each pixel within 12 px its nearest site.
    mask = np.zeros((H, W), bool)
    mask[2, 3] = True
    mask[40, 80] = True
    near = jump_flood(mi.Bool(mask.ravel()), W, H, "jfa", max_gap=3.0).numpy().reshape(H, W)
    yy, xx = np.mgrid[0:H, 0:W]
    found = near != NO_SITE
    d2 = (near // W - yy) ** 2 + (near % W - xx) ** 2
    exact = _nearest_brute(mask)
    reach = exact <= 12 ** 2
    assert found[reach].all()
    np.testing.assert_array_equal(d2[reach], exact[reach])


def test_empty_map_stays_without_sites():
    near = jump_flood(dr.zeros(mi.Bool, W * H), W, H, "jfa+1", max_gap=4.0).numpy()
    assert (near == NO_SITE).all()
