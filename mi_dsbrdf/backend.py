"""Dr.Jit / Mitsuba start-up: libLLVM selection, variant choice, plugin registration.

Dr.Jit's LLVM backend needs libLLVM >= 16: with LLVM 14/15 the first kernel that
uses ``dr.maximum`` aborts the whole process (``LLVM ERROR: Cannot select ...
fmaximum``). :func:`select_libllvm` points ``DRJIT_LIBLLVM_PATH`` at the newest
suitable library *before* Dr.Jit is imported, and :func:`check_llvm` turns an
unusable one into a :class:`~mi_dsbrdf.errors.BackendError` naming the fix,
instead of an abort later on.
"""
from __future__ import annotations

import functools
import glob
import os
import re
import sys

from mi_dsbrdf.errors import BackendError, VariantError

MIN_LLVM = 16
DEFAULT_VARIANT = "llvm_ad_rgb"
#: Variants the plugins run on: JIT (vectorised) and RGB.
SUPPORTED_VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb")
FIX = ("install a libLLVM >= %d (Debian: `apt-get install libllvm19`; or run "
       "`bash scripts/bootstrap.sh`) or point DRJIT_LIBLLVM_PATH at one" % MIN_LLVM)

_LIB_PATTERNS = ("/usr/lib/*/libLLVM-*.so", "/usr/lib/*/libLLVM.so.*",
                 "/usr/lib/llvm-*/lib/libLLVM*.so*", "/usr/local/lib/libLLVM*.so*")


def _major(path: str) -> int | None:
    m = re.search(r"libLLVM[-.](?:so\.)?(\d+)", os.path.basename(path))
    return int(m.group(1)) if m else None


def find_libllvm(min_major: int = MIN_LLVM) -> str | None:
    """Path of the newest libLLVM with major version >= ``min_major``, or None."""
    found = [(_major(p), p) for pat in _LIB_PATTERNS for p in glob.glob(pat)]
    found = [(v, p) for v, p in found if v is not None and v >= min_major]
    return max(found)[1] if found else None


def select_libllvm() -> None:
    """Set DRJIT_LIBLLVM_PATH to a libLLVM >= 16 unless the user chose one.

    Has an effect only before ``drjit`` is first imported.
    """
    if "drjit" in sys.modules or os.environ.get("DRJIT_LIBLLVM_PATH"):
        return
    path = find_libllvm()
    if path:
        os.environ["DRJIT_LIBLLVM_PATH"] = path


def check_llvm() -> tuple:
    """Raise BackendError unless Dr.Jit's LLVM backend runs on libLLVM >= 16."""
    import drjit as dr
    if not dr.has_backend(dr.JitBackend.LLVM):
        raise BackendError("Dr.Jit's LLVM backend could not load libLLVM: " + FIX)
    version = tuple(dr.detail.llvm_version())
    if version[0] < MIN_LLVM:
        raise BackendError(
            "Dr.Jit is using libLLVM %s, which aborts on kernels mi-dsbrdf "
            "compiles (`Cannot select ... fmaximum`); %s" % (".".join(map(str, version)), FIX))
    return version


def ensure_variant() -> str:
    """Select llvm_ad_rgb when no variant is set; check an LLVM one; return it."""
    import mitsuba as mi
    variant = mi.variant()
    if variant is None:
        check_llvm()
        mi.set_variant(DEFAULT_VARIANT)
        return DEFAULT_VARIANT
    if variant.startswith("llvm"):
        check_llvm()
    return variant


def require_supported_variant(plugin: str) -> None:
    """Raise VariantError when the active variant cannot run ``plugin``."""
    import mitsuba as mi
    variant = mi.variant()
    if variant not in SUPPORTED_VARIANTS:
        raise VariantError(
            "the %r plugin needs one of the Mitsuba variants %s (JIT, RGB, "
            "differentiable); the active variant is %r: call "
            "mi.set_variant('llvm_ad_rgb') before loading the scene"
            % (plugin, ", ".join(SUPPORTED_VARIANTS), variant))


def register_plugins(*_args) -> None:
    """Register the package's plugins for the active variant.

    Called on import and again by Mitsuba whenever the variant changes. Under an
    unsupported variant the names are still registered, with constructors that
    raise a :class:`VariantError` saying which variant to use.
    """
    import mitsuba as mi
    if mi.variant() is None:
        return
    from mi_dsbrdf.plugins import bsdf_classes
    for name, cls in bsdf_classes(mi.variant()).items():
        mi.register_bsdf(name, _factory(name, cls))


def _factory(name, cls):
    def make(props):
        require_supported_variant(name)
        return cls(props)
    return make


_callback_installed = False


def install_variant_callback() -> None:
    """Re-register the plugins each time ``mi.set_variant`` switches variant."""
    global _callback_installed
    if _callback_installed:
        return
    import mitsuba as mi
    mi.detail.add_variant_callback(register_plugins)
    _callback_installed = True


def one_blas_thread() -> None:
    """One BLAS thread in worker processes started after this call (they inherit
    the environment), unless the user set a count: with several worker processes
    already filling the cores, OpenBLAS threads of each spin against the others'
    (full fits run 2-4x slower, two workers on two cores)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")


#: glibc's mallopt parameters: keep this much freed memory at the top of the heap
#: instead of handing it back to the kernel at once, and serve allocations below
#: the mmap threshold (glibc's largest) from the heap (a transport, 100 MB, is
#: still mapped and unmapped on its own)
M_TOP_PAD, TOP_PAD_BYTES = -2, 64 << 20
M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES = -3, 32 << 20
_allocator_tuned = False


def keep_freed_memory() -> None:
    """Let glibc keep up to TOP_PAD_BYTES of freed heap memory for reuse (once per
    process; nothing on other C libraries). Inference allocates and frees
    arrays of a few MB thousands of times (Jacobian columns, images, their
    products); by default glibc returns them to the kernel and the next one
    page-faults in again (a point-light Jacobian: 12 ms, 3 ms with this)."""
    global _allocator_tuned
    if _allocator_tuned:
        return
    _allocator_tuned = True
    import ctypes
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt(M_TOP_PAD, TOP_PAD_BYTES)
    mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)


def single_blas_thread(function):
    """Decorator: ``function`` runs with BLAS on one thread (threadpoolctl), and
    with glibc keeping freed memory for reuse (:func:`keep_freed_memory`).
    Inference alternates Dr.Jit kernels (on Dr.Jit's own thread pool) with BLAS
    products of the transport, which are bound by memory bandwidth: a second
    BLAS thread does not speed them up, and its spinning against Dr.Jit's
    threads makes a whole recovery about 1.5x slower."""
    from threadpoolctl import threadpool_limits

    @functools.wraps(function)
    def run(*args, **kwargs):
        keep_freed_memory()
        with threadpool_limits(limits=1, user_api="blas"):
            return function(*args, **kwargs)
    return run
