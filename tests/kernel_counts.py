"""Counting the JIT kernels a call compiles (Dr.Jit's kernel history)."""
import drjit as dr


def compiled_by(fn) -> int:
    """Kernels that ``fn()`` compiled (not found in Dr.Jit's kernel cache)."""
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        fn()
        hist = dr.kernel_history([dr.KernelType.JIT])
    return sum(1 for h in hist if not h.get("cache_hit", True))
