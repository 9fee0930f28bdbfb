"""Import Mitsuba with a working Dr.Jit backend.

Dr.Jit's LLVM backend needs libLLVM 16 or newer: 15 aborts inside the JIT with "Cannot select ...
fminimum" and 14 is refused. Dr.Jit reads ``DRJIT_LIBLLVM_PATH`` once, when it is first imported,
so :func:`load_mitsuba` finds a suitable library and sets the variable *before* that import. With
none it falls back to the (slow, but correct) ``scalar_rgb`` variant and warns once.

Every module that needs Mitsuba goes through :func:`load_mitsuba`; nothing imports ``mitsuba`` at
module level, so ``denoisebench.scenes`` and the metrics stay importable without it.
"""

from __future__ import annotations

import glob
import os
import re
import warnings

# Lazy imports: Mitsuba is imported only inside load_mitsuba, which finds libLLVM and picks
# the variant first: importing it anywhere else would fix the variant too early.

MIN_LLVM_MAJOR = 16
LLVM_VARIANT = "llvm_ad_rgb"
SCALAR_VARIANT = "scalar_rgb"

_SEARCH_PATTERNS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib",
    "/usr/local/opt/llvm/lib/libLLVM*.dylib",
)
_warned_scalar = False


def _llvm_major(path: str) -> int | None:
    """Major version from names such as libLLVM-19.so, libLLVM.so.19.1 or llvm-18/lib/libLLVM.so."""
    name = os.path.basename(path)
    match = re.search(r"libLLVM-(\d+)", name) or re.search(r"libLLVM\.so\.(\d+)", name)
    if match is None:
        match = re.search(r"llvm-(\d+)/", path)
    return int(match.group(1)) if match else None


def find_libllvm() -> str | None:
    """Path of the newest libLLVM >= 16 on this machine, or None.

    An existing ``DRJIT_LIBLLVM_PATH`` wins when it names a file whose version is acceptable (or
    cannot be read from its name: the user chose it deliberately).
    """
    preset = os.environ.get("DRJIT_LIBLLVM_PATH")
    if preset and os.path.exists(preset):
        major = _llvm_major(preset)
        if major is None or major >= MIN_LLVM_MAJOR:
            return preset
    candidates = []
    for pattern in _SEARCH_PATTERNS:
        for path in glob.glob(pattern):
            major = _llvm_major(path)
            if major is not None and major >= MIN_LLVM_MAJOR and os.path.isfile(path):
                candidates.append((major, path))
    if not candidates:
        return None
    return max(candidates)[1]


def load_mitsuba(variant: str | None = None):
    """Return the ``mitsuba`` module with a variant set (LLVM when possible).

    ``variant`` forces a variant; by default ``llvm_ad_rgb`` when a libLLVM >= 16 exists, else
    ``scalar_rgb`` with a one-time warning. Calling again is cheap and keeps the variant already set
    unless another is asked for.
    """
    global _warned_scalar
    if "drjit" not in __import__("sys").modules:
        libllvm = find_libllvm()
        if libllvm is not None:
            os.environ["DRJIT_LIBLLVM_PATH"] = libllvm
    import mitsuba as mi

    current = mi.variant()
    if variant is None:
        if current is not None:
            return mi
        variant = LLVM_VARIANT if os.environ.get("DRJIT_LIBLLVM_PATH") and find_libllvm() else SCALAR_VARIANT
        if variant == SCALAR_VARIANT and not _warned_scalar:
            _warned_scalar = True
            warnings.warn(
                "no libLLVM >= 16 found: rendering with the slow scalar_rgb variant "
                "(Debian: apt-get install libllvm19, or set DRJIT_LIBLLVM_PATH)",
                RuntimeWarning,
                stacklevel=2,
            )
    if current != variant:
        try:
            mi.set_variant(variant)
        except Exception:
            if variant != SCALAR_VARIANT:
                if not _warned_scalar:
                    _warned_scalar = True
                    warnings.warn(
                        f"Mitsuba variant {variant} failed to start; falling back to scalar_rgb",
                        RuntimeWarning,
                        stacklevel=2,
                    )
                mi.set_variant(SCALAR_VARIANT)
            else:
                raise
    return mi
