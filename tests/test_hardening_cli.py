"""Hardening of the ``nbrdf`` command-line tool (issue 16, Rust side; docs/hardening.md): size
options out of range are usage errors (exit status 2, clap's convention) named with their limit
before anything is allocated; bad files are failures (exit status 1) whose message names the file
and says what it is; special files are refused without being opened."""

from __future__ import annotations

import os
import subprocess

import numpy as np
import pytest

from conftest import _cli
from nbrdf_testing import write_merl

CELLS = 90 * 90 * 180


@pytest.fixture(scope="module")
def cli():
    exe = _cli()
    if exe is None:
        pytest.skip("the nbrdf CLI is not built (make setup builds target/release/nbrdf)")
    return exe


def run(cli, *args, timeout=20):
    return subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("args, option, limit", [
    (["train", "t.binary", "--hidden", "100000"], "--hidden", "4096"),
    (["train", "t.binary", "--batch", "100000000"], "--batch", "1048576"),
    (["train", "t.binary", "--samples", "1000000000"], "--samples", "100000000"),
    (["train", "t.binary", "--epochs", "0"], "--epochs", "1000000"),
    (["compare", "a", "b", "--resolution", "100000"], "--resolution", "4096"),
    (["fit-phong", "x.binary", "--samples", "10000000000"], "--samples", "100000000"),
    (["ae", "train", "--nbrdfs", ".", "-o", "ae.json", "--hidden", "100000"], "--hidden", "4096"),
])
def test_size_options_out_of_range_are_usage_errors(cli, args, option, limit):
    result = run(cli, *args)
    assert result.returncode == 2, result.stderr
    assert option in result.stderr and limit in result.stderr and "out of range" in result.stderr


def test_memory_is_estimated_before_allocating(cli, merl_table):
    # Each within its range, together 64 GiB of activations: refused at once, nothing allocated.
    result = run(cli, "train", merl_table, "--hidden", "4096", "--batch", "1048576", timeout=10)
    assert result.returncode == 2, result.stderr
    assert "GiB limit" in result.stderr


def test_usage_errors_exit_2_and_failures_exit_1(cli, tmp_path):
    assert run(cli, "info").returncode == 2          # missing argument
    assert run(cli, "frobnicate").returncode == 2    # unknown command
    assert run(cli, "train", "t.binary", "--hidden", "x").returncode == 2
    missing = run(cli, "info", tmp_path / "missing.binary")
    assert missing.returncode == 1 and "missing.binary" in missing.stderr
    assert run(cli, "--version").returncode == 0


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs need a Unix system")
@pytest.mark.parametrize("command", ["info", "tabulate"])
def test_special_files_are_refused_without_blocking(cli, tmp_path, command):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for path in (fifo, "/dev/zero", tmp_path):
        result = run(cli, command, path, timeout=10)   # a blocking open would time out
        assert result.returncode == 1, result.stderr
        assert "not a regular file" in result.stderr or "a directory" in result.stderr


def test_a_table_given_as_a_network_says_so(cli, merl_table):
    result = run(cli, "tabulate", merl_table)
    assert result.returncode == 1
    assert "this is a MERL table (binary), not an NBRDF network JSON" in result.stderr
    assert "UTF-8" not in result.stderr


def test_a_network_given_as_a_table_says_so(cli, network_file):
    result = run(cli, "info", network_file)
    assert result.returncode == 1
    assert "this is JSON" in result.stderr and "not a MERL table" in result.stderr
    assert "header is" not in result.stderr


def test_nan_in_network_json_is_named(cli, network_file, tmp_path):
    bad = tmp_path / "nan.nbrdf.json"
    bad.write_text(network_file.read_text().replace("[", "[NaN, ", 1))
    result = run(cli, "tabulate", bad, "-o", tmp_path / "x.binary")
    assert result.returncode == 1
    assert "NaN is not valid JSON (line" in result.stderr and str(bad) in result.stderr


def test_tables_beyond_float32_or_without_a_valid_cell_are_refused(cli, tmp_path):
    stored = np.full((3, CELLS), 0.5)
    stored[2, 1234] = 1e300
    huge = write_merl(tmp_path / "huge.binary", stored.reshape(3, 90, 90, 180))
    result = run(cli, "info", huge)
    assert result.returncode == 1
    assert "huge.binary: value 1e300" in result.stderr and "blue channel" in result.stderr
    assert "float32" in result.stderr
    empty = write_merl(tmp_path / "empty.binary", np.full((3, 90, 90, 180), -1.0))
    result = run(cli, "info", empty)
    assert result.returncode == 1 and "empty.binary: no valid cell" in result.stderr


def test_data_errors_name_the_file(cli, tmp_path):
    # One valid cell in 1.46 million: training cannot draw its samples.
    stored = np.full((3, CELLS), -1.0)
    stored[:, 0] = 0.5
    sparse = write_merl(tmp_path / "sparse.binary", stored.reshape(3, 90, 90, 180))
    result = run(cli, "train", sparse, "--samples", "1000", "--epochs", "1", "-q", "-o", tmp_path / "n.json",
                 timeout=60)
    assert result.returncode == 1
    assert "sparse.binary: only" in result.stderr and "valid data" in result.stderr


def test_latent_commands_refuse_anisotropic_networks(cli, tmp_path):
    """The built-in autoencoder and predictor learnt isotropic networks: every latent command
    refuses an anisotropic one with one line naming it (exit status 1), writing nothing; the
    same network marked isotropic is accepted."""
    from nbrdf_testing import write_network

    folder = tmp_path / "nets"
    folder.mkdir()
    aniso = write_network(folder / "brushed.nbrdf.json", name="brushed", anisotropic=True)
    iso = write_network(tmp_path / "plain.nbrdf.json", name="plain")
    assert run(cli, "ae", "encode", "--no-relearn", iso).returncode == 0
    for args in (["ae", "encode", aniso], ["predict-phong", aniso, "-o", tmp_path / "out.nbrdf.json"],
                 ["interpolate", iso, aniso, "-o", tmp_path / "path"],
                 ["ae", "train", "--nbrdfs", folder, "-o", tmp_path / "ae.json", "--epochs", "1", "--quiet"],
                 ["ae", "eval", "--nbrdfs", folder]):
        result = run(cli, *args)
        assert result.returncode == 1, (args, result.stderr)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and "brushed" in lines[0] and "is anisotropic" in lines[0], (args, result.stderr)
    assert not (tmp_path / "out.nbrdf.json").exists() and not (tmp_path / "ae.json").exists()
    assert not (tmp_path / "path").exists()


@pytest.mark.parametrize("defect, field, words", [
    ("count", "spectra", "(wavelengths)"),
    ("order", "wavelengths", "strictly increasing"),
    ("nan", "wavelengths", "finite"),
    ("micrometres", "wavelengths", "nanometres"),
])
def test_bad_spectral_measurements_name_the_field(cli, shared, tmp_path, defect, field, words):
    from nbrdf_tools.data import spectral_rgl

    rgb = spectral_rgl.read_tensor_file(shared / "data" / "rgl" / "paper_white_rgb.bsdf")
    fields = spectral_rgl.spectral_fields(rgb, np.linspace(360.0, 1000.0, 9))
    wavelengths = fields["wavelengths"]
    if defect == "count":            # spectra has 9 wavelengths, the field 8
        fields["wavelengths"] = wavelengths[:-1].copy()
    elif defect == "order":
        wavelengths[[3, 4]] = wavelengths[[4, 3]]
    elif defect == "nan":
        wavelengths[5] = np.nan
    else:
        fields["wavelengths"] = wavelengths / 1000.0
    path = spectral_rgl.write_tensor_file(tmp_path / f"{defect}_spec.bsdf", fields)
    result = run(cli, "train", path, "-o", tmp_path / "x.nbrdf.json", "--quiet")
    assert result.returncode == 1, result.stderr
    assert str(path) in result.stderr and f'field "{field}"' in result.stderr and words in result.stderr
    assert not (tmp_path / "x.nbrdf.json").exists()
