"""The one place that touches Dr.Jit's LLVM backend choice and Mitsuba's variant.

Dr.Jit 1.5 with libLLVM 15 (Debian bookworm's default) aborts the whole process
with ``LLVM ERROR: Cannot select ... fminimum`` at the first kernel compile.
Dr.Jit reads ``DRJIT_LIBLLVM_PATH`` when its LLVM backend starts, so the path
must be set before any array is created: :func:`configure_llvm` runs before
Mitsuba is imported.
"""
from __future__ import annotations

import glob
import os
import re
from dataclasses import dataclass

from .errors import LabError

#: Oldest libLLVM major version that Dr.Jit 1.5 can use.
MIN_LLVM_MAJOR = 16
DEFAULT_VARIANT = "llvm_ad_rgb"
VARIANT_ENV = "MITSUBA_LAB_VARIANT"

_LIB_DIRS = (
    "/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64",
    "/usr/lib", "/usr/local/lib", "/usr/lib/llvm-*/lib", "/opt/homebrew/opt/llvm/lib",
)
# libLLVM-19.so, libLLVM.so.19.1, libLLVM-14.0.6.so.1, libLLVM.so.1 (no version: skipped)
_VERSION_RE = re.compile(r"libLLVM(?:-(\d+)(?:\.(\d+))?[^/]*\.so.*|\.so\.(\d+)(?:\.(\d+))?.*)$")


@dataclass(frozen=True, order=True)
class LlvmLibrary:
    major: int
    minor: int
    path: str


def parse_llvm_version(filename: str) -> tuple[int, int] | None:
    """(major, minor) encoded in a libLLVM file name, or None."""
    m = _VERSION_RE.search(os.path.basename(filename))
    if not m:
        return None
    major = m.group(1) or m.group(3)
    minor = m.group(2) or m.group(4) or "0"
    return int(major), int(minor)


def find_llvm_libraries(dirs=_LIB_DIRS) -> list[LlvmLibrary]:
    """Every libLLVM shared library found in the usual folders, newest first."""
    found = {}
    for pattern in dirs:
        for folder in glob.glob(pattern):
            for path in glob.glob(os.path.join(folder, "libLLVM*.so*")):
                version = parse_llvm_version(path)
                real = os.path.realpath(path)
                if version and os.path.isfile(real):
                    found.setdefault(real, LlvmLibrary(version[0], version[1], path))
    return sorted(found.values(), reverse=True)


def configure_llvm(environ=os.environ, dirs=_LIB_DIRS) -> str | None:
    """Point DRJIT_LIBLLVM_PATH at the newest usable libLLVM unless the user chose one.

    Returns the path in force (None when the user's own setting is kept).
    Raises LabError naming the version found when only old ones exist.
    """
    if environ.get("DRJIT_LIBLLVM_PATH"):
        return None
    libs = find_llvm_libraries(dirs)
    usable = [lib for lib in libs if lib.major >= MIN_LLVM_MAJOR]
    if usable:
        environ["DRJIT_LIBLLVM_PATH"] = usable[0].path
        return usable[0].path
    if libs:
        raise LabError(
            f"found only libLLVM {libs[0].major}.{libs[0].minor} ({libs[0].path}); Dr.Jit needs "
            f"libLLVM >= {MIN_LLVM_MAJOR}: run `apt-get install libllvm19` (or set DRJIT_LIBLLVM_PATH)")
    # No LLVM at all: the LLVM variants will be unavailable, a CUDA one may still work.
    return None


def requested_variant(explicit: str | None = None) -> str:
    return explicit or os.environ.get(VARIANT_ENV) or DEFAULT_VARIANT


def set_variant(name: str) -> str:
    """Select a Mitsuba variant, with one clear line when it cannot run here."""
    import drjit as dr
    import mitsuba as mi

    if name not in mi.variants():
        raise LabError(f"unknown variant '{name}'; this Mitsuba build has: {', '.join(mi.variants())}")
    if name.startswith("cuda") and not dr.has_backend(dr.JitBackend.CUDA):
        raise LabError(f"variant '{name}' needs an NVIDIA GPU with a CUDA driver, and none was found")
    if name.startswith("llvm"):
        if not dr.has_backend(dr.JitBackend.LLVM):
            raise LabError(f"variant '{name}' needs libLLVM >= {MIN_LLVM_MAJOR}, and none could be "
                           "loaded: run `apt-get install libllvm19`")
        version = dr.detail.llvm_version()
        if version[0] < MIN_LLVM_MAJOR:
            raise LabError(
                f"Dr.Jit loaded libLLVM {version[0]}.{version[1]} "
                f"({os.environ.get('DRJIT_LIBLLVM_PATH', 'system default')}), which aborts on "
                f"kernels Mitsuba needs: run `apt-get install libllvm19` and point "
                f"DRJIT_LIBLLVM_PATH at it")
    if mi.variant() != name:
        mi.set_variant(name)
    return name


def activate(variant: str | None = None) -> str:
    """``mitsuba_lab.activate``: configure libLLVM, select ``variant`` (or the default; an
    already selected one is kept when None) and register the lab plugins for it."""
    configure_llvm()
    import mitsuba as mi

    if variant is not None or not mi.variant():
        set_variant(requested_variant(variant))
    from .plugins import register_all

    register_all()
    return mi.variant()


def versions() -> dict[str, str]:
    """Versions worth writing next to every number this lab produces."""
    import drjit as dr
    import mitsuba as mi

    info = {"mitsuba": mi.__version__, "drjit": dr.__version__, "variant": mi.variant() or ""}
    if dr.has_backend(dr.JitBackend.LLVM):
        info["libllvm"] = ".".join(str(v) for v in dr.detail.llvm_version())
    return info
