"""Spectral RGL measurements (``*_spec.bsdf``, issue 31): the Rust reader evaluated per
wavelength against Mitsuba's own ``measured`` plugin in spectral variants (the independent
reference), and its linear sRGB projection against a NumPy float64 integral. No spectral file is
at hand, so each test writes one from a real RGB measurement (``nbrdf_tools.data.spectral_rgl``:
every cell's RGB value times three smooth basis spectra, at irregular wavelengths)."""

from __future__ import annotations

import json
import subprocess

import mitsuba as mi
import numpy as np
import pytest
from test_rgl_reader import ATOL_OF_PEAK, RTOL, _direction_pairs, build_rgl_eval

from nbrdf_tools.pages import spectral_basis
from nbrdf_tools.data import spectral_rgl
from nbrdf_tools.common.paths import default_cli

MATERIALS = ["paper_white_rgb", "cc_iris_purple_gem_rgb"]
# Irregular steps over the RGL database's 360-1000 nm, so that interpolation between unequal
# intervals is exercised; Mitsuba samples 360-830 nm, all inside.
WAVELENGTHS = np.array([360.0, 372.5, 401.0, 430.0, 447.0, 470.0, 488.5, 512.0, 530.0, 556.0, 581.0,
                        600.0, 618.5, 640.0, 672.0, 700.0, 733.0, 780.0, 830.0, 900.0, 1000.0])


@pytest.fixture(scope="module")
def spectral_files(shared, tmp_path_factory):
    folder = tmp_path_factory.mktemp("spectral")
    return {m: spectral_rgl.write_spectral(shared / "data" / "rgl" / f"{m}.bsdf",
                                           folder / f"{m.removesuffix('_rgb')}_spec.bsdf", WAVELENGTHS)
            for m in MATERIALS}


@pytest.fixture(scope="module")
def rgl_eval():
    return build_rgl_eval()


@pytest.fixture
def restore_variant():
    previous = mi.variant()
    yield
    if previous is not None:
        mi.set_variant(previous)


def _rust(binary, path, rows: np.ndarray, spectral: bool) -> np.ndarray:
    args = [str(binary), "--spectral", str(path)] if spectral else [str(binary), str(path)]
    done = subprocess.run(args, input=rows.astype("<f4").tobytes(), capture_output=True)
    assert done.returncode == 0, done.stderr.decode()
    return np.frombuffer(done.stdout, "<f8").reshape(len(rows), -1)


def _mitsuba_spectral(path, view, light, wavelengths, variant: str) -> np.ndarray:
    """Mitsuba's ``measured`` in a spectral variant: f_r cos per row and wavelength (4 a row)."""
    import drjit as dr

    mi.set_variant(variant)
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx = mi.BSDFContext()
    if variant.startswith("scalar"):
        out = np.empty((len(view), 4))
        for k in range(len(view)):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*view[k].tolist())
            si.wavelengths = mi.Spectrum(*wavelengths[k].tolist())
            out[k] = np.array(bsdf.eval(ctx, si, mi.Vector3f(*light[k].tolist())))
        return out
    si = dr.zeros(mi.SurfaceInteraction3f, len(view))
    si.wi = mi.Vector3f(*(view[:, i] for i in range(3)))
    si.wavelengths = mi.Spectrum(*(wavelengths[:, i] for i in range(4)))
    value = bsdf.eval(ctx, si, mi.Vector3f(*(light[:, i] for i in range(3))))
    return np.array(value).reshape(4, len(view)).T


@pytest.mark.parametrize("variant", ["llvm_ad_spectral", "scalar_spectral"])
@pytest.mark.parametrize("material", MATERIALS)
def test_per_wavelength_eval_matches_mitsuba_measured(material, variant, spectral_files, rgl_eval,
                                                      restore_variant):
    path = spectral_files[material]
    view, light = _direction_pairs(seed=10 + MATERIALS.index(material))
    if variant.startswith("scalar"):      # a Python call per row: a subset
        view, light = view[::8], light[::8]
    rng = np.random.default_rng(3)
    wavelengths = rng.uniform(360.0, 830.0, (len(view), 4)).astype(np.float32)
    wavelengths[::5, 0] = rng.choice(WAVELENGTHS[WAVELENGTHS <= 830.0], len(wavelengths[::5]))
    expected = _mitsuba_spectral(path, view, light, wavelengths, variant)
    ours = _rust(rgl_eval, path, np.concatenate([view, light, wavelengths], 1), spectral=True)

    above = (view[:, 2] > 0) & (light[:, 2] > 0)
    assert np.all(expected[~above] == 0) and np.all(ours[~above] == 0)
    peak = np.abs(expected).max()
    allowed = RTOL * np.abs(expected) + ATOL_OF_PEAK * peak
    # Exact mirror pairs: Mitsuba's isotropic `measured` picks either of two values there from
    # one process to the next (see tests/test_rgl_reader.py).
    mirror = np.all(np.abs(view[:, :2] + light[:, :2]) < 1e-7, axis=1) & above
    allowed[mirror] = 0.1 * np.abs(expected[mirror]) + ATOL_OF_PEAK * peak
    error = np.abs(ours - expected)
    worst = np.unravel_index(np.argmax(error / allowed), error.shape)
    assert np.all(error <= allowed), (
        f"{material} {variant}: row {worst[0]} at {wavelengths[worst]} nm: Rust {ours[worst]}, "
        f"Mitsuba {expected[worst]}")
    # Not vacuous: the values vary with the wavelength as the basis spectra make them.
    lit = expected[above][expected[above].mean(1) > 1e-3 * peak]
    assert peak > 0.1 and len(lit) > 0.05 * above.sum() and np.std(lit / lit.mean(1, keepdims=True)) > 0.05


@pytest.mark.parametrize("material", MATERIALS)
def test_srgb_projection_matches_a_float64_integral(material, shared, spectral_files, rgl_eval,
                                                    restore_variant):
    # The spectral file holds rgb . basis(l) per cell, and everything between the cells and the
    # sRGB value is linear: its RGB evaluation must be the RGB file's evaluation times the matrix
    # of the projected basis (from the float64 oracle), up to float32 rounding.
    mi.set_variant("scalar_rgb")
    # The float64 oracle: Mitsuba's CIE tables integrated by the trapezoid rule in NumPy.
    weights = spectral_basis.srgb_weights(WAVELENGTHS)
    basis = spectral_rgl.basis_spectra(WAVELENGTHS.astype(np.float32))
    matrix = basis @ weights          # row c: the sRGB value of basis spectrum c
    # A check of the oracle itself against Mitsuba's own (1000-point) projection of a reflectance
    # spectrum (`spectrum_list_to_srgb` with D65, as for spectral reflectance in RGB variants).
    mixed = basis.T @ np.array([0.5, 0.3, 0.4])
    mitsuba = np.array(mi.spectrum_list_to_srgb(WAVELENGTHS.tolist(), mixed.tolist(), False, True))
    np.testing.assert_allclose(np.array([0.5, 0.3, 0.4]) @ matrix, mitsuba, rtol=3e-3)

    view, light = _direction_pairs(seed=20 + MATERIALS.index(material))
    rows = np.concatenate([view, light], 1)
    rgb = _rust(rgl_eval, shared / "data" / "rgl" / f"{material}.bsdf", rows, spectral=False)[:, :3]
    projected = _rust(rgl_eval, spectral_files[material], rows, spectral=False)[:, :3]
    expected = rgb @ matrix
    bound = np.abs(rgb) @ np.abs(matrix)
    error = np.abs(projected - expected)
    assert np.all(error <= 2e-6 * bound + 1e-9), np.max(error / (bound + 1e-9))
    assert np.std(projected) > 0.01


def test_train_reads_a_spectral_measurement(spectral_files, tmp_path):
    cli = default_cli()
    assert cli.is_file(), f"{cli} is not built (make setup)"
    source = spectral_files["paper_white_rgb"]
    network = tmp_path / "paper_white_spec.nbrdf.json"
    done = subprocess.run([str(cli), "train", str(source), "-o", str(network), "--epochs", "1",
                           "--min-epochs", "1", "--samples", "3000", "--quiet"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    provenance = json.loads(network.read_text())["provenance"]
    assert provenance["source_kind"] == "rgl-spectral-measurement"
    assert provenance["source"] == str(source)
