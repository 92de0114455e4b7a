"""The offline wheelhouse (scripts/wheelhouse.sh) and the GPU run (scripts/gpu_bench.sh).

Fast tests check the wheel slimming and RECORD rewrite on a tiny synthetic wheel, the size
cap's one-line failure, and the helpers of gpu_bench.sh; the slow test builds the real
wheelhouse for this Python, installs it offline into a fresh venv and renders a frame."""
import base64
import hashlib
import importlib.util
import json
import os
import subprocess
import sys
import zipfile

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
SCRIPTS = os.path.join(ROOT, "scripts")


def _load(name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(SCRIPTS, f"{name}.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


wh = _load("_wheelhouse")

VARIANTS = ["scalar_rgb", "llvm_ad_rgb", "llvm_ad_spectral", "cuda_ad_rgb", "cuda_ad_mono"]
EXT = ".cpython-311-x86_64-linux-gnu.so"


def _fake_wheel(path):
    """A wheel shaped like Mitsuba's: one extension per variant, shared plugins, data."""
    files = {"mitsuba/__init__.py": b"from .config import MI_VARIANTS\n",
             "mitsuba/config.py": f"X = 1\nMI_VARIANTS = {VARIANTS!r}\nY = 2\n".encode(),
             "mitsuba/plugins/path.so": b"\x7fELF path plugin",
             "mitsuba/data/srgb.coeff": b"\0" * 1000,
             "mitsuba/data/ior/Au.eta.spd": b"400 0.1\n",
             "mitsuba/include/mitsuba/mitsuba.h": b"#pragma once\n",
             "mitsuba/libmitsuba.so": b"\x7fELF lib",
             "mitsuba-3.9.1.dist-info/METADATA":
                 b"Metadata-Version: 2.1\nName: mitsuba\nVersion: 3.9.1\n",
             "mitsuba-3.9.1.dist-info/WHEEL":
                 b"Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: false\nTag: py3-none-any\n"}
    for v in VARIANTS:
        files[f"mitsuba/{v}{EXT}"] = f"\x7fELF {v}".encode()
    record = [f"{n},sha256=bogus,1" for n in files] + ["mitsuba-3.9.1.dist-info/RECORD,,"]
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for n, data in files.items():
            z.writestr(n, data)
        z.writestr("mitsuba-3.9.1.dist-info/RECORD", "\n".join(record) + "\n")
    return files


def test_record_entry_is_urlsafe_b64_sha256_without_padding():
    data = b"foveated" * 100
    want = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).decode().rstrip("=")
    assert wh.record_entry("a/b.py", data) == f"a/b.py,sha256={want},{len(data)}"
    assert "=" not in wh.record_entry("x", b"").split("sha256=")[1].split(",")[0]


def test_slim_keeps_rgb_ad_variants_and_rewrites_record(tmp_path):
    src = tmp_path / "mitsuba-3.9.1-py3-none-any.whl"
    files = _fake_wheel(src)
    dst, dropped = wh.slim_wheel(str(src), str(tmp_path / "out"))
    names = set(zipfile.ZipFile(dst).namelist())
    for v in ("llvm_ad_rgb", "cuda_ad_rgb"):
        assert f"mitsuba/{v}{EXT}" in names
    for v in ("scalar_rgb", "llvm_ad_spectral", "cuda_ad_mono"):
        assert f"mitsuba/{v}{EXT}" not in names and f"mitsuba/{v}{EXT}" in dropped
    assert "mitsuba/data/srgb.coeff" not in names
    assert "mitsuba/include/mitsuba/mitsuba.h" not in names
    for kept in ("mitsuba/plugins/path.so", "mitsuba/data/ior/Au.eta.spd", "mitsuba/libmitsuba.so",
                 "mitsuba-3.9.1.dist-info/METADATA"):
        assert kept in names and zipfile.ZipFile(dst).read(kept) == files[kept]
    cfg = zipfile.ZipFile(dst).read("mitsuba/config.py").decode()
    assert "MI_VARIANTS = ['llvm_ad_rgb', 'cuda_ad_rgb']" in cfg and "X = 1" in cfg and "Y = 2" in cfg
    assert wh.verify_record(dst) == len(names)
    # The source's bogus RECORD fails the same check.
    with pytest.raises(wh.WheelError, match="does not match"):
        wh.verify_record(str(src))


def test_slimmed_wheel_is_accepted_by_pip(tmp_path):
    src = tmp_path / "mitsuba-3.9.1-py3-none-any.whl"
    _fake_wheel(src)
    dst, _ = wh.slim_wheel(str(src), str(tmp_path / "out"))
    target = tmp_path / "site"
    p = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-index", "--no-deps",
                        "--disable-pip-version-check", "--target", str(target), dst],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert (target / "mitsuba" / f"cuda_ad_rgb{EXT}").exists()
    assert not (target / "mitsuba" / f"scalar_rgb{EXT}").exists()


def test_tampered_member_fails_verification(tmp_path):
    src = tmp_path / "mitsuba-3.9.1-py3-none-any.whl"
    _fake_wheel(src)
    dst, _ = wh.slim_wheel(str(src), str(tmp_path / "out"))
    bad = tmp_path / "bad" / os.path.basename(dst)
    bad.parent.mkdir()
    with zipfile.ZipFile(dst) as zin, zipfile.ZipFile(bad, "w") as zout:
        for n in zin.namelist():
            zout.writestr(n, b"changed" if n == "mitsuba/libmitsuba.so" else zin.read(n))
    with pytest.raises(wh.WheelError, match="libmitsuba.so"):
        wh.verify_record(str(bad))


def test_slim_refuses_a_variant_the_wheel_lacks(tmp_path):
    src = tmp_path / "mitsuba-3.9.1-py3-none-any.whl"
    _fake_wheel(src)
    with pytest.raises(wh.WheelError) as e:
        wh.slim_wheel(str(src), str(tmp_path / "out"), keep=("cuda_ad_rgb", "llvm_ad_mono"))
    assert "llvm_ad_mono" in str(e.value) and "\n" not in str(e.value)


def test_strip_tests_drops_only_test_folders(tmp_path):
    src = tmp_path / "numpy-2.0-py3-none-any.whl"
    with zipfile.ZipFile(src, "w") as z:
        z.writestr("numpy/__init__.py", "")
        z.writestr("numpy/testing/__init__.py", "")
        z.writestr("numpy/_core/tests/test_a.py", "")
        z.writestr("numpy/htmlcov/index.html", "")
        z.writestr("numpy-2.0.dist-info/METADATA", "Name: numpy\n")
        z.writestr("numpy-2.0.dist-info/RECORD", "")
    dst, dropped = wh.strip_tests(str(src), str(tmp_path / "out"))
    assert sorted(dropped) == ["numpy/_core/tests/test_a.py", "numpy/htmlcov/index.html"]
    assert "numpy/testing/__init__.py" in zipfile.ZipFile(dst).namelist()
    assert wh.verify_record(dst) == 4


def test_cap_message_under_and_over():
    mib = wh.MIB
    assert wh.cap_message(2 * mib, 60 * mib, 64) is None
    msg = wh.cap_message(2 * mib, 63 * mib, 64)
    assert msg is not None and "\n" not in msg
    assert "65.0 MiB" in msg and "64 MiB cap by 1.0 MiB" in msg


def test_cap_check_fails_with_one_line(tmp_path):
    (tmp_path / "w.whl").write_bytes(b"\0" * 200_000)
    p = subprocess.run([sys.executable, os.path.join(SCRIPTS, "_wheelhouse.py"), "cap", "--repo",
                        ROOT, "--wheelhouse", str(tmp_path), "--cap-mib", "0.1"],
                       capture_output=True, text=True)
    assert p.returncode == 1
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "over the 0.1 MiB cap" in lines[0], p.stderr
    ok = subprocess.run([sys.executable, os.path.join(SCRIPTS, "_wheelhouse.py"), "cap", "--repo",
                         ROOT, "--wheelhouse", str(tmp_path), "--cap-mib", "4096"],
                        capture_output=True, text=True)
    assert ok.returncode == 0 and ok.stderr == ""


def test_wheelhouse_sh_rejects_a_bad_python_version():
    p = subprocess.run(["bash", os.path.join(SCRIPTS, "wheelhouse.sh"), "python3"],
                       capture_output=True, text=True)
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [
        "wheelhouse: PYVER 'python3' is not allowed; give a CPython version like 3.12"]


def test_gpu_bench_needs_an_output_folder():
    p = subprocess.run(["bash", os.path.join(SCRIPTS, "gpu_bench.sh")], capture_output=True,
                       text=True)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1


def test_offline_pytest_finds_missing_top_level_imports(tmp_path):
    plugin = _load("_offline_pytest")
    f = tmp_path / "test_x.py"
    f.write_text("import os\nimport no_such_module_xyz.sub\nfrom numpy import array\n"
                 "def test():\n    import another_missing_module\n")
    assert plugin.missing_imports(str(f)) == ["no_such_module_xyz"]


def test_bench_summary_lists_steps_and_failures(tmp_path):
    summary = _load("_bench_summary")
    (tmp_path / "steps.csv").write_text(
        "step,status,seconds,limit_s,note\ninstall,ok,9.0,90,pip\n"
        "reorder_64,failed (exit 1),3.0,45,bench_reorder; last line: boom\n"
        "overhead,skipped,0,0,absent\n")
    (tmp_path / "gpu.txt").write_text("NVIDIA H100 80GB HBM3, 550.54.15, 81559 MiB\n")
    (tmp_path / "reorder_96.json").write_text(json.dumps(
        {"full_ms": 20.0, "compiled_after_first": 0,
         "args": {"scene": "voxel-city", "size": [96, 96]},
         "modes": {"compact": {"trace_ms": 4.0, "reorder_ms": 0.5, "total_ms": 10.0,
                               "ray_fraction": 0.1}}}))
    text = summary.summarise(str(tmp_path), "cuda_ad_rgb")
    assert text.startswith("# gpu_bench on NVIDIA H100 80GB HBM3")
    assert "Failed or timed out: reorder_64." in text
    assert "| reorder_96 | voxel-city | 96x96 | compact | 0.100 | 4.0 | 0.5 | 10.0 | 20.0 | 2.00 |" in text
    assert (tmp_path / "reorder.csv").read_text().count("\n") == 2
    assert json.loads((tmp_path / "summary.json").read_text())["failed"] == ["reorder_64"]


@pytest.mark.slow
def test_wheelhouse_installs_offline_and_renders(tmp_path):
    """Builds the wheelhouse for this Python (needs the package registry), installs it into a
    fresh venv with --no-index and renders a foveated frame on llvm_ad_rgb there."""
    pyver = f"{sys.version_info.major}.{sys.version_info.minor}"
    house = tmp_path / "wheelhouse"
    env = dict(os.environ, WHEELHOUSE_DIR=str(house), PYTHON=sys.executable)
    p = subprocess.run(["bash", os.path.join(SCRIPTS, "wheelhouse.sh"), pyver], env=env,
                       capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr[-2000:]
    assert "pyoidn (Intel OIDN denoiser): " in p.stdout
    wheels = sorted(str(w) for w in house.glob("*.whl"))
    assert any(os.path.basename(w).startswith("mitsuba-3.9.1") for w in wheels)
    for w in wheels:
        if os.path.basename(w).startswith("mitsuba-"):
            wh.verify_record(w)
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    py = str(venv / "bin" / "python")
    p = subprocess.run([py, "-m", "pip", "install", "-q", "--disable-pip-version-check",
                        "--no-index", "--find-links", str(house), "--no-deps", *wheels],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    code = """
import importlib.util, json
import numpy as np
import mitsuba as mi
import foveated_mi
mi.set_variant("llvm_ad_rgb"); foveated_mi.register()
from foveated_mi.scenes import load_scene
from foveated_mi.integrators.foveated import FoveatedIntegrator
scene = load_scene("cornell-box", width=32, height=32, spp=1,
                   integrator={"type": "path", "max_depth": 3})
integ = FoveatedIntegrator(nested=scene.integrator(), theta=0.2)
img = np.array(mi.render(scene, integrator=integ, spp=1, seed=0))
print(json.dumps({"variants": mi.variants(), "file": foveated_mi.__file__,
                  "cuda": importlib.util.find_spec("mitsuba.cuda_ad_rgb") is not None,
                  "scalar": importlib.util.find_spec("mitsuba.scalar_rgb") is not None,
                  "shape": list(img.shape), "finite": bool(np.isfinite(img).all()),
                  "mean": float(img.mean()), "rays": integ.stats["ray_fraction"]}))
"""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "FOVEATED_MI_VARIANT")}
    p = subprocess.run([py, "-c", code], capture_output=True, text=True, cwd=str(tmp_path),
                       env=env, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    r = json.loads(p.stdout.strip().splitlines()[-1])
    assert "cuda_ad_rgb" in r["variants"] and r["cuda"] and not r["scalar"]
    assert r["file"].startswith(str(venv))
    assert r["shape"] == [32, 32, 3] and r["finite"] and r["mean"] > 0.0
    assert 0.0 < r["rays"] < 1.0
