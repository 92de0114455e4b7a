"""Shared fixtures: every test runs on llvm_ad_rgb with tiny films and a clean JIT state.

``FOVEATED_MI_VARIANT=cuda_ad_rgb`` runs the suite on the CUDA backend instead."""
import os

import pytest

VARIANT = os.environ.get("FOVEATED_MI_VARIANT") or "llvm_ad_rgb"
os.environ["FOVEATED_MI_VARIANT"] = VARIANT

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

import foveated_mi  # noqa: E402,F401


def _llvm_vector_width(width: int) -> None:
    """Compile LLVM kernels ``width`` lanes wide on this CPU, as a CPU with narrower vector
    registers would (AVX2: 8, SSE4.2: 4; AVX-512: 16). Reductions then run in another order,
    which is what differs between machines. Dr.Jit exports the setter from its core library
    only (a C++ symbol), so it is called through ctypes."""
    import ctypes
    core = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
    cpu = core._Z19jit_llvm_target_cpuv
    features = core._Z24jit_llvm_target_featuresv
    cpu.restype = features.restype = ctypes.c_char_p
    set_target = core._Z19jit_llvm_set_targetPKcS0_j
    set_target.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
    set_target(cpu(), features(), width)
    current = core._Z21jit_llvm_vector_widthv
    current.restype = ctypes.c_uint32
    assert current() == width, (current(), width)


#: ``FOVEATED_MI_TEST_VECTOR_WIDTH=8`` runs the tests as on a CPU with 8-wide vectors.
if VARIANT.startswith("llvm_") and os.environ.get("FOVEATED_MI_TEST_VECTOR_WIDTH"):
    _llvm_vector_width(int(os.environ["FOVEATED_MI_TEST_VECTOR_WIDTH"]))

SHARED_SCENES = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "scenes")
BENCHMARKS = os.path.join(os.path.dirname(__file__), "..", "benchmarks")


@pytest.fixture
def bench(request, monkeypatch):
    """The benchmark script that the test module names in its ``BENCH_MODULE``, imported
    from ``benchmarks/``."""
    import importlib
    monkeypatch.syspath_prepend(BENCHMARKS)
    return importlib.import_module(request.module.BENCH_MODULE)


@pytest.fixture(autouse=True)
def _variant_and_teardown():
    if mi.variant() != VARIANT:
        mi.set_variant(VARIANT)
        foveated_mi.register()
    yield
    dr.sync_thread()
    dr.kernel_history_clear()
    dr.flush_malloc_cache()


@pytest.fixture
def shared_scene():
    """Path of a scene in ../shared/scenes, or a clean skip when the folder is absent."""
    def get(name: str) -> str:
        path = os.path.abspath(os.path.join(SHARED_SCENES, name, "scene.xml"))
        if not os.path.exists(path):
            pytest.skip(f"shared scene {name!r} not found at {path}")
        return path
    return get


#: ``make test-perceptual`` sets this: there a check marked ``perceptual`` that skips fails.
REQUIRE_PERCEPTUAL = os.environ.get("FOVEATED_REQUIRE_PERCEPTUAL") == "1"


def pytest_runtest_setup(item):
    """A check marked ``perceptual`` needs FovVideoVDP (pyfvvdp, torch): without it, a skip
    that says how to install it. Torch runs on one thread: the images are tiny and the test
    workers already share the cores."""
    if item.get_closest_marker("perceptual") is None:
        return
    from foveated_mi import perceptual
    if not perceptual.available():
        pytest.skip("needs the perceptual extra (pyfvvdp, torch): `make test-perceptual` "
                    "installs it")
    import torch
    torch.set_num_threads(1)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Under ``FOVEATED_REQUIRE_PERCEPTUAL=1`` a skipped ``perceptual`` check is a failure:
    the run exists to score JOD, so a missing extra must not pass as a skip."""
    outcome = yield
    report = outcome.get_result()
    if (REQUIRE_PERCEPTUAL and report.skipped and not hasattr(report, "wasxfail")
            and item.get_closest_marker("perceptual") is not None):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else report.longrepr
        reason = str(reason).removeprefix("Skipped: ")
        report.outcome = "failed"
        report.longrepr = f"FOVEATED_REQUIRE_PERCEPTUAL=1 but this perceptual check skipped: " \
                          f"{reason}"
