"""Scenes and evaluation (issue #5): the Veach MIS scene as XML and as a dict, the kitchen with
replaced materials, error metrics, the ground-truth cache, and the --quick runs of the
convergence and rays/sec scripts. Tiny images throughout (64x43 Veach, 48x27 kitchen)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

from nbrdf_testing import random_layers, write_network
from nbrdf_tools.common import metrics
from nbrdf_tools.common.render import bsdf_xml, render, render_passes

REPO = Path(__file__).resolve().parents[1]

VEACH_SIZE = (64, 43)
KITCHEN_SIZE = (48, 27)
# A Blinn-Phong lobe that suits the glossy test tables (gold-metallic-paint's SGD fit, or the
# analytic cos^60 fallback table).
PHONG = {"exponent": 40.0, "specular_weight": 0.7}


def veach(plates, integrator="bsdf", xml=False, size=VEACH_SIZE):
    from nbrdf_tools.common.scenes.veach import load_veach_xml, veach_scene_dict

    if xml:
        return load_veach_xml(plates, integrator=integrator, resolution=size)
    return mi.load_dict(veach_scene_dict(plates, integrator=integrator, resolution=size))


@pytest.fixture
def plates_mask(llvm_variant):
    from nbrdf_tools.common.scenes.veach import plate_mask

    return plate_mask(veach({"type": "diffuse"}))


# ---------------------------------------------------------------------------------------------
# Veach


@pytest.mark.parametrize("integrator", ["bsdf", "mis"])
def test_veach_xml_is_the_dict_scene(llvm_variant, integrator, network_file, merl_table):
    """scenes/veach_mis.xml and nbrdf_tools.common.scenes.veach give bit-identical renders, with our BSDFs
    and built-ins on the plates; no NaN or Inf."""
    cases = [
        {"type": "nbrdf", "filename": str(network_file)},
        [{"type": "nbrdf", "filename": str(network_file), "sampling": "uniform"},
         {"type": "merl", "filename": str(merl_table), "sampling": "phong", **PHONG},
         {"type": "roughconductor", "alpha": 0.1},
         {"type": "roughplastic", "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.2, 0.3]}}],
    ]
    for plates in cases:
        from_dict = render(veach(plates, integrator), spp=4, seed=7)
        from_xml = render(veach(plates, integrator, xml=True), spp=4, seed=7)
        assert from_dict.shape == (VEACH_SIZE[1], VEACH_SIZE[0], 3)
        assert np.all(np.isfinite(from_dict)), f"{plates}: NaN or Inf"
        assert np.array_equal(from_dict, from_xml), f"{plates}: XML and dict scenes differ"
        assert from_dict.mean() > 0


def test_veach_xml_defaults_and_parameters(llvm_variant, merl_table, tmp_path):
    """The XML loads with its defaults (the built-in plate) and as a user would call it: one
    plate file for all plates, or one per plate, and emitter_samples = 0 for BSDF sampling."""
    from nbrdf_tools.common.scenes.veach import VEACH_XML

    scene = mi.load_file(str(VEACH_XML), resx="32", resy="22")
    assert "RoughPlastic" in str(scene)
    assert "emitter_samples = 1" in str(scene.integrator())
    plate = tmp_path / "plate.xml"
    plate.write_text(bsdf_xml({"type": "merl", "filename": str(merl_table)}, version=True))
    scene = mi.load_file(str(VEACH_XML), plate=str(plate), plate4=str(REPO / "scenes" / "plates" / "roughplastic.xml"),
                         emitter_samples="0", resx="32", resy="22")
    text = str(scene)
    assert "MerlBSDF[" in text and "RoughPlastic" in text  # (Mitsuba merges the three merl plates)
    assert "emitter_samples = 0" in str(scene.integrator())
    # The example plate files take their file name as a parameter.
    scene = mi.load_file(str(VEACH_XML), plate=str(REPO / "scenes" / "plates" / "merl.xml"), merl=str(merl_table),
                         resx="32", resy="22")
    assert "MerlBSDF[" in str(scene) and "RoughPlastic" not in str(scene)
    assert np.all(np.isfinite(render(scene, spp=1)))


def test_plate_mask_covers_the_plates(llvm_variant, plates_mask):
    share = plates_mask.mean()
    assert 0.2 < share < 0.4, share
    assert not plates_mask[:5].any()  # the top rows see the back wall and the lights


def test_error_falls_as_spp_grows(llvm_variant, merl_table, plates_mask):
    """MIS, as the references are rendered: RMSE and MAE on the plates fall with the spp."""
    bsdf = {"type": "merl", "filename": str(merl_table), "sampling": "phong", **PHONG}
    scene = veach(bsdf, "mis")
    reference = render_passes(scene, spp=1024, spp_per_pass=512, seed=10**6, progress=False)
    images = [render(scene, spp=spp, seed=spp) for spp in (2, 16, 128)]
    rmse = [metrics.rmse(reference, image, plates_mask) for image in images]
    mae = [metrics.mae(reference, image, plates_mask) for image in images]
    assert rmse[0] > rmse[1] > rmse[2] and mae[0] > mae[1] > mae[2], (rmse, mae)
    assert rmse[2] < 0.3 * rmse[0], rmse


def test_phong_sampling_beats_uniform_on_a_glossy_material(llvm_variant, merl_table, plates_mask):
    """Pure BSDF sampling (the estimator that depends on the BSDF's sampling alone), equal spp:
    Blinn-Phong sampling of a glossy table against uniform hemisphere sampling of the same table.
    The Veach scene's small bright lights make the error heavy-tailed at low spp, so the RMSE is
    taken over two renders at 256 spp."""
    reference = render_passes(veach({"type": "merl", "filename": str(merl_table), "sampling": "phong", **PHONG}, "mis"),
                              spp=1024, spp_per_pass=512, seed=10**6, progress=False)
    errors = {}
    for sampling in ("uniform", "phong"):
        bsdf = {"type": "merl", "filename": str(merl_table), "sampling": sampling}
        if sampling == "phong":
            bsdf.update(PHONG)
        scene = veach(bsdf, "bsdf")
        squared = []
        for seed in (1, 2):
            image = render(scene, spp=256, seed=seed)
            assert np.all(np.isfinite(image))
            squared.append(metrics.rmse(reference, image, plates_mask) ** 2)
        errors[sampling] = float(np.sqrt(np.mean(squared)))
    assert errors["phong"] < 0.85 * errors["uniform"], errors


# ---------------------------------------------------------------------------------------------
# Kitchen


def test_override_xml_replaces_only_the_named_bsdfs():
    from nbrdf_tools.common.scenes.kitchen import bsdf_ids, override_xml

    text = """<scene version="3.0.0">
      <bsdf type="twosided" id="A"><bsdf type="diffuse"/></bsdf>
      <bsdf type="roughconductor" id="B"/>
      <bsdf type="bumpmap"><texture type="bitmap" name="x"/>
        <bsdf type="twosided" id="C"><bsdf type="diffuse"/></bsdf></bsdf>
      <bsdf type="diffuse" id="D"/>
      <shape type="sphere"><ref id="A"/></shape>
    </scene>"""
    new = override_xml(text, {"A": {"type": "nbrdf", "filename": "a.json"}, "B": {"type": "merl", "filename": "b.binary"},
                              "C": {"type": "nbrdf", "filename": "c.json", "sampling": "cosine"}})
    assert bsdf_ids(new) == {"A": "twosided", "B": "merl", "C": "twosided", "D": "diffuse"}
    assert new.count('type="nbrdf"') == 2 and 'value="cosine"' in new and 'type="bumpmap"' in new
    assert '<ref id="A"' in new
    with pytest.raises(KeyError, match="Nope"):
        override_xml(text, {"Nope": {"type": "diffuse"}})


def test_kitchen_loads_and_renders_with_nbrdf_and_merl(llvm_variant, shared, network_file, merl_table):
    """The kitchen with the described materials replaced, alternately by an NBRDF and a MERL
    table (one load and one kernel compile: the scene is large), renders without NaN or Inf."""
    from nbrdf_tools.common.scenes.kitchen import bsdf_ids, kitchen_path, load_description, load_kitchen, override_xml

    path = kitchen_path(shared / "scenes" / "kitchen")
    overrides = load_description()["overrides"]
    assert len(overrides) >= 8
    original = bsdf_ids(path.read_text())
    assert set(overrides) <= set(original)
    ours = [{"type": "nbrdf", "filename": str(network_file)},
            {"type": "merl", "filename": str(merl_table), "sampling": "phong", **PHONG}]
    replaced = {bsdf_id: ours[i % 2] for i, bsdf_id in enumerate(overrides)}
    rewritten = bsdf_ids(override_xml(path.read_text(), replaced))
    untouched_ids = set(original) - set(overrides)
    assert {k: rewritten[k] for k in untouched_ids} == {k: original[k] for k in untouched_ids}
    for bsdf_id in overrides:
        assert rewritten[bsdf_id] == ("twosided" if original[bsdf_id] == "twosided" else replaced[bsdf_id]["type"])
    scene = load_kitchen(replaced, scene=path, resx=KITCHEN_SIZE[0], resy=KITCHEN_SIZE[1], max_depth=4)
    used = {s.bsdf().id(): str(s.bsdf()) for s in scene.shapes() if s.bsdf() is not None}
    text = "".join(used.values())
    assert "NbrdfBSDF[" in text and "MerlBSDF[" in text
    # (Mitsuba merges shapes whose BSDFs are equal, so not every replaced id is left in the scene.)
    for bsdf_id in set(used) & set(overrides):  # replaced, in twosided where the original was
        plugin = "NbrdfBSDF" if replaced[bsdf_id]["type"] == "nbrdf" else "MerlBSDF"
        assert plugin in used[bsdf_id], bsdf_id
        assert used[bsdf_id].startswith("TwoSided") == (original[bsdf_id] == "twosided"), bsdf_id
    untouched = [k for k in used if k not in overrides]
    assert untouched and not any("NbrdfBSDF" in used[k] or "MerlBSDF" in used[k] for k in untouched)
    image = render(scene, spp=2, seed=1)
    assert image.shape == (KITCHEN_SIZE[1], KITCHEN_SIZE[0], 3)
    assert np.all(np.isfinite(image)), "NaN or Inf in the kitchen"
    assert image.mean() > 0


# ---------------------------------------------------------------------------------------------
# Metrics and the cache


def test_metrics_on_known_images():
    reference = np.ones((4, 5, 3))
    image = reference.copy()
    image[0, 0] = 3.0
    mask = np.zeros((4, 5), bool)
    mask[0, :2] = True
    assert metrics.mae(reference, image) == pytest.approx(2.0 / 20)
    assert metrics.rmse(reference, image) == pytest.approx(np.sqrt(4.0 / 20))
    assert metrics.rmse(reference, image, mask) == pytest.approx(np.sqrt(2.0))
    assert metrics.mape(reference, image, mask) == pytest.approx(0.5 * 2.0 / 1.01)
    assert metrics.relmse(reference, image) == pytest.approx(3 * 4.0 / 1.01 / 60)
    assert metrics.relative_rmse(reference, image) == pytest.approx(np.sqrt(4.0 / 20))
    assert metrics.psnr_peak1(reference, reference) == np.inf
    assert metrics.psnr_peak1(reference, image) == pytest.approx(20 * np.log10(1 / np.sqrt(0.2)))
    # Two definitions, two names: the peak is 1, or the reference's maximum.
    assert metrics.psnr_peak_ref(2 * reference, 2 * image) == pytest.approx(20 * np.log10(2 / (2 * np.sqrt(0.2))))
    assert metrics.psnr_peak1(2 * reference, 2 * image) == pytest.approx(20 * np.log10(1 / (2 * np.sqrt(0.2))))
    assert metrics.firefly_count(reference, image * 20) == 20
    with pytest.raises(ValueError):
        metrics.rmse(reference, image[:2])


def test_ssim_and_flip_on_images_with_known_answers():
    """SSIM of two flat images is the luminance term (2ab + C1) / (a^2 + b^2 + C1) of their
    tone-mapped values (no variance, no structure); HDR-FLIP is 0 for equal images and grows
    with the difference."""
    a, b = 0.5, 0.3
    flat_a = np.full((32, 32, 3), a ** 2.2)
    flat_b = np.full((32, 32, 3), b ** 2.2)
    c1 = 0.01 ** 2
    assert metrics.ssim(flat_a, flat_b) == pytest.approx((2 * a * b + c1) / (a * a + b * b + c1), rel=1e-6)
    assert metrics.ssim(flat_a, flat_a) == pytest.approx(1.0)
    rng = np.random.default_rng(0)
    hdr = rng.uniform(0.0, 4.0, (48, 64, 3))
    assert metrics.flip_hdr(hdr, hdr) == 0.0
    errors = [metrics.flip_hdr(hdr, hdr * (1 + k) + 0.1 * k) for k in (0.05, 0.3, 1.0)]
    assert 0 < errors[0] < errors[1] < errors[2] < 1, errors


def test_ground_truth_cache_rerenders_when_inputs_change(llvm_variant, tmp_path):
    from nbrdf_tools.common.ground_truth import RenderCache

    table = tmp_path / "table.binary"
    table.write_bytes(b"one")
    calls = []

    def make():
        calls.append(1)
        return np.full((3, 4, 3), float(len(calls)))

    cache = RenderCache(tmp_path / "cache")
    settings = {"spp": 64, "resolution": [4, 3], "integrator": "mis"}
    first = cache.get("gt", {"scene": "x"}, [table], settings, make)
    again = cache.get("gt", {"scene": "x"}, [table], settings, make)
    assert len(calls) == 1 and np.array_equal(first, again)
    sidecar = json.loads((tmp_path / "cache" / "gt.json").read_text())
    assert sidecar["settings"]["spp"] == 64 and str(table) in sidecar["files"] and "code_version" in sidecar
    cache.get("gt", {"scene": "x"}, [table], {**settings, "spp": 128}, make)  # settings changed
    table.write_bytes(b"two")
    cache.get("gt", {"scene": "x"}, [table], {**settings, "spp": 128}, make)  # table changed
    cache.get("gt", {"scene": "y"}, [table], {**settings, "spp": 128}, make)  # scene changed
    assert len(calls) == 4


# ---------------------------------------------------------------------------------------------
# The scripts' --quick runs (CI)


def _cli_or_skip():
    from conftest import _cli

    cli = _cli()
    if cli is None:
        pytest.skip("the nbrdf CLI is not built (target/release/nbrdf)")
    return cli


def _tiny_latent_models(cli, tmp_path):
    """An autoencoder and a predictor trained for a few steps on five random networks with Phong
    labels: enough to exercise the phong-predicted strategy, not to predict anything well."""
    folder = tmp_path / "nbrdfs"
    folder.mkdir()
    for k, name in enumerate("abcde"):
        write_network(folder / f"{name}.nbrdf.json", random_layers(seed=k), name=name,
                      sampling={"model": "blinn-phong", "exponent": 10.0 * (k + 1), "specular_weight": 0.1 * (k + 1),
                                "source": "fit"})
    ae, predictor = tmp_path / "ae.json", tmp_path / "predictor.json"
    for command in (["ae", "train", "--nbrdfs", folder, "-o", ae, "--epochs", "3", "--warmup", "2", "--quiet"],
                    ["predictor", "train", "--ae", ae, "--nbrdfs", folder, "-o", predictor, "--iterations", "50"]):
        done = subprocess.run([str(cli), *map(str, command)], capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
    return ae, predictor


def test_convergence_quick_json(tmp_path):
    cli = _cli_or_skip()
    from conftest import SHARED

    help_text = subprocess.run([str(cli), "--help"], capture_output=True, text=True).stdout
    can_train = " train " in help_text
    if not can_train and not SHARED.is_dir():
        pytest.skip("the CLI cannot train NBRDFs and ../shared (the authors' networks) is absent")
    ae, predictor = _tiny_latent_models(cli, tmp_path)
    out = tmp_path / "result.json"
    # A fresh clone: no shared data; the MERL material is synthesised and trained by the CLI.
    env = {**os.environ, "NBRDF_SHARED": str(tmp_path / "nonexistent")} if can_train else None
    run = subprocess.run([sys.executable, "-m", "nbrdf_tools.pages.scenes", "--scene", "veach", "--quick",
                          "--json", str(out), "--out", str(tmp_path / "out"), "--cli", str(cli), "--no-progress",
                          "--seeds", "2", "--strategies",
                          "uniform,cosine,phong-fit,two-lobe-fit,phong-predicted,tabulated,default",
                          "--ae", str(ae), "--predictor", str(predictor)],
                         capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(out.read_text())
    rows = report["results"]
    assert rows
    for row in rows:
        assert {"scene", "material", "strategy", "spp", "seconds", "mae", "rmse", "relmse", "mape",
                "psnr_peak1"} <= set(row)
        assert row["scene"] == "veach"
        assert row["strategy"] in ("uniform", "cosine", "phong-fit", "two-lobe-fit", "tabulated", "phong-predicted",
                                   "default", "measured")
        assert row["seconds"] > 0 and np.isfinite(row["rmse"])
    assert {r["strategy"] for r in rows} >= {"uniform", "cosine", "phong-predicted", "default"}
    if " fit-phong " in help_text:
        assert {"phong-fit", "two-lobe-fit"} <= {r["strategy"] for r in rows}
        # `default` is the plugin without `sampling`: the file's stored default, one of those
        # fit-phong chooses from; its ratio to the single lobe is reported.
        summary = report["equal_time"][0]
        assert summary["default_sampling"] in ("cosine", "two_lobe", "tabulated")
        assert set(summary["vs_phong_fit"]) >= {"default", "tabulated", "two-lobe-fit"}
        assert summary["vs_phong_fit"]["default"] == summary["rmse"]["default"] / summary["rmse"]["phong-fit"]
        exponents, weights = report["equal_time"][0]["two_lobe_exponents"], report["equal_time"][0]["two_lobe_weights"]
        assert len(exponents) == 2 and min(exponents) >= 0 and min(weights) >= 0 and sum(weights) <= 1 + 1e-6
    assert sorted({r["spp"] for r in rows}) == [1, 2, 4]
    lobe = report["equal_time"][0]
    assert lobe["predicted_exponent"] >= 0 and 0 <= lobe["predicted_specular_weight"] <= 1
    assert report["representation"] and report["equal_time"]
    for rep in report["representation"]:
        assert 0 < rep["ssim"] <= 1 and 0 <= rep["flip_hdr"] < 1 and rep["relmse"] >= 0
    folder = tmp_path / "out" / "veach"
    assert (folder / "convergence.csv").is_file() and (folder / "plots" / "veach-overview.png").is_file()
    assert (folder / "plots" / "veach-overview.pdf").is_file()
    assert {r["seed"] for r in rows} == {0, 1}  # --seeds 2
    assert list((folder / "renders").rglob("*.exr"))
    # --out holds the caches too.
    assert list((tmp_path / "out" / "materials").glob("*.nbrdf.json"))
    assert list((tmp_path / "out" / "references").glob("*.exr"))


def test_convergence_rgl_path_against_measured(tmp_path, shared):
    """An RGL measurement given as a path outside the shared data: every NBRDF strategy is
    compared with Mitsuba's measured at equal time over several seeds."""
    cli = _cli_or_skip()
    mine = tmp_path / "my_paint.bsdf"
    mine.write_bytes((shared / "data" / "rgl" / "cc_ibiza_sunset_rgb.bsdf").read_bytes())
    out = tmp_path / "result.json"
    run = subprocess.run([sys.executable, "-m", "nbrdf_tools.pages.scenes", "--scene", "veach", "--quick",
                          "--materials", "", "--rgl", str(mine), "--seeds", "3", "--json", str(out),
                          "--out", str(tmp_path / "out"), "--cli", str(cli), "--no-progress"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(out.read_text())
    assert {r["material"] for r in report["results"]} == {"my_paint"}
    assert {r["strategy"] for r in report["results"]} == {"uniform", "cosine", "phong-fit", "two-lobe-fit",
                                                          "tabulated", "measured"}
    assert {r["seed"] for r in report["results"]} == {0, 1, 2}
    summary = report["equal_time"][0]
    assert summary["statistic"] == "median over seeds" and summary["seeds"] == 3
    assert set(summary["vs_measured"]) == {"uniform", "cosine", "phong-fit", "two-lobe-fit", "tabulated"}
    assert summary["best_vs_measured"] == min(summary["vs_measured"].values())
    assert summary["vs_measured"][summary["best_nbrdf"]] == summary["best_vs_measured"]
    text = (tmp_path / "out" / "veach" / "summary.md").read_text()
    assert "two-lobe-fit / measured" in text and f"| {summary['best_nbrdf']} " in text
    # The plates were also timed in diffuse, in the same interleaved runs (3 seeds per level).
    floor = summary["cost_floor"]
    top = max(r["spp"] for r in report["results"])
    assert floor["spp"] == top and set(floor["per_sample"]) == set(summary["vs_measured"])
    assert sorted((t["spp"], t["seed"]) for t in report["timings"]) == sorted(
        (r["spp"], r["seed"]) for r in report["results"] if r["strategy"] == "measured")
    assert 0 < floor["floor_time"] < 5 and all(b > 0 for b in floor["bound"].values())
    assert "`diffuse` time" in text


def test_convergence_kitchen_quick_with_the_new_strategies(tmp_path, shared):
    """The kitchen (two of its overrides, quick settings) honours --strategies: two-lobe-fit,
    tabulated and the stored default are rendered beside phong-fit and compared with it at equal
    time over seeds; measured is skipped with a note; the kitchen's checks still run."""
    cli = _cli_or_skip()
    help_text = subprocess.run([str(cli), "--help"], capture_output=True, text=True).stdout
    description = json.loads((REPO / "scenes" / "kitchen_materials.json").read_text())
    description["overrides"] = {"SteelPotBSDF": "aluminium", "SmallWorktopBSDF": "gray-plastic"}
    materials = tmp_path / "kitchen_materials.json"
    materials.write_text(json.dumps(description))
    out = tmp_path / "result.json"
    run = subprocess.run([sys.executable, "-m", "nbrdf_tools.pages.scenes", "--scene", "kitchen", "--quick",
                          "--kitchen", str(shared / "scenes" / "kitchen"), "--kitchen-materials", str(materials),
                          "--seeds", "2", "--strategies", "cosine,phong-fit,two-lobe-fit,tabulated,default,measured",
                          "--json", str(out), "--out", str(tmp_path / "out"), "--cli", str(cli), "--no-progress"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(out.read_text())
    rows = report["results"]
    expected = {"cosine", "tabulated", "default"}
    if " fit-phong " in help_text:
        expected |= {"phong-fit", "two-lobe-fit"}
    assert {r["strategy"] for r in rows} == expected
    assert {r["material"] for r in rows} == {"2 overrides"} and {r["seed"] for r in rows} == {0, 1}
    assert all(r["seconds"] > 0 and np.isfinite(r["rmse"]) and r["nonfinite"] == 0 for r in rows)
    assert any("measured skipped" in note for note in report["notes"])
    summary = report["equal_time"][0]
    assert summary["statistic"] == "median over seeds" and summary["seeds"] == 2
    assert set(summary["default_samplings"]) == {"aluminium", "gray-plastic"}
    if " fit-phong " in help_text:
        assert set(summary["default_samplings"].values()) <= {"cosine", "two_lobe", "tabulated"}
        assert sum(int(part.rsplit("x", 1)[1]) for part in summary["default_sampling"].split(", ")) == 2
        assert set(summary["vs_phong_fit"]) == expected - {"phong-fit"}
        assert summary["vs_phong_fit"]["default"] == summary["rmse"]["default"] / summary["rmse"]["phong-fit"]
        assert "default / phong-fit" in (tmp_path / "out" / "kitchen" / "summary.md").read_text()
    checks = report["kitchen"]
    assert checks["nonfinite_pixels"]["all_strategy_renders"] == 0 and checks["pixels"] == 48 * 27


def test_equal_time_summary_is_robust_to_one_bad_seed():
    """Median over seeds: one seed with a firefly (RMSE x100) moves the pooled RMSE, not the
    median; the ratio to measured and the best strategy follow the median."""
    from nbrdf_tools.pages.scenes import equal_time_summary

    rows = []
    for strategy, base in (("cosine", 1.0), ("phong-fit", 0.5), ("measured", 0.6)):
        for spp, seconds in ((1, 0.1), (2, 0.2), (4, 0.4)):
            for seed in range(5):
                rmse = base / np.sqrt(spp) * (100.0 if (strategy == "phong-fit" and seed == 3) else 1.0 + 0.01 * seed)
                rows.append({"strategy": strategy, "spp": spp, "seed": seed, "seconds": seconds, "rmse": rmse})
    summary = equal_time_summary(rows)
    assert summary["seconds"] == pytest.approx(0.4) and summary["seeds"] == 5
    assert summary["rmse"]["phong-fit"] == pytest.approx(0.5 * 1.02 / 2)  # median of 1.00, 1.01, 1.02, 100, 1.04
    pooled = np.sqrt(np.mean(np.array([1.0, 1.01, 1.02, 100.0, 1.04]) ** 2)) * 0.5 / 2
    assert summary["rmse_pooled"]["phong-fit"] == pytest.approx(pooled)
    assert summary["vs_measured"]["phong-fit"] == pytest.approx(0.5 / 0.6)
    assert summary["best_nbrdf"] == "phong-fit" and "measured" not in summary["vs_measured"]


def test_cost_floor_bounds_the_equal_time_ratio_by_the_scene_s_share_of_the_time():
    """The cost floor from rows built on closed forms: at the highest common spp, per-sample
    ratio = RMSE / measured's RMSE, time ratio = seconds / measured's, bound = per-sample ratio x
    sqrt(floor seconds / measured's); medians over seeds; strategies that are not NBRDF sampling
    (measured) have no entry; spp beyond what every strategy reached is ignored."""
    from nbrdf_tools.pages.scenes import cost_floor

    rows, timings = [], []
    base = {"cosine": (2.0, 0.7), "tabulated": (0.45, 0.75), "measured": (0.5, 1.0)}
    for spp in (1, 2, 4):
        for seed in range(3):
            jitter = 1.0 + 0.1 * (seed - 1)  # median at seed 1
            for strategy, (rmse, seconds) in base.items():
                rows.append({"strategy": strategy, "spp": spp, "seed": seed,
                             "rmse": rmse / math.sqrt(spp) * jitter, "seconds": seconds * spp * jitter})
            timings.append({"strategy": "diffuse", "spp": spp, "seed": seed, "seconds": 0.64 * spp * jitter})
    rows.append({"strategy": "cosine", "spp": 8, "seed": 0, "rmse": 0.1, "seconds": 5.0})
    floor = cost_floor(rows, timings)
    assert floor["spp"] == 4 and floor["bsdf"] == "diffuse"
    assert floor["floor_time"] == pytest.approx(0.64)
    assert floor["per_sample"] == pytest.approx({"cosine": 4.0, "tabulated": 0.9})
    assert floor["time"] == pytest.approx({"cosine": 0.7, "tabulated": 0.75})
    assert floor["bound"] == pytest.approx({"cosine": 4.0 * 0.8, "tabulated": 0.9 * 0.8})
    assert cost_floor(rows, []) is None
    assert cost_floor([r for r in rows if r["strategy"] != "measured"], timings) is None
    noiseless = [{**r, "rmse": 0.0} if r["strategy"] == "measured" else r for r in rows]
    assert cost_floor(noiseless, timings) is None


def test_convergence_reports_missing_inputs_before_any_work(tmp_path):
    """Without shared data, an RGL material named from it, a missing .bsdf path or the kitchen
    stop the run at once, naming what is missing; nothing is written."""
    cli = _cli_or_skip()
    env = {**os.environ, "NBRDF_SHARED": str(tmp_path / "nonexistent")}
    out = tmp_path / "out"
    for extra, expected in ((["--rgl", "cc_ibiza_sunset_rgb"], "cc_ibiza_sunset_rgb.bsdf"),
                            (["--rgl", str(tmp_path / "mine.bsdf")], str(tmp_path / "mine.bsdf")),
                            (["--scene", "kitchen"], "kitchen scene")):
        run = subprocess.run([sys.executable, "-m", "nbrdf_tools.pages.scenes", "--quick", "--out", str(out),
                              "--cli", str(cli), "--no-progress", *extra],
                             capture_output=True, text=True, timeout=120, env=env)
        assert run.returncode == 2, run.stderr[-2000:]
        assert "missing" in run.stderr and expected in run.stderr, run.stderr[-2000:]
    assert not out.exists()


def test_rgl_materials_are_accepted_as_paths(tmp_path):
    from nbrdf_tools.common.materials import Artefacts

    mine = tmp_path / "my_material.bsdf"
    mine.write_bytes(b"")
    artefacts = Artefacts(tmp_path / "out", tmp_path / "no-cli", shared=tmp_path / "nonexistent")
    assert artefacts.is_rgl(str(mine)) and artefacts.rgl_file(str(mine)) == mine
    assert artefacts.is_rgl("rgl:cc_ibiza_sunset_rgb") and not artefacts.is_rgl("gold-metallic-paint")
    shared_file = tmp_path / "nonexistent" / "data" / "rgl" / "cc_ibiza_sunset_rgb.bsdf"
    assert artefacts.rgl_file("cc_ibiza_sunset_rgb") == shared_file
    assert "nbrdf CLI" in artefacts.missing([str(mine)])[0]


def test_bench_rays_quick_json(tmp_path):
    """The speed table's run: every BSDF of both modes with Mrays/s, memory and ratios; the
    network's sampling strategies; Mitsuba's measured BSDF on the shared RGL file (or the note
    naming it when the shared data is absent)."""
    cli = _cli_or_skip()
    from conftest import SHARED

    rgl = SHARED / "data" / "rgl" / "paper_white_rgb.bsdf"
    out = tmp_path / "bench.json"
    run = subprocess.run([sys.executable, "-m", "nbrdf_tools.bench.rays", "--quick", "--no-progress",
                          "--json", str(out), "--out", str(tmp_path / "bench"), "--cli", str(cli)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(out.read_text())
    assert report["scene"] == "veach" and report["mode"] == "default" and report["variant"] == "llvm_ad_rgb"
    assert [mode_run["mode"] for mode_run in report["runs"]] == ["default", "wavefront"]
    network = tmp_path / "bench" / "gold-metallic-paint.nbrdf.json"
    layers = json.loads(network.read_text())["layers"]
    parameters = sum(len(layer["weights"]) + len(layer["bias"]) for layer in layers)
    assert parameters == sum(layer["inputs"] * layer["outputs"] + layer["outputs"] for layer in layers)
    assert "second_lobe" in json.loads(network.read_text())["sampling"]  # fit-phong --lobes 2
    names = ("nbrdf", "nbrdf-opaque", "nbrdf-cosine", "nbrdf-phong", "nbrdf-two_lobe", "nbrdf-tabulated", "merl",
             "roughconductor", "roughplastic", "principled", "diffuse")
    for mode_run in report["runs"]:
        bsdfs = mode_run["bsdfs"]
        assert mode_run["scene"] == "veach" and mode_run["variant"] == "llvm_ad_rgb"
        for name in names:
            assert bsdfs[name]["mrays_per_s"] > 0 and bsdfs[name]["seconds"] > 0, name
            assert bsdfs[name]["memory_bytes"] > 0, name
            ratio = bsdfs[name]["ratio_vs_roughconductor"]
            assert ratio == pytest.approx(bsdfs[name]["mrays_per_s"] / bsdfs["roughconductor"]["mrays_per_s"])
        for name in ("nbrdf", "nbrdf-opaque", "nbrdf-two_lobe"):
            assert bsdfs[name]["memory_bytes"] == 4 * parameters and bsdfs[name]["file_bytes"] == network.stat().st_size
        # The table built at load: per bin of the 16 rows of theta x phi bins its mass and its
        # alias-table entry (keep probability, alias index), 32 bits each.
        from nbrdf_mitsuba import _native

        table = _native.Sampler("tabulated", material=_native.Material(str(network)))
        rows, nt, np_ = table.rows, table.theta_bins, table.phi_bins
        want = 4 * 3 * rows * nt * np_
        assert bsdfs["nbrdf-tabulated"]["sampler_bytes"] == want
        assert "sampler_bytes" not in bsdfs["nbrdf-phong"] and "sampler_bytes" not in bsdfs["roughconductor"]
        assert bsdfs["merl"]["memory_bytes"] == 34_992_012  # 12-byte header + 3 x 90x90x180 float64
        # diffuse: one RGB reflectance; roughconductor: alpha, eta, k.
        assert bsdfs["diffuse"]["memory_bytes"] == 12 and bsdfs["roughconductor"]["memory_bytes"] == 12
        if rgl.is_file():
            assert bsdfs["measured"]["memory_bytes"] == rgl.stat().st_size
            assert bsdfs["measured"]["ratio_vs_measured"] == 1.0
            assert bsdfs["nbrdf"]["ratio_vs_measured"] == pytest.approx(
                bsdfs["nbrdf"]["mrays_per_s"] / bsdfs["measured"]["mrays_per_s"])
    if rgl.is_file():
        assert report["measured"] == str(rgl) and "vs measured" in run.stdout
    else:
        assert "measured" not in report["bsdfs"] and f"measured skipped: {rgl} is missing" in run.stdout
    assert {"nbrdf-rust", "merl"} <= set(report["runs"][1]["bsdfs"])
    chart = tmp_path / "bench" / "rays_per_second.png"
    assert chart.stat().st_size > 1000 and chart.with_suffix(".pdf").is_file()


def test_bench_rays_runs_in_scalar_rgb(tmp_path):
    """docs/mitsuba.md's scalar rows: one mode, the rust backend, the chosen BSDFs and the reference."""
    cli = _cli_or_skip()
    out = tmp_path / "scalar.json"
    run = subprocess.run([sys.executable, "-m", "nbrdf_tools.bench.rays", "--variant", "scalar_rgb", "--bsdfs", "nbrdf",
                          "--width", "48", "--spp", "1", "--repeats", "1", "--no-progress", "--json", str(out),
                          "--out", str(tmp_path / "bench"), "--cli", str(cli)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(out.read_text())
    assert (report["variant"], report["mode"], report["resolution"]) == ("scalar_rgb", "scalar", [48, 32])
    assert set(report["bsdfs"]) == {"nbrdf", "roughconductor"}
    assert all(figures["mrays_per_s"] > 0 for figures in report["bsdfs"].values())
    assert "once per direction" in run.stdout + run.stderr  # the plugin's note on scalar variants


def test_command_errors_carry_the_commands_stderr(tmp_path):
    """The scripts' one CLI wrapper: a failing command raises with its exit status and stderr."""
    from nbrdf_tools.common import cli

    exe = _cli_or_skip()
    with pytest.raises(cli.CommandError) as failure:
        cli.nbrdf(exe, "synth", "--model", "sgd", "--material", "unobtainium", "-o", tmp_path / "x.binary")
    assert failure.value.returncode != 0 and failure.value.stderr.strip()
    assert failure.value.stderr.strip() in str(failure.value) and "unobtainium" in str(failure.value)
    with pytest.raises(FileNotFoundError, match="nbrdf CLI"):
        cli.nbrdf(tmp_path / "no-cli", "--help")
