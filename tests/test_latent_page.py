"""docs/results/latent.md's data path: a measuring run's `nbrdf ae eval` summary and seed
selection (here made up) go into the stored data in the page's layout, and the page written after
the run is the page that ``--stored-only`` writes from the same data."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from nbrdf_tools.common import stored_page
from nbrdf_tools.pages import latent_page

REPO = Path(__file__).resolve().parents[1]


def _stats(mean, std, median):
    return {"mean": mean, "std": std, "median": median}


EV = {"pca": {"tables": "nbrdf"},
      "summary": {"ae": {m: _stats(0.01, 0.02, 0.005) for m in ("mae", "rmse", "ssim")},
                  "ae_refined": {"mae": _stats(0.000421, 0.00034, 0.000339), "rmse": _stats(0.0024, 0.003, 0.0012),
                                 "ssim": _stats(0.9974, 0.0031, 0.9981)},
                  "pca": {m: _stats(0.5, 0.25, 0.125) for m in ("mae", "rmse", "ssim")}},
      "materials": [{"name": "a", "ae_refined": {"mae": 0.1, "rmse": 0.2, "ssim": 0.9},
                     "pca": {"mae": 0.2, "rmse": 0.1, "ssim": 0.8}},
                    {"name": "b", "ae_refined": {"mae": 0.3, "rmse": 0.2, "ssim": 0.5},
                     "pca": {"mae": 0.2, "rmse": 0.3, "ssim": 0.8}}]}
PROVENANCE = {"selection": {"criterion": "refined validation loss",
                            "candidates": [{"seed": 0, "refined_validation_loss": 4.2e-5},
                                           {"seed": 1, "refined_validation_loss": 1.35e-5},
                                           {"seed": 2, "refined_validation_loss": 1.8e-4}]}}


def test_a_run_s_summary_in_the_page_s_layout():
    table = latent_page.ae_vs_pca_table(EV, "authors")
    assert table["rows"][1] == ["**autoencoder (32), refined code**", "**0.00042** ± 0.00034 (0.00034)",
                                "**0.00240** ± 0.00300 (0.00120)", "**0.997** ± 0.003 (0.998)"]
    assert table["rows"][2] == ["PCA-32", "0.50000 ± 0.25000 (0.12500)", "0.50000 ± 0.25000 (0.12500)",
                                "0.500 ± 0.250 (0.125)"]
    assert table["rows"][-1][0].startswith("the paper")
    assert latent_page.ae_vs_pca_table({**EV, "pca": {"tables": "sgd"}}, "sgd")["rows"][-1][0] == "PCA-32 (SGD tables)"
    assert latent_page.wins(EV) == {"mae": 1, "rmse": 1, "ssim": 1, "of": 2}
    assert latent_page.selection(PROVENANCE) == {"chosen": 1, "loss": 1.35e-5, "others": [4.2e-5, 1.8e-4]}
    data = {"runs": {}, "tables": {}}
    latent_page.update(data, EV, PROVENANCE, "authors", "python -m nbrdf_tools latent --source authors", 30)
    text = latent_page.describe_run(data["runs"]["authors"])
    assert "seed 1 chosen (refined validation loss 1.35e-5, against 4.2e-5 and 1.8e-4" in text
    assert "MAE for 1, RMSE 1, SSIM 1 of the 2 materials" in text and "30 iterations" in text


def test_a_measured_run_and_the_stored_path_write_the_same_page(tmp_path):
    data_file, page_file = tmp_path / "latent.json", tmp_path / "latent.md"
    latent_page.write_measured(EV, PROVENANCE, "sgd", "python -m nbrdf_tools latent --out x", 30, data_file, page_file)
    data, recorded = stored_page.load(data_file), stored_page.load(stored_page.data_path("latent"))
    assert data["tables"]["ae_vs_pca_sgd"]["rows"][1][1] == "**0.00042** ± 0.00034 (0.00034)"
    assert data["tables"]["ae_vs_pca_authors"] == recorded["tables"]["ae_vs_pca_authors"]
    assert "`python -m nbrdf_tools latent --out x`" in page_file.read_text()
    again = tmp_path / "again.md"
    done = subprocess.run([sys.executable, "-m", "nbrdf_tools", "latent", "--stored-only", "--data", str(data_file),
                           "--out", str(again)], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert again.read_text() == page_file.read_text()


def test_trial_runs_leave_the_stored_data_alone(tmp_path):
    record, page = stored_page.data_path("latent"), stored_page.page_path("latent")
    assert latent_page.files_of_run(None, None, tmp_path) == (record, page)
    assert latent_page.files_of_run(None, tmp_path, tmp_path) == (tmp_path / "latent.json", tmp_path / "latent.md")
    assert latent_page.files_of_run(record, tmp_path, tmp_path) == (record, page)
