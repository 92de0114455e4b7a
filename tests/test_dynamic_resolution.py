"""Dynamic resolution as a uniform family (the film traced at a render scale, upscaled
bilinearly), and the envelope of the families that ran, named with what sets it."""
import json
import math

import numpy as np
import pytest

import mitsuba as mi

from foveated_mi import denoise as D
from foveated_mi.baselines import render_uniform, scaled_size, upscale_bilinear
from foveated_mi.scenes import load_scene
from foveated_mi.study import parse_study
from foveated_mi.study.equal_time import envelope_label, envelope_over_seeds, family_of
from foveated_mi.study.tasks import expand_tasks, run_task, task_id
from foveated_mi.validate import ParameterError

needs_oidn = pytest.mark.skipif(not D.oidn_available(), reason="pyoidn not installed")

#: Half an ulp of float32, relative: |fl(x) - x| <= U |x|.
U = 2.0 ** -24


def _box(width, height):
    return load_scene("cornell-box", width=width, height=height,
                      integrator={"type": "path", "max_depth": 4})


# ---------------------------------------------------------------------------------------------
# the upscale
# ---------------------------------------------------------------------------------------------

def _sources(n_out, n_in):
    """Where output pixels sample the input (pixel centres aligned), unclamped."""
    return (np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5


def test_a_constant_image_stays_that_constant_exactly():
    img = np.empty((7, 5, 3), np.float32)
    img[...] = np.float32([0.1, 3.7, 1e-3])
    out = upscale_bilinear(img, (12, 17))
    assert out.shape == (17, 12, 3) and out.dtype == np.float32
    # a + (b - a) * f with a == b is a, bit for bit
    assert np.array_equal(out, np.broadcast_to(img[:1, :1], out.shape))


def test_a_linear_image_is_reproduced_away_from_the_border():
    """A plane is exact under bilinear interpolation wherever the source position needs no
    clamp; what is left is float32 rounding: the input rounded once (U M), then in each of
    the two passes f, b - a, (b - a) f and the sum rounded (at most 2UM, 2UM, 2UM and UM
    with |b - a| <= 2M): 15 U M in all, M the largest magnitude. The border pixels repeat
    the edge sample."""
    h, w, H, W = 13, 23, 18, 32                       # a scale of about 0.71
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    coef = np.array([[0.3, 0.05, -0.02], [1.0, -0.01, 0.03], [0.0, 0.002, 0.001]])
    plane = lambda yy, xx: np.stack([c[0] + c[1] * xx + c[2] * yy for c in coef], -1)  # noqa
    img = plane(y, x).astype(np.float32)
    out = upscale_bilinear(img, (W, H)).astype(np.float64)
    v, u = _sources(H, h), _sources(W, w)
    want = plane(*np.meshgrid(v, u, indexing="ij"))
    inner = ((v >= 0) & (v <= h - 1))[:, None] & ((u >= 0) & (u <= w - 1))[None, :]
    assert inner.sum() > 0.7 * H * W
    M = np.abs(img).max()
    assert np.abs(out - want)[inner].max() <= 15 * U * M
    # The columns left of the first sample's centre repeat input column 0, interpolated
    # down the rows only.
    left = u < 0
    edge = upscale_bilinear(img[:, :1], (1, H))
    assert left.sum() == 1 and np.array_equal(out[:, left].astype(np.float32), edge)


def test_a_smooth_image_meets_the_interpolation_bound():
    """g = x^2 in source pixels: linear interpolation between two samples errs by
    t (1 - t) g'' / 2 at fraction t, within the bound g'' / 8. Doubling the width samples at
    u = x / 2 - 1/4, the fractions 1/4 and 3/4, so the error is 3/16 exactly (rounding of
    15 U M aside) wherever u needs no clamp; an interpolation that aligned the corners
    instead would sample other fractions."""
    w = 16
    img = np.repeat((np.arange(w, dtype=np.float64) ** 2)[None, :, None], 3, 2)
    img = np.repeat(img, 4, 0).astype(np.float32)
    out = upscale_bilinear(img, (2 * w, 8))[..., 0].astype(np.float64)
    u = _sources(2 * w, w)
    inner = (u >= 0) & (u <= w - 1)
    err = out[:, inner] - u[inner] ** 2
    assert np.all(np.abs(err - 3 / 16) <= 15 * U * (w - 1) ** 2)
    assert np.all(err <= 2.0 / 8)                    # the bound, g'' / 8 with g'' = 2


def test_bad_sizes_and_scales_are_one_line():
    for call, name in ((lambda: upscale_bilinear(np.zeros((4, 4)), (8, 8)), "image"),
                       (lambda: upscale_bilinear(np.zeros((4, 4, 3)), (8, 0)), "size"),
                       (lambda: upscale_bilinear(np.zeros((4, 4, 3)), 8), "size"),
                       (lambda: scaled_size((64, 36), 0.0), "scale"),
                       (lambda: scaled_size((64, 36), 1.5), "scale")):
        with pytest.raises(ParameterError) as e:
            call()
        assert str(e.value).startswith(f"{name} = ") and "\n" not in str(e.value)
    assert scaled_size((1152, 648), 0.71) == (818, 460)
    assert scaled_size((3, 3), 0.01) == (1, 1)


# ---------------------------------------------------------------------------------------------
# the uniform frame at a scale
# ---------------------------------------------------------------------------------------------

def test_a_constant_scene_renders_constant_at_any_scale():
    """Only a constant environment, a box filter and 1 spp: every pixel of the traced film
    is the emitter's radiance exactly, and so is every pixel of the upscaled frame."""
    value = [0.25, 0.5, 0.75]
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 60,
                   "film": {"type": "hdrfilm", "width": 40, "height": 24,
                            "rfilter": {"type": "box"}}},
        "emitter": {"type": "constant", "radiance": {"type": "rgb", "value": value}}})
    img, stats = render_uniform(scene, spp=1, seed=1, scale=0.5)
    assert img.shape == (24, 40, 3) and stats["size"] == (20, 12)
    assert np.array_equal(img, np.broadcast_to(np.float32(value), img.shape))


def test_scale_1_is_today_s_frame_bit_for_bit():
    box = _box(32, 24)
    today, s0 = render_uniform(box, spp=2, seed=3)
    one, s1 = render_uniform(box, spp=2, seed=3, scale=1.0)
    assert np.array_equal(today, one) and np.array_equal(one, np.array(mi.render(box, spp=2,
                                                                                   seed=3)))
    assert "scale" not in s1 and "upscale_ms" not in s1 and s1["time_ms"] == s1["render_ms"]


def test_a_scaled_frame_is_the_smaller_film_upscaled():
    """At scale 0.5 a 64x48 film traces what a 32x24 film of the same camera traces (the same
    samples, bit for bit), upscaled; the film is restored after the frame; the time counts
    the upscale."""
    big, small = _box(64, 48), _box(32, 24)
    before, _ = render_uniform(big, spp=2, seed=5)
    img, stats = render_uniform(big, spp=2, seed=5, scale=0.5)
    low = np.array(mi.render(small, spp=2, seed=5), dtype=np.float32)[..., :3]
    assert np.array_equal(img, upscale_bilinear(low, (64, 48)))
    assert stats["size"] == (32, 24) and stats["scale"] == 0.5
    assert stats["time_ms"] == stats["render_ms"] + stats["upscale_ms"]
    assert stats["upscale_ms"] > 0
    assert list(big.sensors()[0].film().size()) == [64, 48]
    after, _ = render_uniform(big, spp=2, seed=5)
    assert np.array_equal(before, after)
    with pytest.raises(ParameterError, match=r"^scale = 0 is invalid"):
        render_uniform(big, spp=1, scale=0)


@needs_oidn
def test_a_scaled_denoised_frame_is_denoised_before_the_upscale():
    big, small = _box(64, 48), _box(32, 24)
    img, stats = render_uniform(big, spp=1, seed=2, scale=0.5, denoise=True)
    low, _ = render_uniform(small, spp=1, seed=2, denoise=True)
    assert np.array_equal(img, upscale_bilinear(low, (64, 48)))
    assert stats["time_ms"] == pytest.approx(stats["render_ms"] + stats["aov_ms"]
                                             + stats["denoise_ms"] + stats["upscale_ms"],
                                             rel=1e-12)


# ---------------------------------------------------------------------------------------------
# the study
# ---------------------------------------------------------------------------------------------

def _study(uniform):
    return parse_study({"seed": 0, "size": [32, 18],
                        "scenes": [{"scene": "cornell-box", "integrator": {"type": "path",
                                                                          "max_depth": 3}}],
                        "foveated": {"configs": [{"preset": "paper"}]},
                        "uniform": uniform})


def test_the_study_expands_scales_into_their_own_families():
    base = _study({"spp": [1], "denoise": [False, True]})
    spec = _study({"spp": [1], "denoise": [False, True], "scale": [0.5, 1]})
    tasks = [t for t in expand_tasks(spec, "llvm_ad_rgb") if t["kind"] == "uniform"]
    assert [t["method"] for t in tasks] == ["uniform@0.5", "uniform+oidn@0.5", "uniform",
                                            "uniform+oidn"]
    assert [t["options"].get("scale") for t in tasks] == [0.5, 0.5, None, None]
    assert json.loads(tasks[0]["config"])["method"] == "uniform@0.5"
    # Scale 1 keeps the ids a study without a scale had (and has: the same payload).
    old = [t for t in expand_tasks(base, "llvm_ad_rgb") if t["kind"] == "uniform"]
    assert [t["task_id"] for t in tasks[2:]] == [t["task_id"] for t in old]
    ident = base.scenes[0].identity()
    assert old[0]["task_id"] == task_id(ident, "uniform", {"denoise": False}, 1, 0,
                                        "llvm_ad_rgb", dict(base.metrics))
    assert len({t["task_id"] for t in tasks}) == 4


def test_a_scaled_row_traces_the_smaller_film():
    spec = _study({"spp": [2], "scale": [0.5]})
    task, = [t for t in expand_tasks(spec, "llvm_ad_rgb") if t["kind"] == "uniform"]
    row, = run_task(task, np.zeros((18, 32, 3), np.float32))
    assert row["method"] == "uniform@0.5" and row["scale"] == 0.5
    assert (row["width"], row["height"]) == (32, 18)
    assert row["rays"] == 16 * 9 and row["ray_fraction"] == 16 * 9 / (32 * 18)
    assert row["samples"] == 16 * 9 * 2 and row["upscale_ms"] > 0


@pytest.mark.parametrize("scale,key", [(0, "uniform.scale"), (1.5, "uniform.scale"),
                                       ("x", "uniform.scale"), ([0.5, "x"], "uniform.scale[1]"),
                                       ([], "uniform.scale"), (True, "uniform.scale"),
                                       (math.nan, "uniform.scale")])
def test_bad_scales_are_one_line(scale, key):
    with pytest.raises(ParameterError) as e:
        _study({"spp": [1], "scale": scale})
    msg = str(e.value)
    assert f": {key} = " in msg and "> 0 and <= 1" in msg and "\n" not in msg


def test_a_scale_applies_to_the_rows_without_history():
    """Every family in one study: raw and + OIDN at each scale, history rows at full
    resolution; a scale with history rows alone, or history without scale 1, is one line."""
    spec = _study({"spp": [1], "history": [False, True], "scale": [0.5, 1]})
    rows = [(u["history"], u.get("scale", 1.0)) for u in spec.uniform]
    assert sorted(set(rows)) == [(False, 0.5), (False, 1.0), (True, 1.0)]
    for table in ({"spp": [1], "history": [True], "scale": [0.5, 1]},
                  {"spp": [1], "history": [False, True], "scale": [0.5]}):
        with pytest.raises(ParameterError) as e:
            _study(table)
        assert ": uniform.scale = " in str(e.value) and "full resolution" in str(e.value)
        assert "\n" not in str(e.value)


# ---------------------------------------------------------------------------------------------
# the envelope, named
# ---------------------------------------------------------------------------------------------

def _cell(method, spp, ms, jod, seeds=(0, 1), options=None):
    rows = [{"scene": "s", "method": method, "spp": float(spp), "frame": 6.0,
             "seed": float(s), "time_ms": ms, "jod_video": jod,
             "config": json.dumps({"options": options or {}})} for s in seeds]
    return dict(rows[0], rows=rows, seeds=len(rows))


def test_the_family_that_sets_the_envelope_changes_with_the_quality():
    """Uniform + OIDN is cheap and flat (7.0 at 10 ms, 7.5 at 20 ms); uniform + history dear
    and steep (7.6 at 30 ms, 9.0 at 60 ms). At JOD 7.2 OIDN's curve sets the envelope
    (10 ms * 2^(0.2/0.5)), at 8.5 the history's (30 ms * 2^(0.9/1.4)), where OIDN never gets."""
    oidn = [_cell("uniform+oidn", 1, 10.0, 7.0), _cell("uniform+oidn", 4, 20.0, 7.5)]
    hist = [_cell("uniform+history", 1, 30.0, 7.6), _cell("uniform+history", 4, 60.0, 9.0)]
    low = _cell("foveated", 1, 5.0, 7.2, options={"preset": "vr"})
    high = _cell("foveated", 2, 10.0, 8.5, options={"preset": "vr"})
    a = envelope_over_seeds(low, [oidn, hist], "jod_video")
    b = envelope_over_seeds(high, [oidn, hist], "jod_video")
    assert a.ratio == pytest.approx(10.0 * 2 ** (0.2 / 0.5) / 5.0, rel=1e-12)
    assert b.ratio == pytest.approx(30.0 * 2 ** (0.9 / 1.4) / 10.0, rel=1e-12)
    assert a.family == "uniform+oidn 1-4 spp" and b.family == "uniform+history 1-4 spp"
    assert a.per_seed_family == [a.family] * 2 and b.per_seed_family == [b.family] * 2
    # Seed by seed: where seed 1's history row takes 8 ms, its cheapest cell already
    # reaches 7.2 and sets that seed's envelope.
    hist[0]["rows"][1] = dict(hist[0]["rows"][1], time_ms=8.0)
    c = envelope_over_seeds(low, [oidn, hist], "jod_video")
    assert c.per_seed_family == ["uniform+oidn 1-4 spp", "uniform+history 1 spp"]
    assert c.per_seed[1] == (8.0 / 5.0, "<")
    # Where the joint front is the cheapest, it is named by the two cells it runs between:
    # 4 ms * 2.5^(1.5/2) from raw 1 spp (5.0) to OIDN 1 spp (7.0), below OIDN's 10 ms.
    raw = [_cell("uniform", 1, 4.0, 5.0)]
    d = envelope_over_seeds(_cell("foveated", 1, 5.0, 6.5, options={"preset": "vr"}),
                            [raw, oidn], "jod_video")
    assert d.family == "front of uniform 1 spp and uniform+oidn 1 spp"
    assert d.ratio == pytest.approx(4.0 * 2.5 ** 0.75 / 5.0, rel=1e-12)


def test_the_label_names_the_families_that_ran():
    five = ["uniform", "uniform+oidn", "uniform+history", "uniform+history+oidn",
            "uniform@0.5"]
    assert envelope_label(five) == "every uniform family"
    assert envelope_label(five + ["flat vr"]) == "every uniform family and flat vr"
    for k in range(5):                       # any kind missing: the families, each named
        rest = five[:k] + five[k + 1:]
        label = envelope_label(rest)
        assert "every" not in label and label.startswith("envelope of ")
        assert sorted(label[len("envelope of "):].replace(" and ", ", ").split(", ")) == \
            sorted(rest)
    assert envelope_label(["uniform+oidn@0.71", "uniform"]) == \
        "envelope of uniform and uniform+oidn@0.71"
    # A second history denoiser counts as + history + denoiser too.
    assert envelope_label(five[:3] + ["uniform+history+svgf", "uniform+oidn@0.5"]) == \
        "every uniform family"
    with pytest.raises(ParameterError):
        envelope_label([])


def test_families_come_from_the_rows():
    assert family_of({"method": "uniform+oidn@0.5", "config": "{}"}) == "uniform+oidn@0.5"
    flat = {"method": "foveated", "config": json.dumps({"options": {"preset": "vr",
                                                                    "sampling_law": "flat"}})}
    assert family_of(flat) == "flat vr"
    assert family_of({"method": "foveated", "config": json.dumps(
        {"options": {"preset": "vr"}})}) is None
