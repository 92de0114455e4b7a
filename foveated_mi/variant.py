"""Variant choice: ``cuda_ad_rgb`` where a CUDA device works, else ``llvm_ad_rgb``.

``FOVEATED_MI_VARIANT`` (or the CLI's ``--variant``) overrides the choice. Dr.Jit 1.5 aborts
with LLVM 15, so before the LLVM backend starts ``DRJIT_LIBLLVM_PATH`` is pinned to an
LLVM >= 16 when one is found and the variable is unset.
"""
from __future__ import annotations

import glob
import os

SUPPORTED = ("cuda_ad_rgb", "llvm_ad_rgb", "cuda_rgb", "llvm_rgb")

_LLVM_CANDIDATES = [
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.{v}.1", "/usr/lib/x86_64-linux-gnu/libLLVM-{v}.so",
    "/usr/lib/aarch64-linux-gnu/libLLVM.so.{v}.1", "/usr/lib/aarch64-linux-gnu/libLLVM-{v}.so",
    "/usr/lib/llvm-{v}/lib/libLLVM.so", "/usr/lib/llvm-{v}/lib/libLLVM-{v}.so",
    "/usr/lib64/libLLVM-{v}.so",
]


def find_llvm() -> str | None:
    """Path of an LLVM >= 16 shared library, newest first, or None.

    Returns
    -------
    path : str or None
        From the usual system locations, else the path noted in ``.venv/llvm-path``.
    """
    for v in range(21, 15, -1):
        for pattern in _LLVM_CANDIDATES:
            for path in glob.glob(pattern.format(v=v)):
                return path
    venv_note = os.path.join(os.path.dirname(__file__), "..", ".venv", "llvm-path")
    if os.path.exists(venv_note):
        path = open(venv_note).read().strip()
        if os.path.exists(path):
            return path
    return None


def pin_llvm() -> None:
    """Set ``DRJIT_LIBLLVM_PATH`` to :func:`find_llvm`'s library, when unset and one is found."""
    if not os.environ.get("DRJIT_LIBLLVM_PATH"):
        path = find_llvm()
        if path:
            os.environ["DRJIT_LIBLLVM_PATH"] = path


def cuda_works() -> bool:
    """Whether Dr.Jit's CUDA backend works on this machine.

    Returns
    -------
    works : bool
        False where the check itself fails.
    """
    import drjit as dr
    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # pragma: no cover - depends on driver state
        return False


def choose_variant(requested: str | None = None) -> str:
    """The variant to use: ``requested``, else ``$FOVEATED_MI_VARIANT``, else CUDA or LLVM.

    Parameters
    ----------
    requested : str or None, optional
        A variant of :data:`SUPPORTED` that this Mitsuba build has.

    Returns
    -------
    variant : str
        The variant: ``cuda_ad_rgb`` where CUDA works, else ``llvm_ad_rgb`` unless one is asked
        for.

    Raises
    ------
    ParameterError
        For a variant that is not available.
    """
    import mitsuba as mi
    from .validate import check_choice

    requested = requested or os.environ.get("FOVEATED_MI_VARIANT") or None
    available = [v for v in mi.variants() if v in SUPPORTED]
    if requested is not None:
        name = "variant" if requested != os.environ.get("FOVEATED_MI_VARIANT") else "FOVEATED_MI_VARIANT"
        return check_choice(name, requested, available)
    if "cuda_ad_rgb" in available and cuda_works():
        return "cuda_ad_rgb"
    return "llvm_ad_rgb"
