"""Finds a libLLVM that Dr.Jit's LLVM backend can use (version 16 or newer).

Dr.Jit reads ``DRJIT_LIBLLVM_PATH`` exactly once, when its binary extension initialises, i.e. at
the first ``import drjit`` (``import mitsuba`` imports drjit). It then keeps that libLLVM (or an
inactive LLVM backend) for the life of the process: setting the variable later, or calling
``mi.set_variant``, changes nothing. Older libLLVMs (14, 15) load but abort at JIT time with
"Cannot select" on Mitsuba's kernels.

So :func:`configure` (run by ``import nbrdf_mitsuba``) sets ``DRJIT_LIBLLVM_PATH`` only when
drjit has not been imported yet and the variable is unset; when drjit was imported first it can
only check what Dr.Jit loaded (:func:`check_backend`) and explain the fix.

This is the implementation; :mod:`nbrdf_mitsuba.llvm` is its public face and command line
(``python -m nbrdf_mitsuba.llvm [--quiet]``). The split keeps ``python -m`` from running a
second, unconfigured copy of this module.
"""

from __future__ import annotations

import glob
import os
import re
import sys
import warnings

MIN_MAJOR = 16
ENV = "DRJIT_LIBLLVM_PATH"

INSTRUCTION = (
    f"install libLLVM >= {MIN_MAJOR}, e.g. `apt-get install libllvm19`, or set {ENV} to the "
    f"path of a libLLVM >= {MIN_MAJOR} before Python imports drjit/mitsuba (or import "
    "nbrdf_mitsuba before mitsuba, which sets it when it finds one)"
)

#: Where libLLVM usually lives (Debian/Ubuntu multiarch, versioned LLVM trees, Fedora, /usr/local,
#: conda environments, Homebrew, the Windows installer).
SEARCH_PATTERNS = [
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/lib64/llvm*/lib/libLLVM*.so*",
    "/usr/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/usr/local/opt/llvm*/lib/libLLVM.dylib",
    "/opt/homebrew/opt/llvm*/lib/libLLVM.dylib",
    "/usr/local/lib/libLLVM*.dylib",
    os.path.join(sys.prefix, "lib", "libLLVM*.so*"),
    os.path.join(sys.prefix, "lib", "libLLVM*.dylib"),
    "C:/Program Files/LLVM/bin/LLVM-C.dll",
]

_VERSION_PATTERNS = [
    re.compile(r"libLLVM-(\d+)"),  # libLLVM-19.so, libLLVM-14.0.6.so.1
    re.compile(r"libLLVM\.so\.(\d+)"),  # libLLVM.so.19.1
    re.compile(r"llvm[-@](\d+)"),  # /usr/lib/llvm-19/lib, llvm@18
    re.compile(r"/llvm/(\d+)\.\d+"),  # Homebrew Cellar/llvm/19.1.7
]

#: What :func:`configure` did: "env" (DRJIT_LIBLLVM_PATH was set), "set" (we set it),
#: "missing" (nothing found), "late" (drjit was already imported).
status: str = "unconfigured"
#: The libLLVM chosen or honoured by :func:`configure`, if any.
chosen: str | None = None


def parse_version(path: str | os.PathLike) -> int | None:
    """Major LLVM version from a library path (its symlink target included), if it shows one."""
    for candidate in (str(path), os.path.realpath(path)):
        for pattern in _VERSION_PATTERNS:
            match = pattern.search(candidate)
            if match:
                return int(match.group(1))
    return None


def candidates(patterns: list[str] | None = None) -> list[tuple[int, str]]:
    """(major version, path) of every libLLVM found, newest first, one per real file."""
    found: dict[str, tuple[int, str]] = {}
    for pattern in SEARCH_PATTERNS if patterns is None else patterns:
        for path in sorted(glob.glob(pattern)):
            if path.endswith(".a") or not os.path.isfile(path):
                continue
            version = parse_version(path)
            if version is None:
                continue
            real = os.path.realpath(path)
            # Prefer the shortest name for a file (libLLVM-19.so over libLLVM.so.19.1).
            if real not in found or len(path) < len(found[real][1]):
                found[real] = (version, path)
    return sorted(found.values(), key=lambda vp: (-vp[0], len(vp[1]), vp[1]))


def find_libllvm(min_major: int = MIN_MAJOR, patterns: list[str] | None = None) -> str | None:
    """Path of the newest libLLVM with major version >= ``min_major``, or None."""
    for version, path in candidates(patterns):
        if version >= min_major:
            return path
    return None


def configure() -> str:
    """Points Dr.Jit at a usable libLLVM if that is still possible; returns :data:`status`."""
    global status, chosen
    if "drjit" in sys.modules:
        status, chosen = "late", os.environ.get(ENV)
        _warn_if_backend_unusable()
    elif os.environ.get(ENV):
        status, chosen = "env", os.environ[ENV]
        version = parse_version(chosen)
        if not os.path.isfile(chosen):
            warnings.warn(f"{ENV}={chosen} does not exist; Dr.Jit's LLVM backend will be unavailable "
                          f"({INSTRUCTION})", stacklevel=3)
        elif version is not None and version < MIN_MAJOR:
            warnings.warn(f"{ENV}={chosen} is LLVM {version}; Dr.Jit's LLVM variants need "
                          f"LLVM >= {MIN_MAJOR} ({INSTRUCTION})", stacklevel=3)
    else:
        chosen = find_libllvm()
        if chosen:
            os.environ[ENV] = chosen
            status = "set"
        else:
            status = "missing"
            warnings.warn(f"nbrdf_mitsuba: no libLLVM >= {MIN_MAJOR} found, Mitsuba's llvm_* "
                          f"variants may not work: {INSTRUCTION}", stacklevel=3)
    return status


def backend_version() -> tuple[int, int, int]:
    """The libLLVM version Dr.Jit loaded; (-1, -1, -1) when its LLVM backend is inactive."""
    import drjit as dr

    return tuple(dr.detail.llvm_version())


def problem() -> str | None:
    """Why Dr.Jit's LLVM backend is unusable for Mitsuba, or None when it is fine."""
    version = backend_version()
    if version[0] >= MIN_MAJOR:
        return None
    what = "is inactive (no libLLVM was loaded)" if version[0] < 0 else \
        f"uses LLVM {'.'.join(map(str, version))}, which fails on Mitsuba's kernels"
    message = f"Dr.Jit's LLVM backend {what}; "
    better = find_libllvm()
    if status == "late" and better:
        message += (f"a suitable library exists at {better}: set {ENV}={better} before Python starts, "
                    "or import nbrdf_mitsuba before drjit/mitsuba")
    else:
        message += INSTRUCTION
    return message


def check_backend() -> None:
    """Raises RuntimeError with the fix when Dr.Jit's LLVM backend cannot run Mitsuba."""
    message = problem()
    if message:
        raise RuntimeError(message)


def _warn_if_backend_unusable() -> None:
    message = problem()
    if message:
        warnings.warn(f"nbrdf_mitsuba was imported after drjit: {message}", stacklevel=4)


def describe() -> str:
    """One line for logs: what configure() did."""
    return f"{status} ({ENV}={os.environ.get(ENV, '<unset>')})"


def main(argv: list[str] | None = None) -> int:
    """``python -m nbrdf_mitsuba.llvm [--quiet]``: lists the libLLVMs found and what Dr.Jit
    loaded; exit status 0 when Dr.Jit's LLVM backend is usable (libLLVM >= 16), else 1."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m nbrdf_mitsuba.llvm",
                                     description="Check that Dr.Jit's LLVM backend has a libLLVM >= 16.")
    parser.add_argument("-q", "--quiet", action="store_true", help="print only problems")
    args = parser.parse_args(argv)
    message = problem()  # imports drjit, after configure() ran on `import nbrdf_mitsuba`
    if not args.quiet:
        for version, path in candidates():
            print(f"found LLVM {version:3d}  {path}")
        print(f"{ENV}: {describe()}")
        print("Dr.Jit's LLVM backend:", ".".join(map(str, backend_version())) if not message else message)
    elif message:
        print(f"error: {message}", file=sys.stderr)
    return 1 if message else 0
