"""``python -m nbrdf_tools estimation --quick`` (issue 33): runs end to end on a tiny case,
writes the table and figure, and resumes (a rerun reuses the stored results)."""

from __future__ import annotations

import pytest


def test_quick_report_runs_and_resumes(llvm_variant, tmp_path):
    from nbrdf_tools.pages.estimation import main

    work, out = tmp_path / "work", tmp_path / "estimation.md"
    argv = ["--quick", "--set", "tuning", "--work", str(work), "--models", "nbrdf,roughplastic", "--out", str(out)]
    assert main(argv) == 0
    text = out.read_text()
    assert text.startswith("```sh\npython -m nbrdf_tools estimation")
    assert "| mitsuba-roughplastic | nbrdf |" in text and "| mitsuba-roughplastic | roughplastic |" in text
    assert "lowest novel-view RMSE" in text
    assert (tmp_path / "images" / "estimation.png").stat().st_size > 0
    # The ceiling: the isotropic network distilled from the truth, measured on the same pairs.
    import json

    ceiling = json.loads((work / "mitsuba-roughplastic" / "nbrdf-from-truth.nbrdf.json").read_text())
    assert ceiling["layers"][0]["inputs"] == 6 and ceiling["sampling"]
    assert "| mitsuba-roughplastic | nbrdf-from-truth |" in text and "the network trained on the truth itself" in text
    stored = work / "mitsuba-roughplastic" / "nbrdf.result.json"
    before = stored.stat().st_mtime_ns
    assert main(argv) == 0
    assert stored.stat().st_mtime_ns == before  # resumed, not re-estimated
    assert "| mitsuba-roughplastic | nbrdf |" in out.read_text() and "pull strength" in out.read_text()
    # --stored-only estimates nothing: a model never run is listed as missing.
    assert main(["--quick", "--set", "tuning", "--work", str(work), "--models", "nbrdf,principled", "--out", str(out),
                 "--stored-only"]) == 0
    assert "Not run (missing from this table): mitsuba-roughplastic principled" in out.read_text()
    assert not (work / "mitsuba-roughplastic" / "principled.result.json").exists()


def test_every_novel_pair_is_measured_and_old_results_are_remeasured(llvm_variant, tmp_path):
    """The table's image metrics are the means over every novel pair; a result stored before the
    pairs changed is measured again from its stored estimate, which is not estimated again."""
    import json

    import numpy as np

    from nbrdf_tools.pages.estimation import NOVEL_PAIRS, main

    work, out = tmp_path / "work", tmp_path / "estimation.md"
    argv = ["--quick", "--set", "tuning", "--work", str(work), "--models", "roughplastic", "--out", str(out),
            "--no-ceiling"]
    assert main(argv) == 0
    folder = work / "mitsuba-roughplastic"
    assert len(NOVEL_PAIRS) == 3
    for prefix in ("novel", "novel1", "novel2"):
        assert (folder / f"{prefix}-truth-0.exr").is_file() and (folder / f"{prefix}-roughplastic-0.exr").is_file()
    stored = folder / "roughplastic.result.json"
    result = json.loads(stored.read_text())
    assert len(result["novel"]) == 3
    assert result["rmse_tonemapped"] == np.mean([m["rmse_tonemapped"] for m in result["novel"]])
    # The pairs differ in light and view: their errors are three numbers, not one repeated.
    assert len({round(m["rmse_tonemapped"], 8) for m in result["novel"]}) == 3
    estimate_file = folder / "roughplastic.json"
    before = estimate_file.stat().st_mtime_ns
    old = {k: v for k, v in result.items() if k not in ("novel", "novel_pairs")}
    stored.write_text(json.dumps({**old, "rmse_tonemapped": 1.0}))
    assert main(argv) == 0
    again = json.loads(stored.read_text())
    assert estimate_file.stat().st_mtime_ns == before
    assert again["rmse_tonemapped"] == result["rmse_tonemapped"] and again["novel_pairs"] == result["novel_pairs"]
    # Other samples for the novel renders: the truth's are rendered again and the stored estimate is
    # measured again at them, not estimated again.
    truth = folder / "novel-truth-0.exr"
    truth_before = truth.read_bytes()
    record = json.loads((folder / "novel-truth.json").read_text())
    assert record["novel_spp"] == again["novel_spp"] == 16 and record["truth_spp"] == again["truth_spp"] == 64
    assert main([*argv, "--measure-spp", "32"]) == 0
    remeasured = json.loads(stored.read_text())
    assert estimate_file.stat().st_mtime_ns == before
    record = json.loads((folder / "novel-truth.json").read_text())
    assert record["novel_spp"] == remeasured["novel_spp"] == 32 and record["truth_spp"] == remeasured["truth_spp"] == 128
    assert truth.read_bytes() != truth_before and remeasured["rmse_tonemapped"] != result["rmse_tonemapped"]
    assert "novel renders take 32 spp, the truth's 128" in out.read_text()


def test_bad_counts_are_refused(tmp_path):
    from nbrdf_tools.pages.estimation import main

    for flag in ("--steps", "--spp", "--measure-spp"):
        with pytest.raises(SystemExit, match=f"{flag} must be at least 1"):
            main(["--quick", "--work", str(tmp_path), flag, "0"])
    from nbrdf_tools.pages.estimation import convergence

    with pytest.raises(SystemExit, match="--measure-spp must be at least 1"):
        convergence.main(["--work", str(tmp_path), "--materials", "mitsuba-roughplastic", "--measure-spp", "0"])


def test_the_ceiling_is_no_competitor():
    """The network distilled from the truth is reported beside the estimates, never as a
    material's lowest nor in the estimate's ratio to the best analytic model."""
    from nbrdf_tools.pages.estimation import CEILING, summary

    rows = [("nbrdf", 0.02), ("nbrdf-no-prior", 0.04), ("principled", 0.03), (CEILING, 0.006)]
    lines = summary([{"material": "rgl-x", "model": m, "rmse_tonemapped": v} for m, v in rows])
    assert lines[0].startswith("* rgl-x: lowest novel-view RMSE: nbrdf;")
    assert "nbrdf / best analytic (principled) = 0.67x" in lines[0]
    assert "the network trained on the truth itself 0.0060" in lines[0]
    assert lines[-1].startswith(f"* the ceiling, {CEILING}") and "0.20x over the 1 measured" in lines[-1]


def test_the_chosen_start_is_named(tmp_path):
    """The run page names each prior estimate's start from its provenance: the decoded start with
    its strengths, the analytic fit chosen with its model (as the network's base, or distilled in
    files written before), the common start."""
    import json

    from nbrdf_tools.pages.estimation import chosen_strengths

    provenances = {
        "rgl-a": {"start": "decoded", "pull_strength": 0.1, "code_strength": 0.0, "held_out_losses": {"0.1": 0.002}},
        "rgl-b": {"start": "analytic", "pull_strength": None, "code_strength": None,
                  "analytic": {"type": "roughplastic"}, "held_out_losses": {"0.1": 0.002, "roughplastic": 0.001}},
        "rgl-c": {"start": "common", "pull_strength": None, "code_strength": None},
    }
    provenances["rgl-d"] = provenances["rgl-b"]
    for name, provenance in provenances.items():
        (tmp_path / name).mkdir()
        base = {"base": provenance["analytic"]} if name == "rgl-d" else {}
        (tmp_path / name / "nbrdf.nbrdf.json").write_text(json.dumps({**base, "provenance": provenance}))
    lines = chosen_strengths([{"material": name, "model": "nbrdf"} for name in provenances], tmp_path)
    assert lines[0] == "* rgl-a: pull strength 0.1, code strength 0.0 (held-out view loss 0.1: 0.002)"
    assert lines[1] == ("* rgl-b: the roughplastic fit, distilled (held-out view loss 0.1: 0.002; "
                        "roughplastic: 0.001)")
    assert lines[2].startswith("* rgl-c: the common start, no prior")
    assert lines[3].startswith("* rgl-d: the roughplastic fit, as its base (held-out")


def test_merl_truths_are_unseen_by_the_prior():
    """A MERL truth from the autoencoder's training split would flatter the prior: the
    report's tables must come from its test split."""
    import json

    from nbrdf_tools.pages.estimation import MERL
    from nbrdf_tools.common.paths import REPO

    split = json.loads((REPO / "nbrdf-core" / "data" / "models" / "autoencoder.json").read_text())["split"]
    assert set(MERL) <= set(split["test"])
    assert not set(MERL) & (set(split["train"]) | set(split.get("validation", [])))


def test_no_models_renders_the_truths_alone(llvm_variant, tmp_path):
    """``--models , --no-ceiling`` renders each truth's training and novel images and estimates
    nothing, so that a timed run that follows measures estimates only."""
    from nbrdf_tools.pages.estimation import main

    work = tmp_path / "work"
    assert main(["--quick", "--set", "tuning", "--work", str(work), "--models", ",", "--no-ceiling"]) == 0
    (folder,) = [p for p in work.iterdir() if (p / "truth.xml").is_file()]
    assert (folder / "train0.exr").is_file() and (folder / "novel-truth-0.exr").is_file()
    assert not list(work.glob("*/*.result.json")) and not (work / "estimation.md").exists()


def test_more_views_keep_the_first_views_images(llvm_variant, tmp_path):
    """``--views N`` adds training images; image i is the same whatever N, so runs with
    different view counts are comparable (their results are not: the next test)."""
    import numpy as np
    import pytest

    from nbrdf_tools.pages.estimation import MITSUBA_TRUTH, QUICK, dict_to_xml, parser, prepare, read_exr

    material = {"xml": dict_to_xml(MITSUBA_TRUTH), "dict": MITSUBA_TRUTH}
    prepare("m", material, {**QUICK, "views": 2}, tmp_path)
    first = [read_exr(tmp_path / "m" / f"train{i}.exr") for i in range(2)]
    assert not (tmp_path / "m" / "train2.exr").exists()
    prepare("m", material, {**QUICK, "views": 3}, tmp_path)
    for i in range(2):
        assert np.array_equal(read_exr(tmp_path / "m" / f"train{i}.exr"), first[i])
    assert (tmp_path / "m" / "train2.exr").is_file()
    assert (tmp_path / "m" / "train.xml").read_text().count("<sensor") == 3
    with pytest.raises(SystemExit):
        parser().parse_args(["--views", "99"])


def test_training_images_may_be_finer_than_the_novel_views(llvm_variant, tmp_path):
    """``--train-resolution N``: the training images and the estimate's scene at N x N, the novel
    views at the report's own size; recorded in the estimates' settings only where it differs,
    and a folder's images at another size are rendered again."""
    from nbrdf_tools.pages.estimation import (MITSUBA_TRUTH, QUICK, dict_to_xml, estimate_settings, image_side,
                                             prepare)

    material = {"xml": dict_to_xml(MITSUBA_TRUTH), "dict": MITSUBA_TRUTH}
    settings = {**QUICK, "train_resolution": 24, "seed": 0}
    prepare("m", material, settings, tmp_path)
    folder = tmp_path / "m"
    assert [image_side(folder / f"train{i}.exr") for i in range(QUICK["views"])] == [24] * QUICK["views"]
    assert image_side(folder / "novel-truth-0.exr") == QUICK["resolution"] == 16
    assert '<integer name="width" value="24"/>' in (folder / "train.xml").read_text()
    assert estimate_settings(settings)["train_resolution"] == 24
    assert "train_resolution" not in estimate_settings({**settings, "train_resolution": None})
    prepare("m", material, {**QUICK, "seed": 0}, tmp_path)  # back to the default: rendered again at 16
    assert image_side(folder / "train0.exr") == 16
    assert '<integer name="width" value="16"/>' in (folder / "train.xml").read_text()


def test_a_work_folder_of_other_settings_is_refused(llvm_variant, tmp_path):
    import pytest

    from nbrdf_tools.pages.estimation import main

    work, out = tmp_path / "work", tmp_path / "estimation.md"
    argv = ["--quick", "--set", "tuning", "--work", str(work), "--models", "roughplastic", "--out", str(out),
            "--no-ceiling"]
    assert main(argv) == 0
    folder = work / "mitsuba-roughplastic"
    before = {p.name: p.read_bytes() for p in folder.iterdir() if p.suffix in (".exr", ".xml")}
    with pytest.raises(SystemExit, match="was estimated with .*'steps': 3.*'steps': 4.*another --work"):
        main([*argv, "--steps", "4"])
    with pytest.raises(SystemExit, match="'train_resolution': 24.*another --work"):
        main([*argv, "--train-resolution", "24"])
    with pytest.raises(SystemExit, match="'views': 2.*'views': 3.*another --work"):
        main([*argv, "--views", "3"])
    # Refused before anything is rendered: the folder's images are the ones its estimate was fitted to.
    assert {p.name: p.read_bytes() for p in folder.iterdir() if p.suffix in (".exr", ".xml")} == before
    assert main(argv) == 0  # the same settings: resumed


def test_convergence_curve_runs(llvm_variant, tmp_path):
    """``python -m nbrdf_tools estimation-convergence``: one analytic model's novel-view RMSE
    at each checkpoint, table and figure written (a short run at the report's full size)."""
    from nbrdf_tools.pages.estimation import convergence

    out = tmp_path / "convergence.md"
    assert convergence.main(["--work", str(tmp_path / "work"), "--materials", "mitsuba-roughplastic",
                             "--models", "roughplastic", "--steps", "4", "--checkpoints", "2", "--out", str(out),
                             "--measure-spp", "64"]) == 0
    rows = [line for line in out.read_text().splitlines() if line.startswith("| mitsuba-roughplastic")]
    assert len(rows) == 1
    cells = [float(c) for c in rows[0].strip("|").split("|")[2:]]
    assert len(cells) == 2 and all(0 < c < 1 for c in cells)
    assert (tmp_path / "images" / "estimation-convergence.png").stat().st_size > 0
