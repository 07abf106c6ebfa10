"""The Python-side comparison (nbrdf_tools.common.compare_materials), the training report
(nbrdf_tools.pages.training) and the RGL tabulation it relies on.

Short runs only: networks of 100,000 samples and a few epochs, small sphere images.
"""

from __future__ import annotations

import csv
import json
import math
import subprocess
from pathlib import Path

import nbrdf_mitsuba  # noqa: F401  (first: points Dr.Jit at a usable libLLVM)
import numpy as np
import pytest

from conftest import _cli, _llvm_problem
from nbrdf_tools.common import compare_materials as cm
from nbrdf_tools.pages import training as train_report

RESOLUTION, SAMPLES = 32, 4000


@pytest.fixture(scope="module", autouse=True)
def _llvm():
    problem = _llvm_problem()
    if problem:
        pytest.skip(f"llvm variant unavailable: {problem}")


@pytest.fixture(scope="module")
def cli() -> Path:
    exe = _cli()
    if exe is None:
        pytest.skip("target/release/nbrdf is not built (make build, or cargo build --release -p nbrdf-core --features cli)")
    return exe


@pytest.fixture(scope="module")
def chrome_table(cli, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("chrome") / "chrome.binary"
    subprocess.run([str(cli), "synth", "--model", "sgd", "--material", "chrome", "-o", str(out)],
                   check=True, capture_output=True)
    return out


@pytest.fixture(scope="module")
def quick_network(cli, merl_table, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("net") / "quick.nbrdf.json"
    subprocess.run([str(cli), "train", str(merl_table), "-o", str(out), "--samples", "50000", "--epochs", "3",
                    "--quiet"], check=True, capture_output=True)
    return out


def _tabulate_rgl_with_folds():
    from nbrdf_mitsuba import tabulate_rgl

    if not hasattr(tabulate_rgl, "PHI_FOLDS"):
        pytest.skip("the installed nbrdf_mitsuba predates this checkout's tabulate_rgl --phi-fold "
                    "(run `make setup` to reinstall the plugin)")
    return tabulate_rgl


# ---------------------------------------------------------------------------------------------
# compare_materials


def test_table_against_itself_has_no_error(merl_table):
    c = cm.compare(merl_table, merl_table, RESOLUTION, SAMPLES)
    assert c.mean.mae == 0.0 and c.mean.rmse == 0.0 and c.mean.relmse == 0.0 and c.mean.flip_hdr == 0.0
    assert math.isinf(c.mean.psnr_peak_ref) and c.mean.ssim == pytest.approx(1.0, abs=1e-12)
    assert c.log_error_adaptive == 0.0 and c.log_error_uniform == 0.0
    doc = c.to_json()
    assert doc["mean"]["psnr_peak_ref"] is None  # like serde_json: no Infinity in JSON
    assert [deg for deg, _ in doc["per_light"]] == list(cm.LIGHT_THETAS_DEG)


def test_different_materials_have_positive_errors(merl_table, chrome_table, capsys):
    c = cm.compare(merl_table, chrome_table, RESOLUTION, SAMPLES)
    assert c.mean.mae > 0 and c.mean.rmse > c.mean.mae * 0.5
    assert 0 < c.mean.ssim < 0.999 and math.isfinite(c.mean.psnr_peak_ref)
    assert 0 < c.mean.flip_hdr < 1 and c.mean.relmse > 0
    assert c.log_error_adaptive > 0 and c.log_error_uniform > 0
    assert cm.main([str(merl_table), str(chrome_table), "--json", "--resolution", "16", "--samples", "500"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["comparison"]) == {"resolution", "per_light", "mean", "log_error_adaptive", "log_error_uniform"}
    assert doc["comparison"]["mean"]["rmse"] > 0


def test_unknown_file_type_is_a_clear_error(merl_table, tmp_path, capsys):
    other = tmp_path / "x.exr"
    other.write_bytes(b"")
    assert cm.main([str(merl_table), str(other)]) == 1
    assert "unknown material file type" in capsys.readouterr().err


def test_python_comparison_reproduces_nbrdf_compare(cli, merl_table, quick_network):
    """Same spheres, PSNR (peak max(reference)) and log-space directions as the Rust tool. SSIM
    is not compared: it is scikit-image's here, which leaves the image border out where the Rust
    tool truncates the window (on 48x48 spheres the two differ by a few hundredths); its own test
    is test_scenes.py::test_ssim_and_flip_on_images_with_known_answers."""
    rust = json.loads(subprocess.run(
        [str(cli), "compare", str(merl_table), str(quick_network), "--json", "--resolution", "48",
         "--samples", str(SAMPLES)], check=True, capture_output=True, text=True).stdout)["comparison"]
    py = cm.compare(merl_table, quick_network, 48, SAMPLES).to_json()
    for (deg_r, er), (deg_p, ep) in zip(rust["per_light"], py["per_light"]):
        assert deg_r == deg_p
        for k in ("mae", "rmse"):
            assert ep[k] == pytest.approx(er[k], rel=2e-3), (deg_r, k)
        assert ep["psnr_peak_ref"] == pytest.approx(er.get("psnr_peak_ref", er.get("psnr")), rel=2e-3), deg_r
        assert 0 < ep["ssim"] <= 1, deg_r
    for k in ("log_error_adaptive", "log_error_uniform"):
        assert py[k] == pytest.approx(rust[k], rel=2e-3), k


def test_splitmix_matches_the_rust_generator():
    # SplitMix64::new(0, Stream::Metrics, 0).next_u64() >> 11, as a uniform in [0, 1).
    u = cm.splitmix_uniforms(0, 6, 0, 2)
    assert u.shape == (2, 4) and np.all((u >= 0) & (u < 1))
    again = cm.splitmix_uniforms(0, 6, 1, 1)  # candidate 1 alone: the same four numbers
    assert np.array_equal(u[1], again[0])


# ---------------------------------------------------------------------------------------------
# train_report


def _read_csv(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_quick_report_on_one_sgd_material_writes_csv_markdown_and_plot(cli, tmp_path):
    out = tmp_path / "report"
    argv = ["--quick", "--set", "sgd", "--materials", "white-paint", "--work", str(out), "--no-progress",
            "--epochs", "3", "--cli", str(cli)]
    assert train_report.main(argv) == 0
    rows = _read_csv(out / "results.csv")
    assert list(rows[0]) == train_report.CSV_COLUMNS
    assert [(r["set"], r["material"], r["method"]) for r in rows] == [
        ("sgd", "white-paint", "adaptive"), ("sgd", "white-paint", "uniform")]
    for r in rows:
        assert r["reference"] == "table" and int(r["epochs"]) == 3 and int(r["samples"]) == 100_000
        assert 0 < float(r["rmse"]) < 0.1 and 0.9 < float(r["ssim"]) <= 1.0
        assert 0 < float(r["flip_hdr"]) < 0.5 and float(r["relmse"]) > 0 and float(r["psnr_peak_ref"]) > 10
        assert float(r["sample_epochs_per_second"]) > 0 and float(r["wall_seconds"]) > 0
    md = (out / "report.md").read_text()
    for heading in ("## Mean ± standard deviation over materials", "## Adaptive vs uniform sampling (SGD)",
                    "## Worst materials", "## Trainer speed"):
        assert heading in md
    assert "M samples/s" in md and (out / "report.png").stat().st_size > 1000
    assert not (out / "tables" / "sgd" / "white-paint.binary").exists()  # deleted once done
    # A rerun resumes: nothing is retrained.
    stored = out / "results" / "sgd" / "white-paint.adaptive.json"
    before = stored.stat().st_mtime_ns
    assert train_report.main(argv) == 0
    assert stored.stat().st_mtime_ns == before
    # With --out, the run's summary replaces the set's table in the page's data, and the stored
    # results alone write the same page.
    data, page = tmp_path / "training.json", tmp_path / "training.md"
    data.write_text((train_report.REPO / "docs" / "results" / "data" / "training.json").read_text())
    assert train_report.main([*argv, "--data", str(data), "--out", str(page)]) == 0
    sgd = json.loads(data.read_text())["sgd"]
    assert "notes" not in sgd and [row[:3] for row in sgd["rows"]] == [["sgd", "adaptive", "1"], ["sgd", "uniform", "1"]]
    assert "| sgd | adaptive | 1 |" in page.read_text()
    again = tmp_path / "again.md"
    assert train_report.main(["--stored-only", "--data", str(data), "--out", str(again)]) == 0
    assert again.read_text() == page.read_text()
    # ... unless the recipe changes.
    assert train_report.main([a if a != "3" else "2" for a in argv]) == 0
    assert json.loads(stored.read_text())["epochs"] == 2


def test_unknown_material_is_an_error(cli, tmp_path, capsys):
    assert train_report.main(["--set", "sgd", "--materials", "unobtainium", "--work", str(tmp_path),
                              "--cli", str(cli), "--no-progress"]) == 1
    assert "unknown material" in capsys.readouterr().err


def test_without_shared_data_the_default_sets_run_on_embedded_fits(cli, tmp_path, capsys, monkeypatch):
    """A fresh clone (no shared data): the default `--set all` is the SGD set alone, with a note;
    an RGL measurement given as a path that does not exist is an error before any training."""
    monkeypatch.setenv("NBRDF_SHARED", str(tmp_path / "nonexistent"))
    assert train_report.main(["--materials", "unobtainium", "--work", str(tmp_path / "a"), "--cli", str(cli),
                              "--no-progress"]) == 1
    captured = capsys.readouterr()
    assert "the RGL set is left out" in captured.out and "unknown material" in captured.err
    assert train_report.main(["--set", "rgl", "--materials", str(tmp_path / "mine.bsdf"), "--work",
                              str(tmp_path / "b"), "--cli", str(cli), "--no-progress"]) == 1
    assert "no such RGL measurement" in capsys.readouterr().err
    assert train_report.main(["--set", "rgl", "--work", str(tmp_path / "c"), "--cli", str(cli), "--no-progress"]) == 1
    assert "data/rgl not found" in capsys.readouterr().err
    assert not any((tmp_path / d).exists() for d in "abc")


# ---------------------------------------------------------------------------------------------
# RGL: tabulation, measured ground truth, the authors' networks


def test_cell_reflectance_estimates():
    t = _tabulate_rgl_with_folds()
    e_lv = np.array([[0.2, 0.2, 0.2], [0.01, 0.01, 0.01]])
    e_vl = np.array([[0.3, 0.3, 0.3], [0.25, 0.25, 0.25]])
    cl, cv = np.array([0.5, 0.001]), np.array([0.6, 0.8])
    rec = t.cell_reflectance(e_lv, e_vl, cl, cv, "reciprocal")
    assert rec[0, 0] == pytest.approx(0.5 / 1.1) and rec[1, 0] == pytest.approx(0.26 / 0.801)
    mir = t.cell_reflectance(e_lv, e_vl, cl, cv, "mirror")
    assert mir[0, 0] == pytest.approx(0.2 / 0.5)  # the ordering as it is
    assert mir[1, 0] == pytest.approx(rec[1, 0])  # grazing light: the bounded reciprocal estimate
    with pytest.raises(ValueError):
        t.cell_reflectance(e_lv, e_vl, cl, cv, "sideways")


def test_measured_ground_truth_against_itself_has_no_error(shared):
    bsdf = shared / "data" / "rgl" / "paper_white_rgb.bsdf"
    c = cm.compare(bsdf, bsdf, RESOLUTION, 2000)
    # Mitsuba's `measured` is not bitwise reproducible across batch layouts (float32 rounding,
    # ~1e-8 here), so "no error" means far below any error of a fit.
    assert c.mean.rmse < 1e-6 and c.mean.ssim == pytest.approx(1.0)


def test_quick_report_on_one_rgl_material_compares_with_measured_and_authors(cli, shared, tmp_path):
    _tabulate_rgl_with_folds()
    out = tmp_path / "rgl"
    assert train_report.main(["--quick", "--set", "rgl", "--materials", "paper_white_rgb", "--work", str(out),
                              "--no-progress", "--epochs", "4", "--cli", str(cli), "--shared", str(shared)]) == 0
    rows = _read_csv(out / "results.csv")
    assert [r["method"] for r in rows] == ["adaptive", "uniform", "authors"]
    assert all(r["reference"] == "measured" for r in rows)
    assert rows[0]["phi_fold"] == "mirror" and (out / "tables" / "rgl" / "paper_white_rgb.mirror.binary").is_file()
    authors = rows[2]
    # The authors' network is close to the measurement (a sanity bound, not a result).
    assert float(authors["rmse"]) < 0.01 and float(authors["ssim"]) > 0.95
    assert all(0 < float(r["rmse"]) < 0.05 for r in rows)
    md = (out / "report.md").read_text()
    assert "## Ours vs authors on RGL" in md and "| paper_white_rgb |" in md
