"""Which Mitsuba variants the lab's plugins run in, checked once in each plugin's constructor."""
from __future__ import annotations


def require_jit_variant(plugin: str) -> None:
    """Raise ValueError (one line) in a scalar variant: the plugins trace Dr.Jit kernels
    (symbolic loops over a wavefront of samples), which scalar variants do not have."""
    import mitsuba as mi

    variant = mi.variant() or ""
    if variant.startswith("scalar"):
        raise ValueError(f"{plugin}: variant '{variant}' is not supported: the lab's plugins run in "
                         f"Dr.Jit's JIT variants (llvm_* or cuda_*, e.g. "
                         f"{variant.replace('scalar', 'llvm_ad', 1)})")
