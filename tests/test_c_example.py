"""C users: `make install PREFIX=...` (library with SONAME, header, nbrdf.pc, the nbrdf command),
then examples/c built through pkg-config and run without LD_LIBRARY_PATH. Its printed numbers are
checked against the float64 NumPy oracles of nbrdf_testing (network and Blinn-Phong pdf)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from nbrdf_testing import nbrdf_reference, phong_pdf, read_network_layers, write_network

REPO = Path(__file__).resolve().parents[1]
EXPONENT, SPECULAR_WEIGHT = 40.0, 0.3

pytestmark = pytest.mark.skipif(shutil.which("cc") is None or shutil.which("pkg-config") is None,
                                reason="needs a C compiler (cc) and pkg-config")


def cargo_version() -> str:
    return re.search(r'^version = "(.+)"', (REPO / "Cargo.toml").read_text(), re.M).group(1)


def soversion() -> str:
    """The ABI's major version (the SONAME's), set in nbrdf-ffi/build.rs."""
    return re.search(r'^const SOVERSION: &str = "(.+)";', (REPO / "nbrdf-ffi/build.rs").read_text(), re.M).group(1)


def without_library_path() -> dict:
    return {k: v for k, v in os.environ.items() if k not in ("LD_LIBRARY_PATH", "DYLD_LIBRARY_PATH")}


@pytest.fixture(scope="module")
def prefix(tmp_path_factory) -> Path:
    prefix = tmp_path_factory.mktemp("prefix")
    subprocess.run(["make", "-s", "-C", str(REPO), "install", f"PREFIX={prefix}"], check=True, capture_output=True,
                   text=True, timeout=600)
    return prefix


def dynamic_section(path: Path) -> str:
    return subprocess.run(["readelf", "-d", str(path)], check=True, capture_output=True, text=True).stdout


def test_install_layout(prefix):
    version = cargo_version()
    major = soversion()
    assert major == "1"  # the ABI of issue 30 (one material and one sampler handle)
    lib = prefix / "lib"
    assert (lib / f"libnbrdf_ffi.so.{version}").is_file()
    assert os.readlink(lib / f"libnbrdf_ffi.so.{major}") == f"libnbrdf_ffi.so.{version}"
    assert os.readlink(lib / "libnbrdf_ffi.so") == f"libnbrdf_ffi.so.{major}"
    if shutil.which("readelf"):
        assert f"Library soname: [libnbrdf_ffi.so.{major}]" in dynamic_section(lib / "libnbrdf_ffi.so")
    assert (prefix / "include" / "nbrdf.h").read_text() == (REPO / "nbrdf-ffi/include/nbrdf.h").read_text()
    cli = subprocess.run([str(prefix / "bin" / "nbrdf"), "--version"], capture_output=True, text=True)
    assert cli.returncode == 0 and version in cli.stdout

    env = {**without_library_path(), "PKG_CONFIG_PATH": str(lib / "pkgconfig")}
    query = lambda *args: subprocess.run(["pkg-config", *args, "nbrdf"], check=True, capture_output=True,  # noqa: E731
                                         text=True, env=env).stdout.split()
    assert query("--modversion") == [version]
    assert query("--cflags") == [f"-I{prefix}/include"]
    assert query("--libs") == [f"-L{lib}", "-lnbrdf_ffi"]


def parse(line: str) -> dict:
    fields = dict(item.split("=", 1) for item in line.split()[1:])
    return {k: np.array([float(x) for x in v.split(",")]) if "," in v else v for k, v in fields.items()}


def test_c_example_runs_and_matches_the_oracles(prefix, tmp_path):
    source = tmp_path / "c"
    shutil.copytree(REPO / "examples" / "c", source)
    env = {**without_library_path(), "PKG_CONFIG_PATH": str(prefix / "lib" / "pkgconfig")}
    build = subprocess.run(["make", "-C", str(source)], capture_output=True, text=True, env=env)
    assert build.returncode == 0, build.stdout + build.stderr
    program = source / "nbrdf_example"
    if shutil.which("readelf"):
        assert f"Shared library: [libnbrdf_ffi.so.{soversion()}]" in dynamic_section(program)

    network = write_network(tmp_path / "gold.nbrdf.json", name="gold", sampling={
        "model": "blinn-phong", "exponent": EXPONENT, "specular_weight": SPECULAR_WEIGHT, "source": "fit"})
    result = subprocess.run([str(program), str(network)], capture_output=True, text=True, env=env, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == f"library {cargo_version()}"
    info = parse(lines[1])
    assert (info["name"], info["hidden"], info["parameters"], info["stored_sampling"]) == ("gold", "21", "675", "phong")
    assert float(info["exponent"]) == EXPONENT and float(info["specular_weight"]) == pytest.approx(SPECULAR_WEIGHT)

    layers = read_network_layers(network)
    evals = [parse(line) for line in lines if line.startswith("eval ")]
    assert len(evals) == 4
    view = np.stack([e["view"] for e in evals], axis=1)
    light = np.stack([e["light"] for e in evals], axis=1)
    rgb = np.stack([e["rgb"] for e in evals], axis=1)
    expected = nbrdf_reference(layers, light, view)
    assert expected.min() > 0  # all four pairs above the horizon: a zero output would be a failure
    np.testing.assert_allclose(rgb, expected, rtol=2e-4)

    samples = [parse(line) for line in lines if line.startswith("sample ")]
    assert len(samples) == 4 and all(s["kind"] == "2" for s in samples)  # NBRDF_SAMPLING_PHONG
    view = np.stack([s["view"] for s in samples], axis=1)
    light = np.stack([s["light"] for s in samples], axis=1)
    pdf = np.array([float(s["pdf"]) for s in samples])
    weight = np.stack([s["weight"] for s in samples], axis=1)
    np.testing.assert_allclose(np.linalg.norm(light, axis=0), 1.0, rtol=1e-5)
    valid = pdf > 0
    assert valid.sum() >= 3
    np.testing.assert_allclose(pdf[valid], phong_pdf(view, light, EXPONENT, SPECULAR_WEIGHT)[valid], rtol=1e-3)
    np.testing.assert_allclose(weight[:, valid], (nbrdf_reference(layers, light, view) / pdf)[:, valid], rtol=1e-3)

    error = parse(next(line for line in lines if line.startswith("error ")))
    assert error["status"] == "3" and error["handle"] == "null"  # NBRDF_ERROR_IO
    message = next(line for line in lines if line.startswith("message "))
    assert message.startswith("message nbrdf_material_load: no-such-network.nbrdf.json")
    assert lines[-1] == "ok"


def test_c_example_reports_a_bad_network(prefix, tmp_path):
    source = tmp_path / "c"
    shutil.copytree(REPO / "examples" / "c", source)
    env = {**without_library_path(), "PKG_CONFIG_PATH": str(prefix / "lib" / "pkgconfig")}
    subprocess.run(["make", "-s", "-C", str(source)], check=True, capture_output=True, env=env)
    bad = tmp_path / "bad.nbrdf.json"
    bad.write_text('{"format": "nbrdf", "version": 1, "layers": []}')
    result = subprocess.run([str(source / "nbrdf_example"), str(bad)], capture_output=True, text=True, env=env)
    assert result.returncode == 1
    assert "nbrdf_material_load failed (status 4)" in result.stderr  # NBRDF_ERROR_FORMAT
