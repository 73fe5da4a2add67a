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


def plugin_settings(plugin: str, props, parameters, kind: str) -> dict:
    """What every lab plugin's constructor does first: refuse an unsupported variant, then
    read its declared parameters from ``props`` (``params.read_properties``), before the
    Mitsuba base class reads any of them."""
    from mitsuba_lab.plugins import params

    require_jit_variant(plugin)
    return params.read_properties(plugin, props, parameters, kind)
