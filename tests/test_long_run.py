"""Long-run checks, marked slow (`make test-slow`): memory, kernels and stats over many frames."""
import json
import os
import subprocess
import sys

import pytest

ROOT = os.path.join(os.path.dirname(__file__), "..")


@pytest.mark.slow
def test_500_frames_memory_kernels_stats():
    r = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "long_run.py"),
                        "--frames", "500", "--size", "48", "48", "--variant", "llvm_ad_rgb"],
                       capture_output=True, text=True, timeout=3600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "all checks met" in r.stdout


@pytest.mark.slow
def test_a_budget_s_moving_choice_compiles_no_kernel_after_warm_up(tmp_path):
    out = tmp_path / "budget.json"
    r = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "long_run.py"),
                        "--frames", "300", "--size", "48", "48", "--frame-budget",
                        "--variant", "llvm_ad_rgb", "--out", str(out)],
                       capture_output=True, text=True, timeout=3600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "all checks met" in r.stdout
    # The transitions are reported frame by frame: the head starts turning at every other
    # phase of 25 frames after the first, a cut starts every other still phase; frame 150
    # follows the memory probe (half the frames), which empties the allocator's cache.
    d = json.loads(out.read_text())
    moves, cuts = d["first_moving_frame"], d["first_frame_after_cut"]
    assert [f for f, _ in moves["frames"]] == [50, 100, 200, 250]
    assert [f for f, _ in cuts["frames"]] == [75, 175, 275]
    for t in (moves, cuts):
        assert t["max"] == max(x for _, x in t["frames"]) and t["max"] > 0


@pytest.mark.slow
def test_2048_frame_fits_in_memory():
    r = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "peak_memory.py"),
                        "--size", "2048", "2048", "--variant", "llvm_ad_rgb"],
                       capture_output=True, text=True, timeout=3600)
    assert r.returncode == 0, r.stdout + r.stderr
