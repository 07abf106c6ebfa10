"""The pieces of ``python -m nbrdf_tools spectral-networks`` (issue 31), at tiny sizes.

References: NumPy float64 log errors, a closed-form interpolation error (a quadratic spectrum:
the chord of ``a + b l + c l^2`` between samples ``h`` apart is off by ``c (l - l0)(l1 - l)``),
metrics of identical images, and step records read back by ``--resume`` instead of a second
training. The whole report runs once with the spectral trainer replaced by a stand-in that
writes a fixed version-3 network (the spectral trainer is another branch's; the RGB networks
and everything downstream are real)."""

from __future__ import annotations

import json

import nbrdf_mitsuba  # noqa: F401  (before mitsuba)
import mitsuba as mi
import numpy as np
import pytest

from conftest import use_variant
from nbrdf_tools.pages import spectral_networks as spectral_report
from test_spectral_networks import spectral_layers


def test_log_errors_are_numpys():
    rng = np.random.default_rng(3)
    source = rng.uniform(-0.1, 4.0, (5, 40))
    other = rng.uniform(-0.1, 4.0, (5, 40))
    found = spectral_report.log_errors({"source": source, "x": other})
    expected = np.abs(np.log(1 + np.maximum(source, 0)) - np.log(1 + np.maximum(other, 0))).mean(axis=1)
    np.testing.assert_allclose(found["x"], expected, rtol=1e-12)
    assert list(found) == ["x"]


def test_pairs_are_above_the_horizon_and_reproducible():
    view, light = spectral_report.pairs(500)
    assert view.shape == light.shape == (3, 500)
    assert np.all(view.astype(np.float32)[2] > 0) and np.all(light.astype(np.float32)[2] > 0)
    np.testing.assert_allclose(np.linalg.norm(view, axis=0), 1.0, rtol=1e-12)
    again, _ = spectral_report.pairs(500)
    np.testing.assert_array_equal(view, again)


def test_interpolation_error_of_a_quadratic_spectrum(restore_variant):
    """A diffuse BSDF whose reflectance is ``r(l) = 0.1 + k (l - 360)^2`` tabulated every 1 nm
    (Mitsuba interpolates linearly between its nodes, so it is exact there): the piecewise-linear
    spectrum through samples ``h`` apart is off by ``k (l - l0)(l1 - l)``, whose relative RMS
    over 360-830 nm (samples every ``h`` from 360 nm and one at 830 nm) is computed here in
    float64."""
    k = 0.8 / 470.0**2
    fine = np.arange(360.0, 831.0)
    spec = {"type": "diffuse", "reflectance": {"type": "spectrum",
                                               "value": [(float(w), float(0.1 + k * (w - 360.0) ** 2)) for w in fine]}}
    view, light = spectral_report.pairs(3, seed=2)
    found = spectral_report.interpolation_errors(spec, view, light)
    reflectance = 0.1 + k * (fine - 360.0) ** 2
    for step in spectral_report.STEPS_NM:
        nodes = np.append(np.arange(360.0, 830.0 - 1e-9, step), 830.0)
        right = np.searchsorted(nodes, fine, side="right").clip(1, len(nodes) - 1)
        chord_error = k * (fine - nodes[right - 1]) * (nodes[right] - fine)
        expected = np.sqrt(np.mean(chord_error**2)) / np.sqrt(np.mean(reflectance**2))
        mean, worst = found[f"{step:g}"]
        # The value is f cos / pi: a factor common to both spectra, which the ratio cancels.
        assert mean == pytest.approx(expected, rel=2e-3, abs=2e-6), step
        assert worst == pytest.approx(mean, rel=1e-3, abs=1e-6)


def test_identical_images_have_no_error():
    rng = np.random.default_rng(1)
    image = rng.uniform(0.0, 3.0, (24, 24, 3))
    errors = spectral_report.image_errors({"source": image, "same": image.copy(), "dark": 0.5 * image})
    assert errors["same"]["rmse_tonemapped"] == 0.0 and errors["same"]["relative_rmse"] == 0.0
    assert errors["same"]["ssim"] == pytest.approx(1.0) and errors["same"]["flip_hdr"] == pytest.approx(0.0, abs=1e-6)
    assert errors["dark"]["relative_rmse"] == pytest.approx(0.5)
    assert errors["dark"]["ssim"] < 1.0 and errors["dark"]["flip_hdr"] > 0.0


def test_steps_are_read_back_only_with_the_same_settings(tmp_path):
    calls = []

    def compute():
        calls.append(1)
        return {"value": len(calls)}

    assert spectral_report.Steps(tmp_path, {"a": 1}, resume=True).run("x", compute) == {"value": 1}
    assert spectral_report.Steps(tmp_path, {"a": 1}, resume=True).run("x", compute) == {"value": 1}
    assert spectral_report.Steps(tmp_path, {"a": 1}, resume=False).run("x", compute) == {"value": 2}
    assert spectral_report.Steps(tmp_path, {"a": 2}, resume=True).run("x", compute) == {"value": 3}
    assert spectral_report.Steps(tmp_path, {"a": 2}, resume=True).run("x", compute, (tmp_path / "gone",)) == {"value": 4}
    assert len(calls) == 4


def _stand_in_spectral_trainer(calls: list):
    """What ``_train_native.train_spectral_from_arrays`` returns, without training: a fixed
    version-3 network (positive spectra) with the provenance fields the report reads."""

    def train(config, view, light, wavelengths, values, n_validation, **options):
        calls.append((view.shape, np.asarray(wavelengths).shape, values.shape))
        assert values.shape == (len(wavelengths), view.shape[1] + n_validation) or values.shape[0] == len(wavelengths)
        layers = spectral_layers()
        return json.dumps({
            "format": "nbrdf", "version": 3, "name": options.get("name", "stand-in"), "anisotropic": False,
            "spectral": {"basis": "cubic_bspline", "count": 16, "min_nm": 360.0, "max_nm": 830.0},
            "layers": [{"inputs": int(w.shape[0]), "outputs": int(w.shape[1]),
                        "weights": [float(v) for v in w.ravel()], "bias": [float(v) for v in b]} for w, b in layers],
            "provenance": {"source": options.get("source"), "epochs": 0, "best_validation_loss": 0.0,
                           "samples": view.shape[1], "max_epochs": 0, "distilled_from": options.get("details")},
        })

    return train


def test_report_runs_and_resumes(tmp_path, monkeypatch, restore_variant):
    """The whole report on Cu at --quick sizes (the spectral trainer stood in for): the page opens
    with its command, has every section, an image row per (variant, network), the EXR images and
    the figure; a second run with --resume trains nothing and writes the same page."""
    use_variant("llvm_ad_spectral")
    from nbrdf_mitsuba import _train_native

    calls = []
    monkeypatch.setattr(_train_native, "train_spectral_from_arrays", _stand_in_spectral_trainer(calls), raising=False)
    out, figure = tmp_path / "spectral.md", tmp_path / "spectral.png"
    argv = ["--quick", "--materials", "Cu", "--out", str(out), "--figure", str(figure), "--work", str(tmp_path / "w"),
            "--threads", "1", "--no-progress"]
    assert spectral_report.main(argv) == 0
    text = out.read_text()
    assert text.startswith("# Spectral networks\n\n```sh\npython -m nbrdf_tools spectral-networks --stored-only "
                           f"--data {out.with_suffix('.json')} --out {out}   #")
    assert "\npython -m nbrdf_tools spectral-networks --quick" in text
    assert "961 (6-21-21-16)" in text and "675 (6-21-21-3): 1.42x" in text
    for section in ("## Log error per wavelength", "## Sphere images", "## Sampling the source's spectrum",
                    "## Training"):
        assert section in text
    assert text.count("| Cu | `llvm_ad_") == 4
    assert "the four shared RGL files" in text
    assert len(calls) == 1 and calls[0][1] == (48,)
    for variant in spectral_report.VARIANTS:
        for name in ("source", "spectral", "rgb"):
            image = spectral_report.read_exr(tmp_path / "w" / f"Cu-{variant}-{name}.exr")
            assert image.shape == (24, 24, 3) and np.all(np.isfinite(image))
    assert figure.stat().st_size > 10_000
    mi.set_variant("llvm_ad_rgb")
    before = (tmp_path / "w" / "Cu-rgb.nbrdf.json").stat().st_mtime_ns
    assert spectral_report.main([*argv, "--resume"]) == 0
    assert len(calls) == 1
    assert (tmp_path / "w" / "Cu-rgb.nbrdf.json").stat().st_mtime_ns == before
    strip = [line for line in text.splitlines() if not line.startswith(("Machine:", "python -m"))]
    again = [line for line in out.read_text().splitlines() if not line.startswith(("Machine:", "python -m"))]
    assert again == strip


def test_bad_arguments_are_refused(capsys):
    with pytest.raises(SystemExit):
        spectral_report.parse_arguments(["--spp", "0"])
    assert "--spp must be at least 1" in capsys.readouterr().err
    assert spectral_report.main(["--materials", "", "--out", "/nonexistent/x.md"]) == 2
