"""Build steps of nbrdf-mitsuba (metadata in pyproject.toml).

* The ``nbrdf`` command (nbrdf-core's binary, feature ``cli``) is a setuptools-rust ``RustBin``:
  the wheel installs it into the environment's ``bin/``.
* The C library ``libnbrdf_ffi``, which the plugin loads through cffi in ABI mode (so it is not a
  CPython extension module), is built with ``cargo build --release -p nbrdf-ffi`` and copied into
  the package with its header ``nbrdf.h``.
* The trainer's C library ``libnbrdf_train`` (nbrdf-ffi/train, which ``python -m
  nbrdf_mitsuba.distill`` alone loads) is built with its own ``cargo build --release -p
  nbrdf-train-ffi`` (one call per library, so that the rendering library's features stay its own)
  and bundled with its header ``nbrdf_train.h``.
* The Cargo workspace is the parent of this directory in a checkout; the sdist carries a copy
  of it under ``rust/`` (only what the two crates need), so that it builds on its own.
* The wheel is tagged ``py3-none-<platform>``: any Python 3, this platform. ``auditwheel repair``
  turns ``linux_x86_64`` into a ``manylinux`` tag (neither file links more than glibc).

Environment:

* NBRDF_LIBRARY   - a prebuilt libnbrdf_ffi (.so/.dylib/.dll): copied instead of building;
* NBRDF_HEADER    - the header to bundle (default: <workspace>/nbrdf-ffi/include/nbrdf.h, or
                    nbrdf.h next to NBRDF_LIBRARY);
* NBRDF_TRAIN_LIBRARY - a prebuilt libnbrdf_train (default: the one next to NBRDF_LIBRARY when
                    that is set and it exists, else built);
* NBRDF_WORKSPACE - the Cargo workspace (default: ./rust in an sdist, else the parent folder);
* CARGO, CARGO_TARGET_DIR and the other Cargo variables are honoured (the output directory is
  asked from ``cargo metadata``).
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py as _build_py
from setuptools.command.sdist import sdist as _sdist
from setuptools_rust import RustBin

try:
    import tomllib
except ImportError:  # Python < 3.11
    import tomli as tomllib

HERE = Path(__file__).resolve().parent
PACKAGE = "nbrdf_mitsuba"
SDIST_WORKSPACE = "rust"
# What the sdist copies of the workspace: its manifest, lock file and licence, and every member
# crate (sources, embedded data, benches and tests, as the manifests name them) without build output.
WORKSPACE_FILES = ["Cargo.toml", "Cargo.lock", "LICENSE"]
IGNORED_IN_CRATES = shutil.ignore_patterns("target", "__pycache__", "*.orig", "*.rej")

if sys.platform == "win32":
    LIBRARY, TRAIN_LIBRARY = "nbrdf_ffi.dll", "nbrdf_train.dll"
elif sys.platform == "darwin":
    LIBRARY, TRAIN_LIBRARY = "libnbrdf_ffi.dylib", "libnbrdf_train.dylib"
else:
    LIBRARY, TRAIN_LIBRARY = "libnbrdf_ffi.so", "libnbrdf_train.so"


def _fail(message):
    raise SystemExit(f"nbrdf-mitsuba build: {message}")


def _is_workspace(root: Path) -> bool:
    return (root / "Cargo.toml").is_file() and (root / "nbrdf-ffi").is_dir() and (root / "nbrdf-core").is_dir()


def _workspace():
    if "NBRDF_WORKSPACE" in os.environ:
        candidates = [Path(os.environ["NBRDF_WORKSPACE"])]
    else:
        candidates = [HERE / SDIST_WORKSPACE, HERE.parent]
    return next((c.resolve() for c in candidates if _is_workspace(c)), None)


def _cargo_build(workspace, package="nbrdf-ffi", library_name=LIBRARY):
    cargo = os.environ.get("CARGO", "cargo")
    # For nbrdf-ffi, without nbrdf-core's `cli` (or `train`) feature: the library the renderer
    # loads carries neither the command line's dependencies nor the training stack.
    command = [cargo, "build", "--release", "-p", package]
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
    library = target / "release" / library_name
    if not library.is_file():
        _fail(f"cargo succeeded but {library} does not exist")
    return library


def _no_workspace():
    _fail(f"no Cargo workspace in {HERE / SDIST_WORKSPACE} or {HERE.parent} (building from a copy of "
          f"mitsuba-plugin/ alone?): build from the nbrdf repository or its sdist, or set NBRDF_WORKSPACE")


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
        _no_workspace()
    candidates = [os.environ.get("NBRDF_HEADER")]
    if workspace is not None:
        candidates.append(workspace / "nbrdf-ffi" / "include" / "nbrdf.h")
    candidates.append(library.parent / "nbrdf.h")
    header = next((Path(c) for c in candidates if c and Path(c).is_file()), None)
    if header is None:
        _fail("nbrdf.h not found: set NBRDF_HEADER")
    return library, header


def train_native_files(library: Path):
    """(libnbrdf_train, nbrdf_train.h) to bundle, next to the rendering ``library``."""
    workspace = _workspace()
    prebuilt = os.environ.get("NBRDF_TRAIN_LIBRARY")
    beside = library.parent / TRAIN_LIBRARY
    if prebuilt:
        train = Path(prebuilt).resolve()
        if not train.is_file():
            _fail(f"NBRDF_TRAIN_LIBRARY={prebuilt} does not exist")
    elif os.environ.get("NBRDF_LIBRARY") and beside.is_file():
        train = beside
    elif workspace is not None:
        train = _cargo_build(workspace, "nbrdf-train-ffi", TRAIN_LIBRARY)
    else:
        _no_workspace()
    candidates = [workspace / "nbrdf-ffi" / "train" / "include" / "nbrdf_train.h"] if workspace else []
    candidates.append(train.parent / "nbrdf_train.h")
    header = next((c for c in candidates if c.is_file()), None)
    if header is None:
        _fail("nbrdf_train.h not found")
    return train, header


class build_py(_build_py):
    """Also builds and bundles the native library and its header."""

    def run(self):
        super().run()
        library, header = native_files()
        train_library, train_header = train_native_files(library)
        # Editable installs import the package from the source tree.
        targets = [HERE / PACKAGE] if getattr(self, "editable_mode", False) else [Path(self.build_lib) / PACKAGE]
        for target in targets:
            target.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(library, target / LIBRARY)
            shutil.copyfile(header, target / "nbrdf.h")
            shutil.copyfile(train_library, target / TRAIN_LIBRARY)
            shutil.copyfile(train_header, target / "nbrdf_train.h")
            # The pretrained autoencoder, whose decoder nbrdf_mitsuba.latent reads (the C ABI carries no models).
            models = (_workspace() or HERE) / "nbrdf-core" / "data" / "models" / "autoencoder.json"
            if models.is_file():
                shutil.copyfile(models, target / "autoencoder.json")
            print(f"nbrdf-mitsuba build: bundled {library}, {train_library} and their headers into {target}",
                  flush=True)


def workspace_members(workspace: Path) -> list:
    """The member crate folders of the workspace's Cargo.toml (globs expanded)."""
    manifest = tomllib.loads((workspace / "Cargo.toml").read_text(encoding="utf-8"))
    patterns = manifest.get("workspace", {}).get("members", [])
    members = sorted({path for pattern in patterns for path in workspace.glob(pattern)
                      if (path / "Cargo.toml").is_file()})
    if not members:
        _fail(f"{workspace / 'Cargo.toml'} names no member crates")
    return members


class sdist(_sdist):
    """Copies the Cargo workspace (what the crates need to build) into the sdist under rust/."""

    def make_release_tree(self, base_dir, files):
        super().make_release_tree(base_dir, files)
        workspace = _workspace()
        if workspace is None:
            _no_workspace()
        target = Path(base_dir) / SDIST_WORKSPACE
        for name in WORKSPACE_FILES:
            if (workspace / name).is_file():
                target.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(workspace / name, target / name)
                if name == "LICENSE":  # the licence also belongs beside the Python metadata
                    shutil.copyfile(workspace / name, Path(base_dir) / name)
        for member in workspace_members(workspace):
            # A member nested in another (nbrdf-ffi/train) came with its parent already.
            shutil.copytree(member, target / member.relative_to(workspace), ignore=IGNORED_IN_CRATES,
                            dirs_exist_ok=True)
        print(f"nbrdf-mitsuba sdist: copied the Cargo workspace {workspace} into {target}", flush=True)


class BinaryDistribution(Distribution):
    """The wheel carries a native library: install it as platform-specific (platlib)."""

    def has_ext_modules(self):
        return True


cmdclass = {"build_py": build_py, "sdist": sdist}

# ...for this platform, but any Python 3 (cffi ABI mode and an executable: no extension module).
try:
    from setuptools.command.bdist_wheel import bdist_wheel as _bdist_wheel
except ImportError:
    from wheel.bdist_wheel import bdist_wheel as _bdist_wheel


class bdist_wheel(_bdist_wheel):
    def get_tag(self):
        _, _, platform = super().get_tag()
        return "py3", "none", platform


cmdclass["bdist_wheel"] = bdist_wheel


def rust_binaries():
    workspace = _workspace()
    if workspace is None:
        return []  # sdist and metadata steps need no Rust; build_py reports the missing workspace
    return [RustBin("nbrdf", path=str(workspace / "nbrdf-core" / "Cargo.toml"), features=["cli"],
                    args=["--bin", "nbrdf"])]


setup(cmdclass=cmdclass, distclass=BinaryDistribution, rust_extensions=rust_binaries())
