"""The estimation report's held-out protocol (issue 60): the truths split once into a tuning set
and a test set, the training scenes written in the forms users write, and the report end to end
on one test-set truth, its results landing in the test set's table."""

from __future__ import annotations

import json

import pytest

from nbrdf_tools.common.paths import REPO
from nbrdf_tools.pages.estimation import truths

TUNING = ["mitsuba-roughplastic", "rgl-paper_white", "rgl-cc_iris_purple_gem", "rgl-cc_ibiza_sunset",
          "rgl-colodur_napoli_4f", "merl-green-metallic-paint", "merl-red-specular-plastic"]


def autoencoder_split() -> dict:
    return json.loads((REPO / "nbrdf-core" / "data" / "models" / "autoencoder.json").read_text())["split"]


def test_the_split():
    """Disjoint sets; the tuning set exactly the seven the defaults were chosen on; at least 20
    test truths, whose MERL materials are all in the autoencoder's test split and none tuned on."""
    test, tuning = truths.names("test"), truths.names("tuning")
    assert tuning == TUNING
    assert len(test) >= 20 and len(set(test)) == len(test)
    assert not set(test) & set(tuning)
    assert truths.names("all") == test + tuning
    assert {truths.set_of(n) for n in test} == {"test"} and {truths.set_of(n) for n in tuning} == {"tuning"}
    split = autoencoder_split()
    merl = [m for m, _, _ in truths.TEST_MERL]
    assert [n for n in test if n.startswith("merl-")] == [f"merl-{m}-{fit}" for m, fit, _ in truths.TEST_MERL]
    assert set(merl) <= set(split["test"])
    assert not set(merl) & (set(split["train"]) | set(split["validation"]))
    assert not set(merl) & {n.removeprefix("merl-") for n in TUNING}
    assert {fit for _, fit, _ in truths.TEST_MERL} == {"sgd", "abc"}
    kinds = {kind for _, _, kind in truths.TEST_MERL}
    assert {"metallic", "plastic", "fabric", "diffuse (wood)", "glossy paint"} <= kinds
    assert {spec.get("material") for spec in truths.TEST_MITSUBA.values()} >= {"Au", "Cu", "Al", "Ag", "Cr"}
    assert set(truths.FORMS) == {truths.form_of(n) for n in test} == {truths.form_of(n) for n in tuning}


def test_extra_rgl_files_join_the_test_set_and_tuned_ones_are_refused(tmp_path):
    extra = tmp_path / "some_paint_rgb.bsdf"
    extra.write_bytes(b"")
    assert truths.names("test", [extra])[-1] == "rgl-some_paint"
    assert truths.set_of("rgl-some_paint") == "test"
    assert "rgl-some_paint" not in truths.names("tuning", [extra])
    truths.check_rgl_files([extra])
    tuned = tmp_path / "paper_white_rgb.bsdf"
    tuned.write_bytes(b"")
    with pytest.raises(SystemExit, match="in the tuning set"):
        truths.check_rgl_files([tuned])
    with pytest.raises(SystemExit, match="no such file"):
        truths.check_rgl_files([tmp_path / "absent_rgb.bsdf"])


def test_scene_forms_render_the_plain_scenes_images(llvm_variant, tmp_path):
    """The marked BSDF nested, in a ``twosided`` or shared by two shapes (the second inside the
    sphere), the field of view a ``-D`` parameter: the same images as the plain scene."""
    from nbrdf_tools.pages.estimation import (LIGHTS, TRAINING_DEFINES, VIEWS, read_exr, render_scene, scene_xml,
                                             training_scene_xml)

    bsdf = truths.dict_to_xml(truths.TEST_MITSUBA["mitsuba-roughplastic-blue"])
    (plain,) = render_scene(scene_xml(bsdf, VIEWS[1:2], LIGHTS, 16), tmp_path / "plain.xml", 8, tmp_path / "plain")
    for form in truths.FORMS:
        text = training_scene_xml(bsdf, form, VIEWS[1:2], LIGHTS, 16)
        assert '<float name="fov" value="$fov"/>' in text and text.count('<bsdf type="roughplastic" id="mat">') == 1
        (image,) = render_scene(text, tmp_path / f"{form}.xml", 8, tmp_path / form, TRAINING_DEFINES)
        assert read_exr(image) == pytest.approx(read_exr(plain), abs=1e-6), form
    with pytest.raises(ValueError, match="unknown scene form"):
        training_scene_xml(bsdf, "inline", VIEWS[:1], LIGHTS, 16)


def test_the_estimate_runs_through_the_twosided_and_shared_forms(llvm_variant, tmp_path):
    """The report's estimate command on a BSDF inside a ``twosided`` and on one shared by two
    shapes, both with the ``-D`` field of view (an analytic model, a few steps)."""
    from nbrdf_tools.pages.estimation import main

    names = ["mitsuba-roughconductor-Cu-0.25", "mitsuba-roughconductor-Al-0.05"]
    assert [truths.form_of(n) for n in names] == ["twosided", "shared"]
    work = tmp_path / "work"
    assert main(["--quick", "--materials", ",".join(names), "--models", "roughconductor", "--steps", "2",
                 "--novel-pairs", "1", "--no-ceiling", "--work", str(work), "--out", str(tmp_path / "page.md")]) == 0
    for name, form in zip(names, ("twosided", "shared")):
        result = json.loads((work / name / "roughconductor.result.json").read_text())
        assert (result["set"], result["scene_form"]) == ("test", form)
        assert 0 < result["rmse_tonemapped"] < 1
        train = (work / name / "train.xml").read_text()
        assert ('type="twosided"' in train) == (form == "twosided") and train.count("<shape") == 1 + (form == "shared")


def test_the_report_end_to_end_on_one_test_truth(llvm_variant, tmp_path):
    """One test-set truth at 16x16, 4 steps, one novel pair, ``nbrdf-no-prior`` and one analytic
    model: the results land in the test set, with their seconds, and both the run's page and the
    results page written from them show them in the test set's table."""
    from nbrdf_tools.pages.estimation import main, page, seeds

    work, out = tmp_path / "work", tmp_path / "run.md"
    assert main(["--quick", "--set", "test", "--steps", "4", "--novel-pairs", "1", "--models",
                 "nbrdf-no-prior,roughconductor", "--no-ceiling", "--work", str(work), "--out", str(out)]) == 0
    (name,) = [p.name for p in work.iterdir() if p.name != "tables"]
    assert name == truths.names("test")[0]
    for model in ("nbrdf-no-prior", "roughconductor"):
        result = json.loads((work / name / f"{model}.result.json").read_text())
        assert result["set"] == "test" and result["settings"]["steps"] == 4 and len(result["novel"]) == 1
        assert result["seconds"] > 0 and result["cores"] >= 1
    run_page = out.read_text()
    assert run_page.index("The test set, per material:") < run_page.index(f"| {name} | {truths.kind_of(name)} |")
    assert "The tuning set, per material:" not in run_page
    stored, results_page = tmp_path / "stored.json", tmp_path / "estimation.md"
    assert seeds.main(["--work", str(work), "--stored", str(stored)]) == 0
    collected = page.load(stored)
    assert list(collected["sets"]) == ["test"] and {r["set"] for r in collected["results"]} == {"test"}
    assert main(["--stored-only", "--stored", str(stored), "--out", str(results_page)]) == 0
    text = results_page.read_text()
    row = next(x for x in text.splitlines() if x.startswith(f"| {name} |"))
    rmse = {r["model"]: r["rmse_tonemapped"] for r in collected["results"]}
    assert f"| {rmse['nbrdf-no-prior']:.4f} | {rmse['roughconductor']:.4f} (roughconductor) |" in row
    assert text.index(row) < text.index("## Setup")
    assert "| test | - | - | no `nbrdf` estimate yet |" in text
    assert "| test | nbrdf-no-prior |" in text
    # No prior's estimate stored: the page names every test truth as still to be estimated, this
    # one with its other models measured.
    missing = next(x for x in text.splitlines() if x.startswith("**The test set is measured in part**"))
    assert f"`{name}` (the other models measured)" in missing
    assert all(f"`{other}`" in missing for other in truths.heldout_names())
