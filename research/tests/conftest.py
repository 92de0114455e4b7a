"""The probes' tests: llvm_ad_rgb, the probe a test module names in ``BENCH_MODULE`` imported
from research/, and a clean JIT state. Run them on purpose: ``pytest research/tests``."""
import os

import pytest

VARIANT = os.environ.get("FOVEATED_MI_VARIANT") or "llvm_ad_rgb"
os.environ["FOVEATED_MI_VARIANT"] = VARIANT

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

import foveated_mi  # noqa: E402,F401

RESEARCH = os.path.join(os.path.dirname(__file__), "..")


@pytest.fixture
def bench(request, monkeypatch):
    """The probe that the test module names in its ``BENCH_MODULE``, imported from research/."""
    import importlib
    monkeypatch.syspath_prepend(RESEARCH)
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
