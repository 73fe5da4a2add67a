"""The JIT backend of this test run, so that tests which switch variants stay on it.

``MITSUBA_LAB_VARIANT`` picks the run's variant (``llvm_ad_rgb`` by default); with
``cuda_ad_rgb`` the mono, spectral and polarized cases run in their ``cuda_ad_*`` twins.
"""
import mitsuba as mi

import mitsuba_lab  # noqa: F401  (selects the run's variant)

#: The variant every test returns to after switching.
HOME = mi.variant()
#: 'llvm' or 'cuda'.
BACKEND = HOME.split("_", 1)[0]


def variant(kind: str) -> str:
    """This backend's variant of ``kind``: ``variant("ad_mono")`` is ``llvm_ad_mono`` on the CPU."""
    return f"{BACKEND}_{kind}"
