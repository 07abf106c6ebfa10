"""``python -m nbrdf_tools estimation-seeds``: the stored results of several seeds' report
runs, tabulated together. Checked against means and spreads computed here in float64 from the
numbers written, on invented results (nothing is estimated)."""

from __future__ import annotations

import json
import statistics

import pytest

from nbrdf_tools.pages.estimation import seeds

SETTINGS = {"views": 3, "steps": 200, "spp": 8}
RMSE = {  # (material, model) -> RMSE per seed 0, 1, 2
    ("rgl-paper_white", "nbrdf"): [0.010, 0.014, 0.012],
    ("rgl-paper_white", "nbrdf-no-prior"): [0.016, 0.015, 0.017],
    ("rgl-paper_white", "principled"): [0.015, 0.016, 0.017],
    ("rgl-paper_white", "roughplastic"): [0.030, 0.031, 0.029],
    ("merl-red-specular-plastic", "nbrdf"): [0.015, 0.020, 0.013],
    ("merl-red-specular-plastic", "nbrdf-no-prior"): [0.013, 0.014, 0.012],
    ("merl-red-specular-plastic", "principled"): [0.028, 0.029, 0.030],
}


def write_result(work, material, model, rmse, settings):
    folder = work / material
    folder.mkdir(parents=True, exist_ok=True)
    result = {"material": material, "model": model, "rmse_tonemapped": rmse, "novel_spp": 4096, "truth_spp": 16384}
    if settings is not None:
        result["settings"] = settings
    (folder / f"{model}.result.json").write_text(json.dumps(result))


def seed_folders(tmp_path, settings=SETTINGS, seeds_=(0, 1, 2)):
    works = []
    for seed in seeds_:
        work = tmp_path / f"seed{seed}"
        for (material, model), values in RMSE.items():
            write_result(work, material, model, values[seed], {**settings, "seed": seed})
        works.append(work)
    # The ceiling is distilled once, without a seed, in the first folder.
    write_result(works[0], "rgl-paper_white", "nbrdf-from-truth", 0.006, None)
    return works


def row(text, material, model):
    (line,) = [x for x in text.splitlines() if x.startswith(f"| {material} | {model} |")]
    return [c.strip() for c in line.strip("|").split("|")]


def test_means_spreads_and_summary_of_the_means(tmp_path):
    out = tmp_path / "seeds.md"
    assert seeds.main(["--work", *map(str, seed_folders(tmp_path)), "--out", str(out)]) == 0
    text = out.read_text()
    assert text.startswith("```sh\npython -m nbrdf_tools estimation-seeds --work")
    for (material, model), values in RMSE.items():
        cells = row(text, material, model)
        assert cells[2:5] == [f"{v:.4f}" for v in values]
        assert float(cells[5]) == pytest.approx(statistics.fmean(values), abs=5e-5)
        assert float(cells[6]) == pytest.approx(statistics.stdev(values), abs=5e-5)
    # The report's order: RGL before MERL, the models in the report's order, the ceiling last.
    lines = [x for x in text.splitlines() if x.startswith("| rgl-") or x.startswith("| merl-")]
    assert lines[0].startswith("| rgl-paper_white | nbrdf |") and lines[-1].startswith("| merl-")
    assert row(text, "rgl-paper_white", "nbrdf-from-truth")[2:] == ["0.0060", "", "", "0.0060", "-"]
    # The summary reads the means: on red the network without the prior is lowest on the mean,
    # though the prior is lowest at seed 2; the prior's ratio is its mean over principled's.
    mean = {case: statistics.fmean(v) for case, v in RMSE.items()}
    red = mean["merl-red-specular-plastic", "nbrdf"] / mean["merl-red-specular-plastic", "principled"]
    paper = mean["rgl-paper_white", "nbrdf"] / mean["rgl-paper_white", "principled"]
    assert "* merl-red-specular-plastic: lowest novel-view RMSE: nbrdf-no-prior" in text
    assert f"nbrdf / best analytic (principled) = {red:.2f}x" in text
    assert "* rgl-paper_white: lowest novel-view RMSE: nbrdf;" in text
    assert f"mean nbrdf / best analytic novel-view RMSE: {(red + paper) / 2:.2f}x over 2 materials" in text
    assert "Not run at every seed" not in text


def test_a_case_missing_at_a_seed_is_named(tmp_path):
    works = seed_folders(tmp_path)
    (works[2] / "rgl-paper_white" / "principled.result.json").unlink()
    out = tmp_path / "seeds.md"
    assert seeds.main(["--work", *map(str, works), "--out", str(out)]) == 0
    text = out.read_text()
    assert row(text, "rgl-paper_white", "principled")[2:5] == ["0.0150", "0.0160", "-"]
    assert "Not run at every seed (means over fewer): rgl-paper_white principled (2 of 3)" in text


def test_folders_that_differ_in_more_than_the_seed_are_refused(tmp_path):
    works = seed_folders(tmp_path / "a", seeds_=(0, 1)) + seed_folders(tmp_path / "b", {**SETTINGS, "steps": 100},
                                                                         seeds_=(2,))
    with pytest.raises(SystemExit, match="differ in more than their seed"):
        seeds.main(["--work", *map(str, works)])


def test_folders_measured_on_other_novel_pairs_are_refused(tmp_path):
    works = seed_folders(tmp_path)
    stored = works[1] / "rgl-paper_white" / "nbrdf.result.json"
    result = json.loads(stored.read_text())
    stored.write_text(json.dumps({**result, "novel_pairs": [["0, 0, 4", "1, 1, 1", 10.0]]}))
    with pytest.raises(SystemExit, match="differ in more than their seed"):
        seeds.main(["--work", *map(str, works)])


def test_one_seed_in_two_folders_is_refused(tmp_path):
    works = seed_folders(tmp_path / "a", seeds_=(0, 1)) + seed_folders(tmp_path / "b", seeds_=(1,))
    with pytest.raises(SystemExit, match="seed 1"):
        seeds.main(["--work", *map(str, works)])


def test_a_folder_without_results_is_refused(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit, match="no stored results"):
        seeds.main(["--work", str(tmp_path / "empty")])
