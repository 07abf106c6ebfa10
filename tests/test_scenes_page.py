"""docs/results/scenes.md's data path: a measuring run's report (here a made-up one, two
materials, two seeds) goes into the stored data in the page's layout, and the page written after
the run is the page that ``--stored-only`` writes from the same data."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from nbrdf_tools.common import stored_page
from nbrdf_tools.pages.scenes import page, record

REPO = Path(__file__).resolve().parents[1]


def _settings(scene="veach", integrator="bsdf"):
    return {"scene": scene, "integrator": integrator, "resolution": [64, 43], "max_spp": 4, "gt_spp": 32,
            "seeds": 2, "variant": "llvm_ad_rgb", "train_args": ["--epochs", "2"], "seconds": 12.3}


def _veach_report(integrator="bsdf"):
    equal_time = [{"material": "aluminium", "seconds": 0.5, "exponent": 3162.3, "specular_weight": 0.8,
                   "rmse": {"uniform": 10.0, "cosine": 4.0, "phong-fit": 0.5}},
                  {"material": "cc_paint", "seconds": 1.25, "exponent": 75.0, "specular_weight": 0.75,
                   "rmse": {"uniform": 2.0, "cosine": 2.5, "phong-fit": 0.625, "measured": 0.5}}]
    representation = [{"material": "aluminium", "model": "nbrdf", "network": "trained", "region": "plates",
                       "mae": 0.0030691, "rmse": 0.021264, "relative_rmse": 0.0351, "mape": 0.0069412,
                       "psnr_peak1": 33.46}]
    results = [{"strategy": "cosine", "spp": 1, "seed": 0, "rmse": 1.0, "seconds": 0.1}]
    return {"settings": _settings("veach", integrator), "equal_time": equal_time,
            "representation": representation, "results": results}


def _kitchen_strategies_report():
    results = [{"strategy": s, "spp": spp, "seed": seed, "rmse": rmse * (1 + 0.1 * seed), "seconds": t + seed}
               for s, rmse, t in (("cosine", 0.08, 2.0), ("phong-fit", 0.07, 2.5), ("tabulated", 0.0735, 3.0))
               for spp in (1, 4) for seed in (0, 1, 2)]
    equal_time = [{"material": "2 overrides", "seconds": 2.0, "default_sampling": "tabulated x2",
                   "rmse": {"cosine": 0.09, "phong-fit": 0.072, "tabulated": 0.0756}}]
    representation = [{"material": "2 overrides", "model": "nbrdf", "network": "trained", "region": "image",
                       "mae": 0.001, "rmse": 0.03612, "relative_rmse": 0.01439, "mape": 0.01, "psnr_peak1": 30.0}]
    kitchen = {"spp": 4, "pixels": 1296, "overridden_pixels_percent": 48.7,
               "nonfinite_pixels": {"nbrdf": 0, "merl": 0, "nbrdf_reference": 0, "all_strategy_renders": 0},
               "fireflies": {"nbrdf": 1, "merl": 0}}
    return {"settings": _settings("kitchen"), "equal_time": equal_time, "representation": representation,
            "results": results, "kitchen": kitchen}


def test_a_veach_run_fills_its_section_in_the_page_s_layout():
    data = {"tables": {}, "runs": {}}
    assert record.update(data, _veach_report()) == "veach"
    table = data["tables"]["veach"]
    assert table["columns"] == ["material", "Phong n, w", "time (s)", "uniform", "cosine", "phong-fit", "measured",
                                "phong-fit / cosine", "phong-fit / uniform"]
    assert table["rows"][0] == ["aluminium", "3.16e+03, 0.80", "0.50", "10", "4", "0.5", "-", "0.12", "0.050"]
    assert table["rows"][1] == ["cc_paint", "75, 0.75", "1.25", "2", "2.5", "0.625", "0.5", "0.25", "0.312"]
    assert data["tables"]["veach_representation"]["rows"] == [
        ["aluminium", "nbrdf", "trained", "plates", "0.003069", "0.02126", "0.035", "0.006941", "33.5"]]
    run = data["runs"]["veach"]
    assert run["resolution"] == [64, 43] and run["spp"] == [1, 4] and run["seeds"] == 2
    assert run["training"] == "--epochs 2" and run["seconds"] == 12.3 and run["date"]
    # MIS has no representation table of its own (the references are the same).
    assert record.update(data, _veach_report("mis")) == "veach_mis" and "veach_mis_representation" not in data["tables"]


def test_a_kitchen_run_with_the_lobes_and_the_table_fills_the_strategies_section():
    data = {"tables": {}, "runs": {}}
    assert record.update(data, _kitchen_strategies_report()) == "kitchen_strategies"
    table = data["tables"]["kitchen_strategies"]
    assert table["columns"][-2:] == ["cosine / phong-fit", "tabulated / phong-fit"]
    assert table["rows"] == [["2 overrides", "tabulated x2", "2.00", "0.09", "0.072", "0.0756", "1.25", "1.05"]]
    # At the highest spp (4), the median over seeds 0-2 is seed 1's render: RMSE x1.1, time +1 s.
    assert data["tables"]["kitchen_strategies_equal_spp"]["rows"] == [
        ["cosine", "0.088", "1.14", "3.00"], ["phong-fit", "0.077", "1.00", "3.50"],
        ["tabulated", "0.0809", "1.05", "4.00"]]
    run = data["runs"]["kitchen_strategies"]
    assert run["checks"] == {"spp": 4, "pixels": 1296, "nonfinite": 0, "fireflies_nbrdf": 1, "fireflies_table": 0,
                             "replaced_percent": 49}
    assert run["representation"] == {"rmse": 0.0361, "relative_rmse": 0.0144}
    text = page.describe_checks(run)
    assert "1 (NBRDF) and 0 (table) of 1,296 pixels" in text and "cover 49 %" in text and "relative 1.4 %" in text


def test_a_measured_run_and_the_stored_path_write_the_same_page(tmp_path):
    data_file, page_file = tmp_path / "scenes.json", tmp_path / "scenes.md"
    assert page.write_measured(_veach_report(), data_file, page_file) == "veach"
    data = stored_page.load(data_file)
    recorded = stored_page.load(stored_page.data_path("scenes"))
    # The run replaced its section and kept the others as stored.
    assert data["tables"]["veach"]["rows"][0][0] == "aluminium" and len(data["tables"]["veach"]["rows"]) == 2
    assert data["tables"]["kitchen"] == recorded["tables"]["kitchen"]
    assert "64x43, 1–4 spp, references at 32 spp, 2 seeds" in page_file.read_text()
    again = tmp_path / "again.md"
    done = subprocess.run([sys.executable, "-m", "nbrdf_tools", "scenes", "--stored-only", "--data", str(data_file),
                           "--out", str(again)], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert again.read_text() == page_file.read_text()


def test_trial_runs_leave_the_stored_data_alone(tmp_path):
    def files(**given):
        args = argparse.Namespace(**{"data": None, "out": None, "quick": False, **given})
        return page.files_of_run(args, given.get("out") or tmp_path / "default")

    assert files() == (stored_page.data_path("scenes"), stored_page.page_path("scenes"))
    assert files(quick=True) == (tmp_path / "default" / "scenes.json", tmp_path / "default" / "scenes.md")
    assert files(out=tmp_path / "x") == (tmp_path / "x" / "scenes.json", tmp_path / "x" / "scenes.md")
    assert files(out=tmp_path / "x", data=stored_page.data_path("scenes"))[1] == stored_page.page_path("scenes")
