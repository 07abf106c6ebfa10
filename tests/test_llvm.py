"""libLLVM discovery for Dr.Jit (nbrdf_mitsuba.llvm) and its interplay with the import order."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from nbrdf_mitsuba import llvm


@pytest.mark.parametrize("path, version", [
    ("/usr/lib/x86_64-linux-gnu/libLLVM-19.so", 19),
    ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", 19),
    ("/usr/lib/x86_64-linux-gnu/libLLVM-14.0.6.so.1", 14),
    ("/usr/lib/llvm-17/lib/libLLVM.so", 17),
    ("/opt/homebrew/opt/llvm@18/lib/libLLVM.dylib", 18),
    ("/usr/local/Cellar/llvm/20.1.2/lib/libLLVM.dylib", 20),
    ("/somewhere/libLLVM.so", None),
])
def test_parse_version(path, version):
    assert llvm.parse_version(path) == version


def test_find_prefers_the_newest_supported(tmp_path):
    for name in ("libLLVM-14.so.1", "libLLVM-15.so", "libLLVM.so.19.1", "libLLVM-17.so", "libLLVM-20.a"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "libLLVM-19.so").symlink_to(tmp_path / "libLLVM.so.19.1")
    patterns = [str(tmp_path / "libLLVM*.so*"), str(tmp_path / "libLLVM*.a")]
    found = llvm.candidates(patterns)
    assert [v for v, _ in found] == [19, 17, 15, 14]
    assert found[0][1].endswith("libLLVM-19.so")  # one entry per real file, shortest name
    assert llvm.find_libllvm(16, patterns).endswith("libLLVM-19.so")
    assert llvm.find_libllvm(20, patterns) is None
    only_old = [str(tmp_path / "libLLVM-1[45]*")]
    assert llvm.find_libllvm(16, only_old) is None


def run_python(code: str, **env_changes) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    env.update(env_changes)
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True, text=True,
                          timeout=120)


@pytest.mark.skipif(llvm.find_libllvm() is None, reason="no libLLVM >= 16 on this machine")
def test_import_before_drjit_sets_the_library():
    result = run_python("""
        import os, nbrdf_mitsuba, drjit as dr
        print(nbrdf_mitsuba.llvm.status, os.environ["DRJIT_LIBLLVM_PATH"], dr.detail.llvm_version()[0])
    """)
    assert result.returncode == 0, result.stderr
    status, path, major = result.stdout.split()
    assert status == "set" and path == llvm.find_libllvm() and int(major) >= 16


@pytest.mark.skipif(llvm.find_libllvm() is None, reason="no libLLVM >= 16 on this machine")
def test_import_after_drjit_reports_late_and_explicit_path_is_honoured():
    result = run_python("""
        import drjit, mitsuba, nbrdf_mitsuba
        print(nbrdf_mitsuba.llvm.status)
    """)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["late"]
    chosen = llvm.find_libllvm()
    result = run_python("""
        import os, nbrdf_mitsuba
        print(nbrdf_mitsuba.llvm.status, os.environ["DRJIT_LIBLLVM_PATH"])
    """, DRJIT_LIBLLVM_PATH=chosen)
    assert result.stdout.split() == ["env", chosen], result.stderr


def test_unusable_backend_gives_the_instruction(tmp_path):
    """With no usable libLLVM, constructing a BSDF in an llvm variant explains the fix."""
    old = llvm.find_libllvm(0, ["/usr/lib/x86_64-linux-gnu/libLLVM-1[45].so*"])
    library = old or str(tmp_path / "libLLVM-missing.so")
    result = run_python("""
        import warnings
        warnings.simplefilter("always")
        import nbrdf_mitsuba, mitsuba as mi
        print("problem:", nbrdf_mitsuba.llvm.problem())
        mi.set_variant("llvm_ad_rgb")
    """, DRJIT_LIBLLVM_PATH=library)
    output = result.stdout + result.stderr
    assert "problem: Dr.Jit's LLVM backend" in output, output
    assert "apt-get install libllvm19" in output, output
