"""docs/results/estimation.md is exactly what its opening command writes from the figures checked
in beside it (docs/results/estimation/stored.json), and its numbers are the stored figures'
means, spreads and ratios, recomputed here in float64 (nothing is estimated or rendered)."""

from __future__ import annotations

import json
import statistics

import pytest

from nbrdf_tools.common.paths import REPO
from nbrdf_tools.pages.estimation import main, seeds

PAGE = REPO / "docs" / "results" / "estimation.md"
STORED = REPO / "docs" / "results" / "estimation" / "stored.json"


def row(text, material, model):
    (line,) = [x for x in text.splitlines() if x.startswith(f"| {material} | {model} |")]
    return [c.strip() for c in line.strip("|").split("|")]


def test_the_page_is_what_its_command_writes(tmp_path):
    first = PAGE.read_text().splitlines()[:3]
    assert first == ["```sh", "python -m nbrdf_tools estimation --stored-only --out docs/results/estimation.md", "```"]
    out = tmp_path / "estimation.md"
    assert main(["--stored-only", "--out", str(out)]) == 0
    assert out.read_bytes() == PAGE.read_bytes(), \
        "docs/results/estimation.md is not what its opening command writes: run it and commit the page"
    assert (PAGE.parent / json.loads(STORED.read_text())["figure"]["path"]).is_file()


def figures_by_seed(stored: dict, which: str) -> dict[tuple[str, str], dict]:
    """The stored novel-view RMSE of set ``which``, by (material, model) and then seed."""
    figures: dict[tuple[str, str], dict] = {}
    for r in stored["results"]:
        if r["set"] == which:
            figures.setdefault((r["material"], r["model"]), {})[r.get("seed")] = r["rmse_tonemapped"]
    return figures


def test_the_tables_numbers_are_the_stored_figures():
    stored, text = json.loads(STORED.read_text()), PAGE.read_text()
    figures = figures_by_seed(stored, "tuning")  # the per-model table is the tuning set's
    assert len(figures) == 42
    for (material, model), by_seed in figures.items():
        cells = row(text, material, model)
        values = list(by_seed.values())
        assert float(cells[3]) == pytest.approx(statistics.fmean(values), abs=5e-5)
        if len(values) > 1:
            assert float(cells[4]) == pytest.approx(statistics.stdev(values), abs=5e-5)
            assert cells[5] == f"{min(values):.4f}-{max(values):.4f}"
        analytic = [statistics.fmean(v.values()) for (m, mod), v in figures.items()
                    if m == material and mod in ("principled", "roughconductor", "roughplastic")]
        assert float(cells[6].rstrip("x")) == pytest.approx(statistics.fmean(values) / min(analytic), abs=5e-3)
        prior = figures[material, "nbrdf"]
        if model not in ("nbrdf", "nbrdf-from-truth"):
            shared = [s for s in by_seed if s in prior]
            assert cells[7] == f"{sum(prior[s] < by_seed[s] for s in shared)} of {len(shared)}"
    # Rows of several seeds and of one: their seed lists and the seeds both were measured at.
    assert row(text, "rgl-paper_white", "nbrdf")[2] == "0-1"
    assert row(text, "rgl-colodur_napoli_4f", "principled")[2] == "0-2, 4"
    assert row(text, "merl-red-specular-plastic", "nbrdf-no-prior")[2] == "0-5"
    assert row(text, "merl-red-specular-plastic", "nbrdf-no-prior")[7] == "2 of 2"
    measured = [m for m in {m for m, _ in figures} if not m.startswith("mitsuba-")]
    ratios = [statistics.fmean(figures[m, "nbrdf"].values())
              / min(statistics.fmean(v.values()) for (mm, mod), v in figures.items()
                    if mm == m and mod in ("principled", "roughconductor", "roughplastic")) for m in measured]
    assert f"* mean over the 6 measured materials (RGL and MERL): {statistics.fmean(ratios):.2f}x" in text
    for which in ("test", "tuning"):
        for seed in (0, 1):
            wall = [r["seconds"] for r in stored["results"] if r["model"] == "nbrdf" and "seconds" in r
                    and r["set"] == which and r.get("seed") == seed]
            if wall:
                span = f"{min(wall):.0f}-{max(wall):.0f}"
                assert f"| {which} | nbrdf | {seed} | {span} | {statistics.median(wall):.0f} |" in text


def test_the_test_sets_table_is_the_stored_figures():
    """Each test truth's row: the prior's RMSE, the best analytic model's and their ratio, from the
    stored figures' means over the seeds each was measured at."""
    stored, text = json.loads(STORED.read_text()), PAGE.read_text()
    figures = figures_by_seed(stored, "test")
    for material in {m for m, _ in figures}:
        rmse = {model: statistics.fmean(by_seed.values()) for (m, model), by_seed in figures.items() if m == material}
        analytic = {m: v for m, v in rmse.items() if m in ("principled", "roughconductor", "roughplastic")}
        cells = next(line for line in text.splitlines() if line.startswith(f"| {material} | ")).split(" | ")
        best = min(analytic, key=analytic.get)
        assert cells[5] == f"{analytic[best]:.4f} ({best})"
        if "nbrdf" in rmse:
            assert cells[3] == f"{rmse['nbrdf']:.4f}"
            assert float(cells[6].rstrip("x")) == pytest.approx(rmse["nbrdf"] / analytic[best], abs=5e-3)
        else:
            assert cells[3] == "-" and f"`{material}`" in text.split("**The test set is measured in part**")[1]


def work_result(work, material, model, rmse, seed):
    folder = work / material
    folder.mkdir(parents=True, exist_ok=True)
    result = {"material": material, "model": model, "rmse_tonemapped": rmse, "seconds": 10.0 + rmse,
              "cpu_seconds": 20.0, "novel": [{"rmse_tonemapped": rmse}] * 3,
              "novel_pairs": [["0, 0, 4", "1, 1, 1", 10.0]], "novel_spp": 64, "truth_spp": 256}
    if seed is not None:
        result["settings"] = {"views": 2, "steps": 7, "spp": 4, "seed": seed}
    (folder / f"{model}.result.json").write_text(json.dumps(result))


def test_work_folders_collected_into_a_stored_file_give_the_page(tmp_path):
    rmse = {("rgl-paper_white", "nbrdf"): [0.010, 0.014], ("rgl-paper_white", "principled"): [0.015, 0.012]}
    works = [tmp_path / f"seed{seed}" for seed in (0, 1)]
    for seed, work in enumerate(works):
        for (material, model), values in rmse.items():
            work_result(work, material, model, values[seed], seed)
        work_result(work, "rgl-paper_white", "nbrdf-from-truth", 0.005, None)  # in both: counted once
    stored, out = tmp_path / "stored.json", tmp_path / "page.md"
    assert seeds.main(["--work", *map(str, works), "--stored", str(stored)]) == 0
    collected = json.loads(stored.read_text())
    assert collected["settings"]["steps"] == 7 and collected["settings"]["novel_spp"] == 64
    assert [(r["model"], r.get("seed")) for r in collected["results"]] == [
        ("nbrdf", 0), ("nbrdf", 1), ("principled", 0), ("principled", 1), ("nbrdf-from-truth", None)]
    assert collected["results"][0]["rmse_per_pair"] == [0.010] * 3
    assert main(["--stored-only", "--stored", str(stored), "--out", str(out)]) == 0
    text = out.read_text()
    assert text.startswith(f"```sh\npython -m nbrdf_tools estimation --stored-only --stored {stored} --out ")
    cells = row(text, "rgl-paper_white", "nbrdf")
    assert cells[2:6] == ["0-1", "0.0120", f"{statistics.stdev([0.010, 0.014]):.4f}", "0.0100-0.0140"]
    assert cells[6] == f"{0.012 / 0.0135:.2f}x"
    assert row(text, "rgl-paper_white", "principled")[7] == "1 of 2"
    assert row(text, "rgl-paper_white", "nbrdf-from-truth")[2:4] == ["-", "0.0050"]
    assert "2 training views" in text and "7 steps, 4 spp" in text and "at 64 spp against the truth's 256" in text


def test_stored_goes_with_stored_only_and_without_work(tmp_path):
    with pytest.raises(SystemExit, match="--stored goes with --stored-only"):
        main(["--stored", str(STORED), "--out", str(tmp_path / "x.md")])
    with pytest.raises(SystemExit, match="--stored goes with --stored-only"):
        main(["--stored-only", "--stored", str(STORED), "--work", str(tmp_path)])


def headline_row(text, which):
    """The headline table's row of ``which`` (the first table whose rows open with a set)."""
    line = next(x for x in text.splitlines() if x.startswith(f"| {which} | "))
    return [c.strip() for c in line.strip("|").split("|")]


def prior_ratios(results, model="nbrdf"):
    """material -> ``model``'s (the prior's) mean RMSE over the best analytic model's mean (from
    stored rows)."""
    means: dict[tuple[str, str], list] = {}
    for r in results:
        means.setdefault((r["material"], r["model"]), []).append(r["rmse_tonemapped"])
    ratios = {}
    for material in {m for m, _ in means}:
        analytic = [statistics.fmean(v) for (m, other), v in means.items()
                    if m == material and other in ("principled", "roughconductor", "roughplastic")]
        if (material, model) in means and analytic:
            ratios[material] = statistics.fmean(means[material, model]) / min(analytic)
    return ratios


def test_the_headline_leads_with_the_test_set_and_its_ratios_are_the_stored_figures():
    """The test set leads; each set's headline row (materials, mean, median and worst ratio, wins,
    the measured materials' mean) is the stored figures'; where the test set is measured in part
    the page says so."""
    stored, text = json.loads(STORED.read_text()), PAGE.read_text()
    assert len(text.splitlines()) < 200
    assert text.index("## The headline: the test set") < text.index("## The tuning set")
    assert text.index("| test |") < text.index("| tuning |")
    for which, count in (("test", None), ("tuning", 7)):
        ratios = prior_ratios([r for r in stored["results"] if r["set"] == which])
        cells = headline_row(text, which)
        if not ratios:
            assert cells[3] in ("not measured yet", "no `nbrdf` estimate yet")
            continue
        assert cells[1] == str(len(ratios)) and (count is None or len(ratios) == count)
        assert cells[3] == f"{statistics.fmean(ratios.values()):.2f}x"
        assert cells[4] == f"{statistics.median(ratios.values()):.2f}x"
        worst = max(ratios, key=ratios.get)
        assert cells[5] == f"{ratios[worst]:.2f}x ({worst})"
        assert cells[6] == f"{sum(v < 1 for v in ratios.values())} of {len(ratios)}"
        measured = [v for m, v in ratios.items() if not m.startswith("mitsuba-")]
        assert cells[7] == f"{statistics.fmean(measured):.2f}x ({len(measured)})"
        ceilings = prior_ratios([r for r in stored["results"] if r["set"] == which], "nbrdf-from-truth")
        assert cells[9] == (f"{statistics.fmean(ceilings[m] for m in ratios):.2f}x" if set(ratios) <= set(ceilings)
                            else "-")
    estimated = {r["material"] for r in stored["results"] if r["set"] == "test" and r["model"] == "nbrdf"}
    assert ("**The test set is measured in part**" in text) == (0 < len(estimated) < 25)


def test_collecting_a_set_keeps_the_others_stored_figures(tmp_path):
    """``estimation-seeds --stored FILE`` over test-set folders keeps FILE's tuning figures; the
    page's test table shows the new ones and the headline computes from them."""
    stored = tmp_path / "stored.json"
    stored.write_text(STORED.read_text())
    settings = json.loads(STORED.read_text())["settings"]
    work = tmp_path / "seed0"
    for model, rmse in (("nbrdf", 0.02), ("nbrdf-no-prior", 0.05), ("principled", 0.04), ("roughconductor", 0.025)):
        folder = work / "merl-chrome-abc"
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{model}.result.json").write_text(json.dumps({
            "material": "merl-chrome-abc", "model": model, "set": "test", "rmse_tonemapped": rmse, "seconds": 60.0,
            "cpu_seconds": 110.0, "cores": 2, "novel": [{"rmse_tonemapped": rmse}] * 3,
            "novel_pairs": settings["novel_pairs"], "novel_spp": settings["novel_spp"],
            "truth_spp": settings["truth_spp"],
            "settings": {"views": settings["views"], "steps": settings["steps"], "spp": settings["spp"], "seed": 0}}))
    assert seeds.main(["--work", str(work), "--stored", str(stored)]) == 0
    collected = json.loads(stored.read_text())
    assert sorted(collected["sets"]) == ["test", "tuning"]
    assert [r for r in collected["results"] if r["set"] == "tuning"] == \
        [r for r in json.loads(STORED.read_text())["results"] if r["set"] == "tuning"]
    assert {r["material"] for r in collected["results"] if r["set"] == "test"} == {"merl-chrome-abc"}
    out = tmp_path / "page.md"
    assert main(["--stored-only", "--stored", str(stored), "--out", str(out)]) == 0
    text = out.read_text()
    assert "has not been measured yet" not in text
    cells = headline_row(text, "test")
    assert cells[1:7] == ["1", "0", "0.80x", "0.80x", "0.80x (merl-chrome-abc)", "1 of 1"]
    (line,) = [x for x in text.splitlines() if x.startswith("| merl-chrome-abc |")]
    assert "0.0250 (roughconductor)" in line and "| 0.80x | 2.00x |" in line
    assert text.index("| merl-chrome-abc |") < text.index("## The tuning set")
    assert "| test | nbrdf | 0 | 60-60 | 60 |" in text


def test_the_ceilings_mean_is_over_every_material_or_none():
    """The headline's ceiling mean is the mean of ceiling / best analytic over the materials with a
    prior's ratio, and absent where one of them has no ceiling (a mean over some would not compare)."""
    from nbrdf_tools.pages.estimation import headline

    cases = {("a", "nbrdf"): {0: 2.0}, ("a", "principled"): {0: 4.0}, ("a", "nbrdf-from-truth"): {None: 1.0},
             ("b", "nbrdf"): {0: 3.0}, ("b", "roughplastic"): {0: 2.0}, ("b", "nbrdf-from-truth"): {None: 0.5}}
    assert headline.summary(headline.per_material(cases))["ceiling_mean"] == pytest.approx((0.25 + 0.25) / 2)
    del cases["b", "nbrdf-from-truth"]
    assert headline.summary(headline.per_material(cases))["ceiling_mean"] is None
    assert headline.table({"test": cases})[2].endswith("| - |")
