"""Long-run checks, marked slow (`make test-slow`): memory, kernels and stats over many frames."""
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
def test_a_budget_s_moving_choice_compiles_no_kernel_after_warm_up():
    r = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "long_run.py"),
                        "--frames", "300", "--size", "48", "48", "--frame-budget",
                        "--variant", "llvm_ad_rgb"],
                       capture_output=True, text=True, timeout=3600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "all checks met" in r.stdout


@pytest.mark.slow
def test_2048_frame_fits_in_memory():
    r = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "peak_memory.py"),
                        "--size", "2048", "2048", "--variant", "llvm_ad_rgb"],
                       capture_output=True, text=True, timeout=3600)
    assert r.returncode == 0, r.stdout + r.stderr
