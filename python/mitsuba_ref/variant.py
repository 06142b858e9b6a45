"""Choosing Mitsuba's variant: `llvm_ad_rgb` (vectorised, 10-50x faster) when a libLLVM >= 16 is found,
else `scalar_rgb`. libLLVM 15 aborts the process inside drjit ("Cannot select: fminimum"), so only
versions >= 16 are ever offered to drjit. Must run before the first `import mitsuba`.
"""
import glob
import os
import re

_CANDIDATES = [
    "/usr/lib/x86_64-linux-gnu/libLLVM-*.so*",
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.*",
    "/usr/lib/aarch64-linux-gnu/libLLVM-*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM.so.*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
]


def _major(path):
    m = re.search(r"(?:llvm-|LLVM-|LLVM\.so\.)(\d+)", path)
    return int(m.group(1)) if m else 0


def find_libllvm():
    """The newest libLLVM >= 16 on this machine, or None."""
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    if env and os.path.exists(env):
        return env
    found = sorted({p for pat in _CANDIDATES for p in glob.glob(pat)}, key=_major, reverse=True)
    found = [p for p in found if _major(p) >= 16]
    return found[0] if found else None


def select(requested="auto"):
    """Imports mitsuba with the requested variant ("auto", "llvm_ad_rgb" or "scalar_rgb"); returns the
    module. "auto" falls back to scalar_rgb when no suitable libLLVM exists or the llvm variant fails."""
    if requested in ("auto", "llvm_ad_rgb"):
        lib = find_libllvm()
        if lib:
            os.environ["DRJIT_LIBLLVM_PATH"] = lib
        elif requested == "llvm_ad_rgb":
            raise RuntimeError(
                "llvm_ad_rgb needs libLLVM >= 16: install Debian's libllvm19 (apt-get install libllvm19) "
                "or set DRJIT_LIBLLVM_PATH"
            )
    import mitsuba as mi

    if requested == "scalar_rgb" or (requested == "auto" and not find_libllvm()):
        mi.set_variant("scalar_rgb")
        return mi
    try:
        mi.set_variant("llvm_ad_rgb")
    except Exception:  # noqa: BLE001 - any failure of the LLVM backend falls back
        if requested == "llvm_ad_rgb":
            raise
        mi.set_variant("scalar_rgb")
    return mi
