"""Image I/O (EXR layers, sRGB PNG, atomic writes) and the PSNR/SSIM wrappers."""
import math
import os
import sys
import types

import colour
import imageio.v3 as iio
import numpy as np
import OpenEXR
import pytest
from hypothesis import given, settings, strategies as st
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from foveated_mi import io as fio
from foveated_mi.metrics import COMPARE_KEYS, compare, psnr, ssim, ssim_win_size
from foveated_mi.validate import ParameterError


def bits(a):
    """Bit pattern of an array, so NaN payloads and -0.0 count in 'exact'."""
    a = np.ascontiguousarray(a)
    return a.view({2: np.uint16, 4: np.uint32}[a.dtype.itemsize])


# ----------------------------------------------------------------------------------------
# EXR
# ----------------------------------------------------------------------------------------

def sample_layers(h=9, w=13, seed=0):
    rng = np.random.default_rng(seed)
    rgb = rng.normal(size=(h, w, 3)).astype(np.float32) * 10
    rgb[0, 0] = [np.nan, np.inf, -np.inf]
    rgb[0, 1] = [-0.0, 1e-40, 3e38]
    return {
        "": rng.random((h, w, 4)).astype(np.float32),                    # unprefixed RGBA
        "color": rgb,                                                    # 3 channels
        "reprojection": rng.random((h, w, 2)).astype(np.float32) * w,    # 2 channels
        "depth": rng.random((h, w, 1)).astype(np.float32),               # 1 channel
        "nearest": rng.integers(0, 2**32, (h, w, 1), dtype=np.uint32),   # UINT
        "probability": rng.random((h, w, 1)).astype(np.float16),         # HALF
        "a.b": rng.random((h, w, 3)).astype(np.float32),                 # dotted layer name
    }


def test_exr_round_trip_is_exact(tmp_path):
    path = tmp_path / "frame.exr"
    layers = sample_layers()
    fio.write_exr(path, layers)
    back = fio.read_exr(path)
    assert set(back) == set(layers)
    for name, arr in layers.items():
        assert back[name].dtype == arr.dtype and back[name].shape == arr.shape, name
        np.testing.assert_array_equal(bits(back[name]), bits(arr), err_msg=name)


def test_exr_channel_names_follow_the_layer_convention(tmp_path):
    path = tmp_path / "frame.exr"
    fio.write_exr(path, sample_layers())
    names = set(OpenEXR.File(str(path), separate_channels=True).channels())
    assert names == {"R", "G", "B", "A", "color.R", "color.G", "color.B", "reprojection.X",
                     "reprojection.Y", "depth.Y", "nearest.Y", "probability.Y", "a.b.R",
                     "a.b.G", "a.b.B"}


def test_exr_2d_float64_and_bool_inputs(tmp_path):
    path = tmp_path / "x.exr"
    d = np.linspace(0, 1, 12).reshape(3, 4)
    mask = d > 0.5
    fio.write_exr(path, {"d": d, "hit": mask})
    back = fio.read_exr(path)
    np.testing.assert_array_equal(back["d"][..., 0], d.astype(np.float32))
    assert back["hit"].dtype == np.uint32
    np.testing.assert_array_equal(back["hit"][..., 0], mask.astype(np.uint32))


def test_exr_attrs_round_trip(tmp_path):
    path = tmp_path / "x.exr"
    attrs = {"spp": 4, "theta": 0.25, "scene": "voxel-monument", "gaze": (0.5, 0.25),
             "passes": ["sampling", "reorder"], "M": np.eye(4, dtype=np.float32)}
    fio.write_exr(path, {"color": np.zeros((2, 2, 3), np.float32)}, attrs=attrs)
    back = fio.read_exr_attrs(path)
    assert back["spp"] == 4 and back["scene"] == "voxel-monument"
    assert back["theta"] == pytest.approx(0.25)
    np.testing.assert_allclose(back["gaze"], [0.5, 0.25])
    assert list(back["passes"]) == ["sampling", "reorder"]
    np.testing.assert_array_equal(back["M"], np.eye(4))


@pytest.mark.parametrize("layers", [
    {"c": np.zeros((4, 4, 5), np.float32)},                          # 5 channels
    {"c": np.zeros((4,), np.float32)},                               # 1-D
    {"c": np.zeros((0, 4, 3), np.float32)},                          # empty
    {"c": np.zeros((4, 4, 3), np.float32), "d": np.zeros((4, 5), np.float32)},  # H, W differ
    {"c": np.zeros((4, 4, 3), np.int64)},                            # dtype
    {"c": np.zeros((4, 4, 3), np.complex64)},
    {1: np.zeros((4, 4, 3), np.float32)},                            # name not a str
    {},                                                              # nothing
    [("c", np.zeros((4, 4, 3), np.float32))],                        # not a dict
])
def test_exr_rejects_bad_layers(tmp_path, layers):
    with pytest.raises(ParameterError):
        fio.write_exr(tmp_path / "bad.exr", layers)
    assert not os.listdir(tmp_path)


@pytest.mark.parametrize("attrs", [{"channels": "x"}, {"compression": 1}, {"n": 2**40},
                                   {"flag": True}, {"d": {"a": 1}}, {"v": (1, 2, 3, 4)},
                                   {"": 1}, {"m": np.eye(2)}, {"o": None}])
def test_exr_rejects_bad_attrs(tmp_path, attrs):
    with pytest.raises(ParameterError, match="attrs"):
        fio.write_exr(tmp_path / "bad.exr", {"c": np.zeros((2, 2, 3), np.float32)}, attrs=attrs)


def test_exr_file_errors_name_the_path(tmp_path):
    missing_dir = tmp_path / "no" / "such" / "dir" / "x.exr"
    with pytest.raises(OSError, match="no/such/dir"):
        fio.write_exr(missing_dir, {"c": np.zeros((2, 2, 3), np.float32)})
    with pytest.raises(FileNotFoundError, match="nothing.exr"):
        fio.read_exr(tmp_path / "nothing.exr")
    junk = tmp_path / "junk.exr"
    junk.write_bytes(b"not an exr file")
    with pytest.raises(OSError, match="junk.exr"):
        fio.read_exr(junk)


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores directory permissions")
def test_unwritable_directory(tmp_path):
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o500)
    try:
        with pytest.raises(PermissionError, match="ro"):
            fio.write_png(d / "x.png", np.zeros((2, 2, 3)))
    finally:
        d.chmod(0o700)


def test_permission_error_names_the_path(tmp_path, monkeypatch):
    # as root the directory test above is skipped: simulate the refusal instead
    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")
    monkeypatch.setattr(fio.tempfile, "mkstemp", refuse)
    with pytest.raises(PermissionError, match=r"cannot write .*x\.exr: Permission denied"):
        fio.write_exr(tmp_path / "x.exr", {"c": np.zeros((2, 2, 3), np.float32)})


# ----------------------------------------------------------------------------------------
# atomic writes
# ----------------------------------------------------------------------------------------

def test_atomic_write_keeps_old_file_when_the_block_fails(tmp_path):
    path = tmp_path / "stats.json"
    path.write_text("old contents")
    with pytest.raises(RuntimeError, match="midway"):
        with fio.atomic_write(path, "w") as f:
            f.write("new contents, half of th")
            raise RuntimeError("failed midway")
    assert path.read_text() == "old contents"
    assert os.listdir(tmp_path) == ["stats.json"]          # no temporary left behind


def test_atomic_write_replaces_on_success_with_normal_permissions(tmp_path):
    path = tmp_path / "stats.json"
    with fio.atomic_write(path, "w") as f:
        f.write("first")
    assert path.read_text() == "first"
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask
    path.chmod(0o640)
    with fio.atomic_write(path) as tmp:                     # path mode: writer takes a name
        assert os.path.dirname(tmp) == str(tmp_path) and tmp.endswith(".json")
        with open(tmp, "w") as f:
            f.write("second")
    assert path.read_text() == "second"
    assert path.stat().st_mode & 0o777 == 0o640            # the old file's permissions
    assert os.listdir(tmp_path) == ["stats.json"]


def test_exr_writer_failing_midway_keeps_old_exr(tmp_path, monkeypatch):
    path = tmp_path / "frame.exr"
    good = {"color": np.ones((4, 4, 3), np.float32)}
    fio.write_exr(path, good)

    class BrokenFile:                   # writes part of a file, then fails like a full disk
        def __init__(self, header, channels):
            pass

        def write(self, filename):
            with open(filename, "wb") as f:
                f.write(b"\x76\x2f\x31\x01 truncated")
            raise RuntimeError("No space left on device")

    fake = types.SimpleNamespace(File=BrokenFile, ZIP_COMPRESSION=OpenEXR.ZIP_COMPRESSION,
                                 scanlineimage=OpenEXR.scanlineimage)
    monkeypatch.setitem(sys.modules, "OpenEXR", fake)
    with pytest.raises(OSError, match="frame.exr"):
        fio.write_exr(path, {"color": np.zeros((4, 4, 3), np.float32)})
    monkeypatch.undo()
    np.testing.assert_array_equal(fio.read_exr(path)["color"], good["color"])
    assert os.listdir(tmp_path) == ["frame.exr"]


def test_atomic_write_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing"):
        with fio.atomic_write(tmp_path / "missing" / "x.txt", "w"):
            pass
    with pytest.raises(IsADirectoryError):
        with fio.atomic_write(tmp_path, "w"):
            pass
    with pytest.raises(ParameterError, match="mode"):
        with fio.atomic_write(tmp_path / "x.txt", "r"):
            pass


# ----------------------------------------------------------------------------------------
# PNG
# ----------------------------------------------------------------------------------------

def srgb_piecewise(v):
    """IEC 61966-2-1 sRGB encoding written out, as a cross-check of colour-science's."""
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055)


@pytest.mark.parametrize("exposure", [0.0, 1.5, -2.0])
def test_png_is_8bit_srgb(tmp_path, exposure):
    rng = np.random.default_rng(3)
    img = rng.random((7, 11, 3)) * 1.5 - 0.1
    img[0, 0] = [np.nan, np.inf, -np.inf]
    path = tmp_path / "x.png"
    fio.write_png(path, img, exposure=exposure)
    got = iio.imread(path)
    assert got.dtype == np.uint8 and got.shape == (7, 11, 3)
    lin = np.clip(np.nan_to_num(img * 2.0 ** exposure, nan=0.0, posinf=1.0, neginf=0.0), 0, 1)
    expected = np.round(colour.models.eotf_inverse_sRGB(lin) * 255).astype(np.uint8)
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(got[0, 0], [0, 255, 0])
    assert np.abs(got.astype(int) - np.round(srgb_piecewise(lin) * 255)).max() <= 1


def test_png_with_tonemap_rgba_and_gray(tmp_path):
    rng = np.random.default_rng(4)
    img = rng.random((5, 6, 4)) * 4.0
    img[..., 3] = rng.random((5, 6))
    fio.write_png(tmp_path / "rgba.png", img, tonemap="reinhard", exposure=1.0)
    got = iio.imread(tmp_path / "rgba.png")
    assert got.shape == (5, 6, 4)
    x = img[..., :3] * 2.0
    rgb = np.round(colour.cctf_encoding(x / (1 + x), function="sRGB") * 255)
    assert np.abs(got[..., :3].astype(int) - rgb).max() <= 1       # float32 tone mapping
    np.testing.assert_array_equal(got[..., 3], np.round(img[..., 3] * 255))  # alpha linear

    gray = rng.random((5, 6))
    fio.write_png(tmp_path / "gray.png", gray)
    got = iio.imread(tmp_path / "gray.png")
    assert got.shape == (5, 6)
    np.testing.assert_array_equal(got, np.round(colour.cctf_encoding(gray, function="sRGB") * 255))


@pytest.mark.parametrize("kw", [dict(linear_rgb=np.zeros((4, 4, 2))), dict(linear_rgb=np.zeros(4)),
                                dict(exposure=math.nan), dict(tonemap="filmic"),
                                dict(linear_rgb=np.zeros((4, 4, 3), complex))])
def test_png_rejects_bad_arguments(tmp_path, kw):
    args = dict(linear_rgb=np.zeros((4, 4, 3)))
    args.update(kw)
    with pytest.raises(ParameterError):
        fio.write_png(tmp_path / "x.png", **args)
    assert not os.listdir(tmp_path)


# ----------------------------------------------------------------------------------------
# metrics
# ----------------------------------------------------------------------------------------

def pair(shape, seed=0, scale=1.0, noise=0.05):
    rng = np.random.default_rng(seed)
    ref = rng.random(shape) * scale
    return ref, ref + rng.normal(0, noise * scale, shape)


@pytest.mark.parametrize("shape", [(16, 20, 3), (9, 9), (32, 24, 4)])
def test_psnr_matches_definition_and_skimage(shape):
    ref, test = pair(shape)
    ref = np.clip(ref, 0, 1)
    mse = np.mean((ref - test) ** 2)
    assert psnr(ref, test) == pytest.approx(10 * np.log10(1.0 / mse), rel=1e-12)
    assert psnr(ref, test, data_range=2.0) == pytest.approx(
        peak_signal_noise_ratio(ref, test, data_range=2.0), rel=1e-12)


def test_default_data_range_for_hdr_reference():
    ref, test = pair((12, 12, 3), scale=8.0)
    ref[0, 0, 0] = -1.0
    rng = ref.max() - ref.min()
    assert psnr(ref, test) == pytest.approx(peak_signal_noise_ratio(ref, test, data_range=rng))
    assert ssim(ref, test) == pytest.approx(
        structural_similarity(ref, test, data_range=rng, channel_axis=-1))
    with pytest.raises(ParameterError, match="data_range"):
        psnr(np.full((8, 8), 3.0), np.zeros((8, 8)))


@pytest.mark.parametrize("shape", [(16, 20, 3), (10, 8), (7, 7, 3)])
def test_ssim_matches_skimage(shape):
    ref, test = pair(shape, seed=1)
    ref = np.clip(ref, 0, 1)
    expected = structural_similarity(ref, test, data_range=1.0, win_size=7,
                                     channel_axis=-1 if len(shape) == 3 else None)
    assert ssim(ref, test) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("shape,win", [((6, 6, 3), 5), ((4, 9, 3), 3), ((5, 30), 5),
                                       ((3, 3, 3), 3)])
def test_ssim_small_images_shrink_the_window(shape, win):
    ref, test = pair(shape, seed=2)
    ref = np.clip(ref, 0, 1)
    expected = structural_similarity(ref, test, data_range=1.0, win_size=win,
                                     channel_axis=-1 if len(shape) == 3 else None)
    assert ssim(ref, test) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("shape", [(2, 8, 3), (1, 1, 3), (8, 2)])
def test_ssim_is_nan_below_three_pixels(shape):
    ref, test = pair(shape)
    assert math.isnan(ssim(np.clip(ref, 0, 1), test))
    assert math.isfinite(psnr(np.clip(ref, 0, 1), test))


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 40), st.integers(1, 40))
def test_ssim_win_size_rule(h, w):
    win = ssim_win_size(h, w)
    if min(h, w) < 3:
        assert win is None
    else:
        assert win % 2 == 1 and 3 <= win <= min(h, w, 7)
        assert win == 7 or win + 2 > min(h, w)          # the largest that fits


def test_identical_images_and_compare():
    ref, test = pair((10, 10, 3))
    ref = np.clip(ref, 0, 1)
    assert psnr(ref, ref) == math.inf
    assert ssim(ref, ref) == pytest.approx(1.0)
    out = compare(ref, test)
    # every key of COMPARE_KEYS is present (stable CSV columns); FLIP and the region keys
    # are nan here (test has values outside [0, 1]; no gaze given)
    assert set(out) == set(COMPARE_KEYS)
    assert out["psnr"] == psnr(ref, test) and out["ssim"] == ssim(ref, test)
    assert all(math.isnan(v) for k, v in out.items() if k not in ("psnr", "ssim"))
    r32 = ref.astype(np.float32)
    assert compare(r32, r32.copy())["psnr"] == math.inf


@pytest.mark.parametrize("args", [
    (np.zeros((4, 4, 3)), np.zeros((4, 5, 3))),          # shapes differ
    (np.zeros((4, 4, 3, 1)), np.zeros((4, 4, 3, 1))),    # 4-D
    (np.zeros(4), np.zeros(4)),                          # 1-D
    (np.zeros((4, 4)), np.full((4, 4), np.nan)),         # NaN in test
    (np.full((4, 4), np.inf), np.zeros((4, 4))),         # inf in reference
    (np.zeros((4, 4), complex), np.zeros((4, 4))),
])
def test_metrics_reject_bad_inputs(args):
    for fn in (psnr, ssim):
        with pytest.raises(ParameterError):
            fn(*args)
    with pytest.raises(ParameterError, match="data_range"):
        psnr(np.zeros((4, 4)), np.zeros((4, 4)), data_range=0.0)
