"""``python -m nbrdf_tools.estimate_report --quick`` (issue 33): runs end to end on a tiny case,
writes the table and figure, and resumes (a rerun reuses the stored results)."""

from __future__ import annotations


def test_quick_report_runs_and_resumes(llvm_variant, tmp_path):
    from nbrdf_tools.estimate_report import main

    work, out = tmp_path / "work", tmp_path / "estimation.md"
    argv = ["--quick", "--work", str(work), "--models", "nbrdf,roughplastic", "--out", str(out)]
    assert main(argv) == 0
    text = out.read_text()
    assert text.startswith("```sh\npython -m nbrdf_tools.estimate_report")
    assert "| mitsuba-roughplastic | nbrdf |" in text and "| mitsuba-roughplastic | roughplastic |" in text
    assert "lowest novel-view RMSE" in text
    assert (tmp_path / "images" / "estimation.png").stat().st_size > 0
    stored = work / "mitsuba-roughplastic" / "nbrdf.result.json"
    before = stored.stat().st_mtime_ns
    assert main(argv) == 0
    assert stored.stat().st_mtime_ns == before  # resumed, not re-estimated
    assert "| mitsuba-roughplastic | nbrdf |" in out.read_text() and "prior strength" in out.read_text()
    # --stored-only estimates nothing: a model never run is listed as missing.
    assert main(["--quick", "--work", str(work), "--models", "nbrdf,principled", "--out", str(out),
                 "--stored-only"]) == 0
    assert "Not run (missing from this table): mitsuba-roughplastic principled" in out.read_text()
    assert not (work / "mitsuba-roughplastic" / "principled.result.json").exists()


def test_merl_truths_are_unseen_by_the_prior():
    """A MERL truth from the autoencoder's training split would flatter the prior: the
    report's tables must come from its test split."""
    import json

    from nbrdf_tools.estimate_report import MERL
    from nbrdf_tools.paths import REPO

    split = json.loads((REPO / "nbrdf-core" / "data" / "models" / "autoencoder.json").read_text())["split"]
    assert set(MERL) <= set(split["test"])
    assert not set(MERL) & (set(split["train"]) | set(split.get("validation", [])))
