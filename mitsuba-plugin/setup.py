"""Build step of nbrdf-mitsuba: compiles the C ABI library and bundles it with the package.

`build_py` runs `cargo build --release -p nbrdf-ffi` in the Cargo workspace one level up (or in
$NBRDF_WORKSPACE) and copies the shared library and the committed header `nbrdf.h` into the
package. Environment:

* NBRDF_LIBRARY   - a prebuilt libnbrdf_ffi (.so/.dylib/.dll): copied instead of building;
* NBRDF_HEADER    - the header to bundle (default: <workspace>/nbrdf-ffi/include/nbrdf.h, or
                    nbrdf.h next to NBRDF_LIBRARY);
* NBRDF_WORKSPACE - the Cargo workspace (default: the parent of this directory);
* CARGO, CARGO_TARGET_DIR and the other Cargo variables are honoured (the output directory is
  asked from `cargo metadata`).
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py as _build_py

HERE = Path(__file__).resolve().parent
PACKAGE = "nbrdf_mitsuba"

if sys.platform == "win32":
    LIBRARY = "nbrdf_ffi.dll"
elif sys.platform == "darwin":
    LIBRARY = "libnbrdf_ffi.dylib"
else:
    LIBRARY = "libnbrdf_ffi.so"


def _fail(message):
    raise SystemExit(f"nbrdf-mitsuba build: {message}")


def _workspace():
    root = Path(os.environ.get("NBRDF_WORKSPACE", HERE.parent)).resolve()
    if not (root / "Cargo.toml").is_file() or not (root / "nbrdf-ffi").is_dir():
        return None
    return root


def _cargo_build(workspace):
    cargo = os.environ.get("CARGO", "cargo")
    command = [cargo, "build", "--release", "-p", "nbrdf-ffi"]
    print(f"nbrdf-mitsuba build: running {' '.join(command)} in {workspace}", flush=True)
    try:
        subprocess.run(command, cwd=workspace, check=True)
        metadata = subprocess.run(
            [cargo, "metadata", "--format-version", "1", "--no-deps"],
            cwd=workspace, check=True, capture_output=True, text=True,
        )
    except FileNotFoundError:
        _fail(f"`{cargo}` not found: install Rust (https://rustup.rs) or set NBRDF_LIBRARY to a prebuilt {LIBRARY}")
    except subprocess.CalledProcessError as error:
        _fail(f"`{' '.join(error.cmd)}` failed with status {error.returncode}")
    target = Path(json.loads(metadata.stdout)["target_directory"])
    library = target / "release" / LIBRARY
    if not library.is_file():
        _fail(f"cargo succeeded but {library} does not exist")
    return library


def native_files():
    """(library, header) to bundle."""
    workspace = _workspace()
    prebuilt = os.environ.get("NBRDF_LIBRARY")
    if prebuilt:
        library = Path(prebuilt).resolve()
        if not library.is_file():
            _fail(f"NBRDF_LIBRARY={prebuilt} does not exist")
    elif workspace is not None:
        library = _cargo_build(workspace)
    else:
        _fail(f"no Cargo workspace at {HERE.parent} (building from a copy of the sources?): set NBRDF_WORKSPACE "
              f"to the nbrdf repository or NBRDF_LIBRARY to a prebuilt {LIBRARY}")
    candidates = [os.environ.get("NBRDF_HEADER")]
    if workspace is not None:
        candidates.append(workspace / "nbrdf-ffi" / "include" / "nbrdf.h")
    candidates.append(library.parent / "nbrdf.h")
    header = next((Path(c) for c in candidates if c and Path(c).is_file()), None)
    if header is None:
        _fail("nbrdf.h not found: set NBRDF_HEADER")
    return library, header


class build_py(_build_py):
    """Also builds and bundles the native library and its header."""

    def run(self):
        super().run()
        library, header = native_files()
        # Editable installs import the package from the source tree.
        targets = [HERE / PACKAGE] if getattr(self, "editable_mode", False) else [Path(self.build_lib) / PACKAGE]
        for target in targets:
            target.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(library, target / LIBRARY)
            shutil.copyfile(header, target / "nbrdf.h")
            print(f"nbrdf-mitsuba build: bundled {library} and {header} into {target}", flush=True)


cmdclass = {"build_py": build_py}

class BinaryDistribution(Distribution):
    """The wheel carries a native library: install it as platform-specific (platlib)."""

    def has_ext_modules(self):
        return True


# ...for this platform, but any Python 3 (cffi ABI mode, no extension module).
try:
    try:
        from setuptools.command.bdist_wheel import bdist_wheel as _bdist_wheel
    except ImportError:
        from wheel.bdist_wheel import bdist_wheel as _bdist_wheel

    class bdist_wheel(_bdist_wheel):
        def get_tag(self):
            _, _, platform = super().get_tag()
            return "py3", "none", platform

    cmdclass["bdist_wheel"] = bdist_wheel
except ImportError:
    pass

setup(cmdclass=cmdclass, distclass=BinaryDistribution)
