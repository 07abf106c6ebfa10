"""``nbrdf train X_spec.bsdf`` (issue 31): a spectral measurement gives a spectral network (file
format version 3) by default, learnt at the file's own wavelengths; ``--output-kind rgb`` gives
the RGB network of its sRGB projection; ``--output-kind spectral`` of an RGB source is refused.

The spectral file is written from a real RGB measurement (``nbrdf_tools.data.spectral_rgl``, as in
tests/test_rgl_spectral.py). The references are independent of nbrdf: Mitsuba's own ``measured``
in ``llvm_ad_spectral`` for the spectrum, and for the projection Mitsuba's ``measured`` on the
RGB file in ``scalar_rgb`` times the float64 sRGB matrix of the three basis spectra."""

from __future__ import annotations

import json
import subprocess

import nbrdf_mitsuba  # noqa: F401  (before mitsuba)
import numpy as np
import pytest
from test_rgl_reader import _mitsuba_eval
from test_rgl_spectral import WAVELENGTHS, _mitsuba_spectral

from conftest import use_variant
from nbrdf_tools.pages import spectral_basis
from nbrdf_tools.data import spectral_rgl
from nbrdf_tools.common.paths import default_cli

MATERIAL = "paper_white_rgb"
#: A short run: enough for both networks to learn the material's shape, small for CI.
BUDGET = ["--samples", "8000", "--epochs", "30", "--min-epochs", "30", "--hidden", "16", "--quiet"]


@pytest.fixture(scope="module")
def sources(shared, tmp_path_factory):
    rgb = shared / "data" / "rgl" / f"{MATERIAL}.bsdf"
    folder = tmp_path_factory.mktemp("spectrain")
    return rgb, spectral_rgl.write_spectral(rgb, folder / "paper_white_spec.bsdf", WAVELENGTHS)


def _train(source, out, *extra) -> subprocess.CompletedProcess:
    cli = default_cli()
    assert cli.is_file(), f"{cli} is not built (make setup)"
    return subprocess.run([str(cli), "train", str(source), "-o", str(out), *BUDGET, *extra],
                          capture_output=True, text=True, timeout=300)


def _pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) float32 view and light, uniform on the hemisphere above cos 0.1, no mirror pairs."""
    rng = np.random.default_rng(seed)

    def draw():
        z = rng.uniform(0.1, 1.0, n)
        phi = rng.uniform(0.0, 2.0 * np.pi, n)
        r = np.sqrt(1.0 - z * z)
        return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1).astype(np.float32)

    return draw(), draw()


def _log_error(expected: np.ndarray, got: np.ndarray) -> float:
    return float(np.mean(np.abs(np.log1p(np.maximum(expected, 0.0)) - np.log1p(np.maximum(got, 0.0)))))


def test_a_spectral_file_trains_a_spectral_network_as_good_as_the_rgb_one(sources, tmp_path, restore_variant):
    """Both networks with the same budget: the spectral network's per-wavelength log error
    against Mitsuba's ``measured`` in a spectral variant is comparable to the RGB network's error
    against the projection."""
    from nbrdf_mitsuba import _native

    rgb_file, spec_file = sources
    spectral_net, rgb_net = tmp_path / "spec.nbrdf.json", tmp_path / "rgb.nbrdf.json"
    for out, extra in ((spectral_net, []), (rgb_net, ["--output-kind", "rgb"])):
        done = _train(spec_file, out, *extra)
        assert done.returncode == 0, done.stderr
    document = json.loads(spectral_net.read_text())
    assert document["version"] == 3 and document["layers"][-1]["outputs"] == 16
    provenance = document["provenance"]
    assert provenance["source_kind"] == "rgl-spectral-measurement"
    assert provenance["network_kind"] == "auto"
    assert provenance["spectral_target"]["wavelengths"] == len(WAVELENGTHS)
    rgb_document = json.loads(rgb_net.read_text())
    assert rgb_document["version"] == 1 and rgb_document["layers"][-1]["outputs"] == 3

    view, light = _pairs(300, 5)
    rng = np.random.default_rng(6)
    wavelengths = rng.uniform(365.0, 825.0, (len(view), 4)).astype(np.float32)
    use_variant("llvm_ad_spectral")
    expected = _mitsuba_spectral(spec_file, view, light, wavelengths, "llvm_ad_spectral")
    got = _native.Material(spectral_net).eval_spectral(view.T, light.T, np.ascontiguousarray(wavelengths.T)).T
    spectral_error = _log_error(expected, got)

    use_variant("scalar_rgb")
    basis = spectral_rgl.basis_spectra(WAVELENGTHS.astype(np.float32))
    matrix = basis @ spectral_basis.srgb_weights(WAVELENGTHS)
    projection = _mitsuba_eval(rgb_file, view, light).astype(np.float64) @ matrix
    rgb_error = _log_error(projection, _native.Material(rgb_net).eval(view.T, light.T).T)
    assert spectral_error < 1.5 * rgb_error + 2e-3, (spectral_error, rgb_error)
    # Not vacuous: the spectrum varies with the wavelength, and an untrained-scale answer is far.
    assert np.std(expected / expected.mean(1, keepdims=True)) > 0.05
    assert _log_error(expected, np.full_like(expected, expected.mean())) > 5 * spectral_error


def test_output_kind_spectral_of_an_rgb_source_is_refused(sources, tmp_path):
    rgb_file, _ = sources
    done = _train(rgb_file, tmp_path / "x.nbrdf.json", "--output-kind", "spectral")
    assert done.returncode != 0
    assert "spectral source" in done.stderr and str(rgb_file) in done.stderr, done.stderr
    assert not (tmp_path / "x.nbrdf.json").exists()
