"""Shared fixtures: every test runs on llvm_ad_rgb with tiny films and a clean JIT state.

``FOVEATED_MI_VARIANT=cuda_ad_rgb`` runs the suite on the CUDA backend instead."""
import os

import pytest

VARIANT = os.environ.get("FOVEATED_MI_VARIANT") or "llvm_ad_rgb"
os.environ["FOVEATED_MI_VARIANT"] = VARIANT

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

import foveated_mi  # noqa: E402,F401

SHARED_SCENES = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "scenes")


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
