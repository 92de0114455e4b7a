"""Backend parity: what could differ between ``llvm_ad_rgb`` and ``cuda_ad_rgb``.

Every test runs on the suite's variant (``FOVEATED_MI_VARIANT=cuda_ad_rgb make test`` on a
CUDA machine) and compares against a NumPy reference or an exact property, so that a backend
difference shows as a failure rather than as a different picture:

- Float64 accumulation (``scatter_add`` atomics of ``discrete_sibson``, the gather sums of
  ``sibson``, the summed-area table of ``fast_sibson``) on values whose Float32 sums are wrong;
- device-wide scans and atomics: ``dr.compress`` / ``dr.cumsum`` / ``dr.block_sum`` of the
  reorder pass, the one-entry ``scatter_reduce`` count of the camera-cut test;
- the traced-pixel sensor of the gradient pass against the source sensor at the same pixels;
- OIDN's device choice (a pure function) and the denoiser on the device it picks.

Kernel reuse under per-frame scalars (``dr.opaque``) is checked by
``tests/test_integrator.py::test_per_frame_scalars_compile_nothing_new``.
"""
import logging
import os
import sys

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from foveated_mi import denoise as D
from foveated_mi.frame import reproject
from foveated_mi.frame.pixel_filter import FilterSampler, SplatFootprint
from foveated_mi.reconstruct import (interleave_rgb0, jump_flood, reconstruct,
                                     summed_area_table)
from foveated_mi.frame.reorder import reorder
from foveated_mi.frame.traced_sensor import TracedSensors, flat_layout
from foveated_mi.validate import ParameterError

W, H = 32, 24
N = W * H
needs_oidn = pytest.mark.skipif(not D.oidn_available(), reason="pyoidn not installed")


# ----------------------------------------------------------------------------- Float64 sums
def cancelling_case(seed=0, density=0.08):
    """Sites valued in {+2^25, -2^25, 1, ..., 7} per channel: every partial sum is an integer
    below 2^53, so Float64 sums are exact whatever the order of the atomics, while Float32
    sums lose the small values next to the large ones (2^25 + 1 rounds to 2^25)."""
    rng = np.random.default_rng(seed)
    mask = rng.random(N) < density
    mask[[0, N - 1]] = True
    big = np.float32(2.0 ** 25)
    values = rng.choice(np.array([big, -big, 1, 2, 3, 5, 7], np.float32), size=(3, N))
    return mask, np.where(mask[None], values, np.float32(0)).astype(np.float32)


def backend_nearest(mask):
    """The nearest-site map from the backend's jump flood (the reference reuses it, so only
    the accumulation is compared)."""
    return jump_flood(mi.Bool(mask), W, H).numpy().astype(np.int64)


def test_the_cancelling_case_needs_float64():
    """The case above tells Float64 from Float32 sums (so the tests below can fail)."""
    _, values = cancelling_case()
    f = values.T.reshape(H, W, 3)
    exact = np.cumsum(np.cumsum(f.astype(np.float64), 0), 1)
    single = np.cumsum(np.cumsum(f, 0, dtype=np.float32), 1, dtype=np.float32)
    assert np.count_nonzero(exact != single) > N // 10


@pytest.mark.parametrize("method", ["sibson", "discrete_sibson", "fast_sibson"])
def test_float64_sums_match_numpy(method):
    """Exact Float64 sums give the NumPy Float64 result to one Float32 rounding (the final
    division may be rounded differently by a backend, never the sums)."""
    # The references of tests/test_interpolation.py (written from the definitions).
    ref = getattr(pytest.importorskip("test_interpolation"), "ref_" + method)
    mask, values = cancelling_case()
    nearest = backend_nearest(mask)
    out = reconstruct(method, mi.Color3f(values), mi.Bool(mask),
                      mi.UInt32(nearest.astype(np.uint32)), W, H, max_radius=8).numpy()
    want = ref(values, nearest, W, H, 8).astype(np.float32)
    np.testing.assert_array_max_ulp(out, want, maxulp=1)


def test_summed_area_table_is_exact():
    """The Float64 table (column walk, then ``dr.prefix_reduce`` along rows) equals NumPy's
    cumulative sums exactly, and its channel bounds are the channel extrema."""
    _, values = cancelling_case(seed=1)
    table, lo, hi = summed_area_table(interleave_rgb0(mi.Color3f(values)), W, H)
    f = values.reshape(3, H, W).astype(np.float64)
    want = np.cumsum(np.cumsum(f, 1), 2)
    np.testing.assert_array_equal(table.numpy().reshape(3, H, W), want)
    np.testing.assert_array_equal(lo.numpy(), values.min(axis=1))
    np.testing.assert_array_equal(hi.numpy(), values.max(axis=1))


# ----------------------------------------------------------------------------- scans, atomics
@pytest.mark.parametrize("w,h,frac", [(W, H, 0.3), (128, 96, 0.07), (128, 96, 0.9)])
def test_reorder_launch_order_matches_numpy(w, h, frac):
    """``compact`` (``dr.compress``) and the active lanes of ``rows`` (``dr.cumsum``,
    ``dr.block_sum``) launch the traced pixels in row-major order, with the right count per
    row."""
    m = np.random.default_rng(3).random(w * h) < frac
    want = np.flatnonzero(m)
    for mode in ("compact", "rows"):
        r = reorder(mi.Bool(m), w, h, mode)
        lanes = r.wavefront.numpy()
        if r.active is not None:
            lanes = lanes[r.active.numpy()]
        np.testing.assert_array_equal(lanes, want, err_msg=mode)
    counts = reorder(mi.Bool(m), w, h, "rows").row_counts.numpy()
    np.testing.assert_array_equal(counts, m.reshape(h, w).sum(axis=1))


@pytest.mark.parametrize("frac", [0.05, 0.5])
def test_camera_cut_count_matches_numpy(frac):
    """The one-entry atomic count of history hits decides a cut as NumPy does."""
    hit = np.random.default_rng(4).random(N) < frac
    total = int(hit.sum())
    rmap = reproject.ReprojectionMap(dr.zeros(mi.Point2f, N), mi.Bool(hit),
                                     dr.zeros(mi.UInt32, N))
    for fraction in (total / N - 0.01, total / N + 0.01):
        kept, cut = reproject.unless_cut(rmap, fraction)
        want_cut = total < fraction * N
        assert bool(cut.numpy()[0]) == want_cut
        np.testing.assert_array_equal(kept.hit.numpy(), hit & (not want_cut))


# ----------------------------------------------------------------------------- traced sensor
@pytest.mark.parametrize("rfilter,kind", [("box", "uniform"), ("gaussian", "importance"),
                                          ("mitchell", "splat")])
def test_traced_sensor_rays_equal_the_source_sensor_rays(rfilter, kind):
    """A flat pixel's ray (through the traced-pixel sensor) equals the source sensor's ray at
    the same traced pixel and footprint sample: origin, direction, differentials, weight."""
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=W, height=H, rfilter={"type": rfilter})
    src = mi.load_dict(d).sensors()[0]
    film = src.film()
    rng = np.random.default_rng(5)
    traced_mask = rng.random(N) < 0.3
    pixels = rng.permutation(np.flatnonzero(traced_mask))[:60]
    if kind == "splat":
        fp, traced = SplatFootprint(film), mi.Bool(traced_mask)
    else:
        fp, traced = FilterSampler(film, importance=kind == "importance"), None
    sensor, lay = TracedSensors().get(src, mi.UInt32(pixels), fp, traced)
    # Powers of two: a flat film position and its jitter convert exactly both ways.
    assert lay == flat_layout(60) == (8, 8)
    spp = 4
    k = np.repeat(np.arange(lay.width * lay.height), spp)
    u = rng.integers(0, 256, (2, k.size)) / 256.0
    flat = mi.Point2f((k % lay.width + u[0]) / lay.width, (k // lay.width + u[1]) / lay.height)
    time, s1, s3 = mi.Float(0.25), mi.Float(0.5), mi.Point2f(0.5)
    got, got_w = sensor.sample_ray_differential(time, s1, flat, s3)

    # The same pixels through the source sensor (padding repeats the last traced pixel).
    pix = np.concatenate([pixels, np.full(lay.width * lay.height - 60, pixels[-1])])[k]
    x, y = mi.UInt32(pix % W), mi.UInt32(pix // W)
    extra = () if traced is None else (traced,)
    fs = fp.sample(mi.Point2f(u), x, y, *extra)
    pos = mi.Point2f(fs.position.x / W, fs.position.y / H)
    want, want_w = src.sample_ray_differential(time, s1, pos, s3)
    if fp.signed:
        want_w = want_w * fs.weight
    assert kind != "splat" or fp.signed, "mitchell must exercise the signed weight"
    # The same film positions (exact, above) through the same camera code, possibly compiled
    # into other kernels (a backend may contract a multiply-add in one and not the other):
    # each side's rounding errors, about 32 per value (the projective transform of the
    # sample, the normalisation, the rotation to world space, the filter weight) on terms no
    # larger than the value plus one (unit directions; origins are the camera's translation).
    for a, b in ((got.o, want.o), (got.d, want.d), (got.o_x, want.o_x), (got.d_x, want.d_x),
                 (got.o_y, want.o_y), (got.d_y, want.d_y), (got_w, want_w)):
        b = b.numpy()
        tolerances.assert_within(a.numpy(), b, tolerances.chain_bound(np.abs(b) + 1, 2 * 32),
                                 "ray")
    if kind == "uniform":   # the box filter's position is Mitsuba's own: pixel + jitter
        # Pixel + k / 256 is exact in float32; the division by the film size (Dr.Jit turns a
        # division by a literal into a product with its reciprocal, rounded, or within an ulp
        # on CUDA's rcp.approx) rounds 2 to 3 times, exact for the power-of-two width.
        want_pos = np.stack([(pix % W + u[0]) / W, (pix // W + u[1]) / H])
        tolerances.assert_within(pos.numpy(), want_pos, tolerances.chain_bound(want_pos, 3),
                                 "position")


# ----------------------------------------------------------------------------- OIDN's device
@pytest.mark.parametrize("variant,requested,available,want", [
    ("llvm_ad_rgb", "auto", False, "cpu"), ("llvm_ad_rgb", "auto", True, "cpu"),
    ("llvm_ad_rgb", "cpu", True, "cpu"), ("cuda_ad_rgb", "auto", True, "cuda"),
    ("cuda_ad_rgb", "auto", False, "cpu"), ("cuda_ad_rgb", "cpu", True, "cpu"),
    ("cuda_ad_rgb", "cuda", True, "cuda"), ("cuda_rgb", "auto", True, "cuda"),
    ("scalar_rgb", "auto", True, "cpu"), (None, "auto", True, "cpu")])
def test_oidn_device_choice(variant, requested, available, want):
    assert D.choose_device(variant, requested, available) == want


@pytest.mark.parametrize("variant,requested,available,match", [
    ("llvm_ad_rgb", "cuda", True, "needs a cuda_\\* variant"),
    ("cuda_ad_rgb", "cuda", False, "no OIDN CUDA device"),
    ("cuda_ad_rgb", "gpu", True, "one of 'auto', 'cpu', 'cuda'")])
def test_oidn_device_refusals_are_one_line(variant, requested, available, match):
    with pytest.raises(ParameterError, match=match) as e:
        D.choose_device(variant, requested, available)
    assert "\n" not in str(e.value) and str(e.value).startswith(D.DEVICE_ENV)


def test_oidn_device_request_from_env(monkeypatch):
    monkeypatch.delenv(D.DEVICE_ENV, raising=False)
    assert D.requested_device() == ("auto", D.DEVICE_ENV)
    monkeypatch.setenv(D.DEVICE_ENV, " cpu ")
    assert D.requested_device() == ("cpu", D.DEVICE_ENV)
    assert D.requested_device("cuda") == ("cuda", "device")      # the argument wins
    monkeypatch.setenv(D.DEVICE_ENV, "GPU")
    with pytest.raises(ParameterError, match=r"^FOVEATED_MI_OIDN_DEVICE = 'GPU' is invalid"):
        D.requested_device()
    with pytest.raises(ParameterError, match=r"^device = 'gpu' is invalid"):
        D.requested_device("gpu")
    # Availability is asked only on a CUDA variant, and never decides for an LLVM one.
    monkeypatch.setattr(D, "oidn_cuda_available", lambda device_id=0: True)
    monkeypatch.setenv(D.DEVICE_ENV, "auto")
    assert D.resolve_device("llvm_ad_rgb") == "cpu"
    assert D.resolve_device("cuda_ad_rgb") == "cuda"


def _noisy(seed=6):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W] / np.array([H, W])[:, None, None]
    truth = np.stack([0.2 + 0.6 * xx, 0.3 + 0.5 * yy, 0.4 + 0.2 * xx * yy], -1).astype(np.float32)
    noisy = np.maximum(truth + rng.normal(0, 0.15, truth.shape), 0).astype(np.float32)
    albedo = np.full_like(truth, 0.5)
    normal = np.zeros_like(truth)
    normal[..., 2] = 1
    return truth, noisy, albedo, normal


def _jit(img):
    return mi.Color3f(np.ascontiguousarray(img.reshape(-1, 3).T))


def _img(c):
    return c.numpy().T.reshape(H, W, 3)


def _oidn_module():
    import foveated_mi.postprocess  # noqa: F401  (the package re-exports the function)
    return sys.modules["foveated_mi.postprocess.oidn"]


@needs_oidn
def test_oidn_stage_on_the_chosen_device(monkeypatch, caplog):
    """The frame's denoiser runs on the device the choice names, logs it once, and gives the
    CPU device's result (bit-identical on LLVM: the same filter over Dr.Jit's memory; close
    on CUDA, whose OIDN kernels differ)."""
    monkeypatch.delenv(D.DEVICE_ENV, raising=False)
    monkeypatch.setattr(D, "_logged", set())
    truth, noisy, albedo, normal = _noisy()
    expect = D.resolve_device(mi.variant())
    with caplog.at_level(logging.INFO, logger="foveated_mi"):
        out = _img(_oidn_module().oidn(_jit(noisy), _jit(albedo), mi.Vector3f(_jit(normal)), W, H))
    assert D.last_device() == expect
    assert f"OIDN denoises on its {expect.upper()} device" in caplog.text
    cpu = D.denoise(noisy, albedo, normal, device="cpu")
    assert np.mean((out - truth) ** 2) < np.mean((noisy - truth) ** 2) / 3
    if expect == "cpu" and mi.variant().startswith("llvm"):
        np.testing.assert_array_equal(out, cpu)
    else:
        assert np.mean(np.abs(out - cpu)) < 0.02 * np.mean(cpu)


@needs_oidn
def test_oidn_forced_cpu_and_refused_cuda(monkeypatch):
    """``cpu`` works on every variant (a CUDA frame then goes through host memory); ``cuda``
    on a variant or machine without it is one line from the frame's stage."""
    _, noisy, albedo, normal = _noisy(7)
    oidn = _oidn_module().oidn
    monkeypatch.setenv(D.DEVICE_ENV, "cpu")
    out = _img(oidn(_jit(noisy), _jit(albedo), mi.Vector3f(_jit(normal)), W, H))
    assert D.last_device() == "cpu"
    np.testing.assert_array_equal(out, D.denoise(noisy, albedo, normal, device="cpu"))
    if mi.variant().startswith("cuda_") and D.oidn_cuda_available():
        pytest.skip("OIDN's CUDA device is available here: nothing to refuse")
    monkeypatch.setenv(D.DEVICE_ENV, "cuda")
    with pytest.raises(ParameterError, match=r"^FOVEATED_MI_OIDN_DEVICE = 'cuda'") as e:
        oidn(_jit(noisy), None, None, W, H)
    assert "\n" not in str(e.value)


@needs_oidn
def test_oidn_device_buffers_match_the_one_call_api():
    """The paths the CUDA device uses, run on the CPU device: NumPy images copied through OIDN
    buffers (``denoise(device='cuda')``) and Dr.Jit arrays read in place (the frame's stage)
    give pyoidn's own result, with and without guides."""
    _, noisy, albedo, normal = _noisy(8)
    for kw in ({"albedo": albedo, "normal": normal}, {}):
        want = D.denoise(noisy, **kw, device="cpu", quality="fast")
        images = {"color": noisy, **kw}
        got = D._denoise_device_copy("cpu", images, True, "fast", False)
        np.testing.assert_array_equal(got, want)
        if mi.variant().startswith("llvm"):
            jit = {k: _jit(v) for k, v in kw.items()}
            inplace = _oidn_module()._denoise_in_place(
                _jit(noisy), jit.get("albedo"), jit.get("normal"), W, H, kind="cpu",
                quality="fast", clean_aux=False)
            np.testing.assert_array_equal(_img(inplace), want)


@needs_oidn
@pytest.mark.skipif(not os.environ.get("FOVEATED_MI_VARIANT", "").startswith("cuda_"),
                    reason="needs a cuda_* variant")
def test_oidn_numpy_api_on_the_cuda_device():
    if not D.oidn_cuda_available():
        pytest.skip("pyoidn offers no OIDN CUDA device here")
    truth, noisy, albedo, normal = _noisy(9)
    gpu = D.denoise(noisy, albedo, normal, device="cuda")
    assert D.last_device() == "cuda"
    cpu = D.denoise(noisy, albedo, normal, device="cpu")
    assert np.mean(np.abs(gpu - cpu)) < 0.02 * np.mean(cpu)
    assert np.mean((gpu - truth) ** 2) < np.mean((noisy - truth) ** 2) / 3
