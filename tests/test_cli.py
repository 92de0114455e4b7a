"""The `foveated-mi` command line end to end, in-process (same interpreter, same JIT cache)."""
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from foveated_mi.cli import main
from foveated_mi.io import read_exr


def run(args, capsys):
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_render_writes_exr_layers_png_and_stats(tmp_path, capsys):
    exr = tmp_path / "f.exr"
    stats = tmp_path / "s.json"
    code, out, err = run(["render", "cornell-box", "--preset", "paper", "--size", "40", "32",
                          "--theta", "0.15",
                          "--sigma-p", "0.6", "--gaze", "0.4", "0.6", "--reorder", "rows_blocks",
                          "--atrous-iterations", "1", "--compare-full", "--warmup", "0",
                          "--out", str(exr), "--stats", str(stats)], capsys)
    assert code == 0, err
    assert "trace" in out and "PSNR" in out
    layers = read_exr(exr)
    for name, c in [("image", 3), ("sampling_map", 1), ("shading", 4), ("nearest", 2),
                    ("filled", 3), ("interpolated", 3), ("tonemapped", 3), ("filtered", 3)]:
        assert layers[name].shape == (32, 40, c), name
    s = json.loads(stats.read_text())
    for key in ("pixels", "rays", "ray_fraction", "timings_ms", "variant", "size", "spp",
                "theta", "sigma_p", "gaze", "reorder", "full_ms", "speedup", "psnr", "ssim"):
        assert key in s, key
    assert set(s["timings_ms"]) == {"gbuffer", "sampling", "reorder", "trace", "reconstruct",
                                    "post", "total"}
    assert s["reorder"] == "rows_blocks" and s["gaze"] == [0.4, 0.6] and s["size"] == [40, 32]
    smap = layers["sampling_map"][..., 0]
    assert smap.sum() == s["rays"]
    # The shading layer's alpha marks exactly the traced pixels on this first frame.
    np.testing.assert_array_equal(layers["shading"][..., 3] > 0, smap > 0)
    # nearest holds (x, y) of a traced pixel for every pixel.
    xy = layers["nearest"].astype(int)
    assert smap[xy[..., 1], xy[..., 0]].all()
    assert (tmp_path / "f.png").exists()
    assert np.all(np.isfinite(layers["image"]))


@pytest.mark.parametrize("args,needle", [
    (["--theta", "0"], "theta = 0.0 is invalid"),
    (["--theta", "nan"], "theta = nan is invalid"),
    (["--sigma-p", "1.5"], "sigma_p = 1.5 is invalid"),
    (["--gaze", "nan", "0.5"], "gaze"),
    (["--spp", "0"], "--spp = 0 is invalid"),
    (["--reorder", "diagonal"], "reorder = 'diagonal' is invalid"),
    (["--reconstruction", "cubic"], "reconstruction = 'cubic' is invalid"),
    (["--map-seed", "-2"], "map_seed = -2 is invalid"),
    (["--stereo", "--ipd", "0"], "--ipd = 0.0 is invalid"),
    (["--preset", "vr", "--foveal-still-spp", "1/32"], "foveal_still_spp = '1/32' is invalid"),
    (["--preset", "vr", "--max-history", "0.5"], "max_history = '0.5' is invalid"),
])
def test_bad_flags_one_line_exit_2(args, needle, capsys, tmp_path):
    out = tmp_path / "x.exr"
    code, _, err = run(["render", "cornell-box", "--size", "8", "8", "--out", str(out)] + args,
                       capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], err
    assert not out.exists()


def test_missing_scene_file(capsys, tmp_path):
    code, _, err = run(["render", str(tmp_path / "nope.xml")], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "nope.xml" in err


def test_failed_run_keeps_previous_output(tmp_path, capsys):
    exr = tmp_path / "keep.exr"
    exr.write_bytes(b"previous good file")
    code, _, _ = run(["render", "cornell-box", "--size", "8", "8", "--sigma-p", "2",
                      "--out", str(exr)], capsys)
    assert code == 2 and exr.read_bytes() == b"previous good file"


def test_console_script_installed():
    exe = os.path.join(os.path.dirname(sys.executable), "foveated-mi")
    if not os.path.exists(exe):  # installed elsewhere (pip --target, as scripts/gpu_bench.sh)
        exe = shutil.which("foveated-mi") or exe
    r = subprocess.run([exe, "render", "cornell-box", "--theta", "-3"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip() == ("foveated-mi: error: theta = -3.0 is invalid: expected a finite "
                                "number > 0")


def test_max_depth_and_seed_flags(tmp_path, capsys):
    exr = tmp_path / "d.exr"
    code, _, err = run(["render", "cornell-box", "--size", "16", "16", "--max-depth", "2",
                        "--seed", "7", "--warmup", "0", "--out", str(exr), "--quiet"], capsys)
    assert code == 0, err
    code, _, err = run(["render", "cornell-box", "--size", "16", "16", "--seed", "-1",
                        "--out", str(exr)], capsys)
    assert code == 2 and err.strip() == ("foveated-mi: error: --seed = -1 is invalid: expected "
                                         "an integer >= 0 and <= 4294967295")


@pytest.mark.parametrize("space", ["buffer", "film"])
def test_render_with_the_vr_preset_writes_the_film_layers_it_has(tmp_path, capsys, space):
    exr = tmp_path / "vr.exr"
    code, out, err = run(["render", "cornell-box", "--preset", "vr", "--size", "48", "32",
                          "--foveal-space", space, "--warmup", "0", "--out", str(exr)], capsys)
    assert code == 0, err
    layers = read_exr(exr)
    on_film = [("image", 3), ("sampling_map", 1), ("probability", 1)]
    if space == "film":
        on_film += [("shading", 4), ("depth", 1)]
    else:
        # Its G-buffer and history are on the buffer's samples: nothing of them on the film.
        assert "shading" not in layers and "depth" not in layers
    for name, c in on_film:
        assert layers[name].shape == (32, 48, c), name
    # The foveal formation reconstructs nothing on the film: no nearest-site layer, and its
    # filtered buffer lies on the polar grid, not the film.
    assert "nearest" not in layers and "filtered" not in layers


def test_render_stereo_writes_both_eyes(tmp_path, capsys):
    """--stereo: the EXR holds each eye as a layer, the PNG shows them side by side, the
    stats hold each eye's stats and gaze; the eyes see the box from 6 cm apart."""
    import imageio.v3 as iio
    exr, stats = tmp_path / "eyes.exr", tmp_path / "eyes.json"
    code, out, err = run(["render", "cornell-box", "--preset", "vr", "--size", "32", "24",
                          "--stereo", "--ipd", "0.06", "--gaze", "0.45", "0.5", "--warmup", "1",
                          "--out", str(exr), "--stats", str(stats)], capsys)
    assert code == 0, err
    assert "two eyes of 32x24" in out
    layers = read_exr(exr)
    assert layers["left"].shape == layers["right"].shape == (24, 32, 3)
    assert np.all(np.isfinite(layers["left"])) and not np.array_equal(layers["left"],
                                                                        layers["right"])
    assert iio.imread(tmp_path / "eyes.png").shape[:2] == (24, 64)
    s = json.loads(stats.read_text())
    assert s["ipd"] == 0.06 and s["left"]["rays"] > 0 and s["right"]["rays"] > 0
    # Both eyes fixate one point in front of them: the left eye sees it right of where the
    # right eye does.
    (lx, ly), (rx, ry) = s["gazes"]
    assert lx > rx and abs(ly - ry) < 1e-6


def test_render_headset_one_eye_and_both(tmp_path, capsys):
    """--headset: one eye's buffer at the scene's camera, the frustum's aspect; with --stereo,
    both eyes at the headset's default IPD."""
    from foveated_mi.headsets import headset
    h = headset("quest3")
    w, ht = h.rig(40).size("left")
    exr = tmp_path / "eye.exr"
    code, _, err = run(["render", "cornell-box", "--preset", "vr", "--headset", "quest3",
                        "--eye-width", "40", "--warmup", "0", "--quiet", "--out", str(exr)],
                       capsys)
    assert code == 0, err
    assert read_exr(exr)["image"].shape == (ht, w, 3)
    stats = tmp_path / "eyes.json"
    code, out, err = run(["render", "cornell-box", "--headset", "varjo_xr4", "--eye-width",
                          "32", "--stereo", "--warmup", "0", "--out", str(tmp_path / "s.exr"),
                          "--stats", str(stats)], capsys)
    assert code == 0, err
    w, ht = headset("varjo_xr4").rig(32).size("left")
    assert f"two eyes of {w}x{ht}, ipd 0.063" in out
    assert json.loads(stats.read_text())["ipd"] == headset("varjo_xr4").ipd


@pytest.mark.parametrize("args, needle", [
    (["--headset", "quest4"], "--headset = 'quest4' is invalid"),
    (["--headset", "quest3", "--size", "8", "8"], "--size = [8, 8] is invalid"),
    (["--eye-width", "64"], "--eye-width = 64 is invalid"),
    (["--headset", "quest3", "--eye-width", "2"], "--eye-width = 2 is invalid"),
])
def test_bad_headset_flags_one_line_exit_2(args, needle, capsys, tmp_path):
    out = tmp_path / "x.exr"
    code, _, err = run(["render", "cornell-box", "--out", str(out)] + args, capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], err
    assert not out.exists()


def test_headsets_lists_every_model(capsys):
    from foveated_mi.headsets import HEADSETS
    code, out, _ = run(["headsets", "--eye-width", "640"], capsys)
    assert code == 0 and all(f"`{name}` | 640x" in out for name in HEADSETS)
