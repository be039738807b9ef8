"""Start-up: libLLVM choice, variant selection and re-registration, wrong variants.

Each case runs in a fresh interpreter: variants and Dr.Jit's LLVM library are
process-wide state.
"""
import glob
import os
import subprocess
import sys

import pytest

from mi_dsbrdf.backend import MIN_LLVM, find_libllvm


def run_python(code, **env):
    e = dict(os.environ)
    e.update(env)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=e, timeout=120)


def test_find_libllvm_returns_a_new_enough_library():
    path = find_libllvm()
    assert path is not None and os.path.exists(path)
    import drjit as dr
    assert dr.detail.llvm_version()[0] >= MIN_LLVM


def test_default_variant_and_switching_reregisters_plugins():
    r = run_python(
        "import mitsuba as mi, mi_dsbrdf\n"
        "assert mi.variant() == 'llvm_ad_rgb'\n"
        "mi.load_dict({'type': 'dsbrdf'})\n"
        "mi.set_variant('scalar_rgb')\n"
        "try:\n"
        "    mi.load_dict({'type': 'dsbrdf'})\n"
        "except RuntimeError as e:\n"
        "    assert 'needs one of the Mitsuba variants' in str(e) and 'scalar_rgb' in str(e), e\n"
        "else:\n"
        "    raise SystemExit('no error under scalar_rgb')\n"
        "mi.set_variant('llvm_ad_rgb')\n"
        "b = mi.load_dict({'type': 'dsbrdf'})\n"
        "assert 'DSBRDF' in str(b)\n"
        "print('ok')\n")
    assert r.returncode == 0 and "ok" in r.stdout, r.stderr[-2000:]


def test_variant_set_before_import_is_kept():
    r = run_python("import mitsuba as mi\nmi.set_variant('llvm_ad_mono')\nimport mi_dsbrdf\n"
                   "assert mi.variant() == 'llvm_ad_mono'\n"
                   "try:\n    mi.load_dict({'type': 'merl'})\nexcept RuntimeError as e:\n"
                   "    assert 'needs one of the Mitsuba variants' in str(e)\n    print('ok')\n")
    assert r.returncode == 0 and "ok" in r.stdout, r.stderr[-2000:]


def test_old_libllvm_gives_clear_error_instead_of_abort():
    old = sorted(p for p in glob.glob("/usr/lib/*/libLLVM-1[45].so*") + glob.glob("/usr/lib/*/libLLVM.so.1[45]*"))
    if not old:
        pytest.skip("no libLLVM 14/15 on this machine to test with")
    r = run_python("import mi_dsbrdf", DRJIT_LIBLLVM_PATH=old[0])
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])   # an exception, not an abort (134)
    assert "BackendError" in r.stderr and "libllvm19" in r.stderr


def test_missing_libllvm_gives_clear_error():
    r = run_python("import mi_dsbrdf", DRJIT_LIBLLVM_PATH="/nonexistent/libLLVM.so")
    assert r.returncode == 1 and "BackendError" in r.stderr and "could not load libLLVM" in r.stderr
