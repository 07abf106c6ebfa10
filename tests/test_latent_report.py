"""The latent-space report's own pieces (nbrdf_tools.pages.latent, nbrdf_tools.common.network) and the
CLI commands it drives
that have no scene: ``nbrdf tabulate`` (checked against a NumPy evaluation of the network at the
cell centres of docs/design.md section 3), the distillation of the authors' networks into the common
initialisation, ``predictor eval``, and the smoothness measures of the interpolation figure."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from nbrdf_testing import (CELLS, SCALE, bsdf_eval, cell_centre_angles, f32, from_angles, nbrdf_reference,
                           normalize, random_layers, random_pairs, read_merl, write_network)
from nbrdf_tools.pages import latent as latent_report
from nbrdf_tools.common import network


def _cli_or_skip() -> Path:
    from conftest import _cli

    cli = _cli()
    if cli is None:
        pytest.skip("the nbrdf CLI is not built (target/release/nbrdf)")
    return cli


def _nbrdf(cli: Path, *command) -> str:
    """Runs the CLI, fails the test with its stderr unless it succeeds; returns its stdout."""
    done = subprocess.run([str(cli), *map(str, command)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout


def _labelled_networks(folder: Path, names: str, seed: int, lobe) -> None:
    """Writes a random network per name into `folder` (seeds `seed`, `seed + 1`, ...), each with
    the fitted Blinn-Phong sampling `lobe(k) = (exponent, specular_weight)` of the k-th name."""
    folder.mkdir(exist_ok=True)
    for k, name in enumerate(names):
        exponent, weight = lobe(k)
        write_network(folder / f"{name}.nbrdf.json", random_layers(seed=seed + k), name=name,
                      sampling={"model": "blinn-phong", "exponent": exponent, "specular_weight": weight,
                                "source": "fit"})


def test_detour_is_one_for_an_even_path_and_grows_with_a_swing():
    assert latent_report.detour(np.linspace(0.2, 0.8, 7)) == pytest.approx(1.0)
    # Out to 1 and back to 0.8: path 0.8 + 0.2 + ... over a straight distance of 0.6.
    assert latent_report.detour(np.array([0.2, 1.0, 0.8])) == pytest.approx((0.8 + 0.2) / 0.6)
    frames = np.zeros((3, 4, 4, 3))
    frames[1] += 0.5  # a bright midpoint between two equal ends: a detour, however small the ends differ
    frames[2] += 1e-3
    assert latent_report.detour(frames) > 100


def test_appearance_tells_a_sharp_highlight_from_a_broad_one_and_reads_colour():
    inp, cos = latent_report.sphere_inputs(64, np.radians(45.0))
    cos_h = inp[..., 2]

    def lobe(n):
        return (np.where(cos > 0, cos_h ** n, 0.0) * cos)[..., None] * np.array([1.0, 1.0, 1.0])

    widths = [latent_report.appearance(lobe(n))["highlight"] for n in (2000, 200, 20, 2)]
    assert widths == sorted(widths) and widths[0] < 0.01 and widths[-1] > 0.1, widths
    # Measured above the diffuse floor: a sharp spot on a bright base is still narrow.
    assert latent_report.appearance(lobe(2000) + 0.2 * lobe(0))["highlight"] < 0.02
    broad = (np.where(cos > 0, 0.3, 0.0) * cos)[..., None] * np.array([0.6, 0.3, 0.1])
    b = latent_report.appearance(broad)
    assert b["highlight"] > widths[-1]
    assert b["chromaticity"] == pytest.approx([0.6, 0.3, 0.1])
    assert latent_report.appearance(np.zeros((8, 8, 3)))["luminance"] == 0.0


def test_numpy_network_matches_the_plugin(variant, tmp_path):
    """nbrdf_tools.common.network (the scripts' NumPy forward pass) against its Rust twin through the
    `nbrdf` BSDF, and against the tests' float64 oracle written from the paper."""
    import mitsuba as mi

    layers = random_layers(seed=4)
    path = write_network(tmp_path / "n.nbrdf.json", layers)
    view, light = random_pairs(300 if variant.startswith("llvm") else 60, seed=5)
    view, light = f32(view), f32(light)
    # (float32 rounding leaves the directions unit to 1e-7; the oracle normalises them)
    unit_view, unit_light = normalize(view), normalize(light)
    ours = network.evaluate(network.read_layers(path), unit_view.T, unit_light.T).T * unit_light[2]
    oracle = nbrdf_reference([(w.astype(np.float64), b.astype(np.float64)) for w, b in layers], light, view)
    assert np.allclose(ours, oracle, rtol=1e-9, atol=1e-12)
    plugin = bsdf_eval(mi.load_dict({"type": "nbrdf", "filename": str(path)}), view, light)
    assert np.allclose(ours, plugin, rtol=2e-4, atol=1e-6), np.abs(ours - plugin).max()


def test_sphere_images_and_weight_interpolation(tmp_path):
    layers = random_layers(seed=4)
    path = write_network(tmp_path / "n.nbrdf.json", layers)
    a = latent_report.render_network(path)
    assert a.shape == (64, 64, 3) and a.max() > 0
    assert np.all(a[0, 0] == 0) and np.all(a[-1, -1] == 0)  # corners: off the sphere
    # Interpolating a network with itself changes nothing.
    mid = network.lerp(network.read_layers(path), network.read_layers(path), 0.4)
    assert np.allclose(latent_report.render_layers(mid), a)


def test_tabulate_holds_the_network_at_cell_centres(tmp_path):
    cli = _cli_or_skip()
    layers = random_layers(seed=2)
    net = write_network(tmp_path / "n.nbrdf.json", layers)
    table = tmp_path / "n.binary"
    subprocess.run([str(cli), "tabulate", str(net), "-o", str(table)], check=True, capture_output=True)
    stored = read_merl(table).reshape(3, CELLS)
    rng = np.random.default_rng(0)
    cells = rng.integers(0, CELLS, 4000)
    i_th, rest = np.divmod(cells, 90 * 180)
    i_td, i_pd = np.divmod(rest, 180)
    theta_h, theta_d, phi_d = cell_centre_angles(i_th, i_td, i_pd)
    light, view = from_angles(theta_h, np.zeros_like(theta_h), theta_d, phi_d)
    above = (light[2] > 0) & (view[2] > 0)
    got = stored[:, cells]
    assert np.all(got[:, ~above] < 0), "cells with a direction below the horizon must be invalid"
    want = nbrdf_reference(layers, light, view)[:, above] / light[2][above] / SCALE[:, None]
    assert np.allclose(got[:, above], want, rtol=1e-4, atol=1e-6 / SCALE.min())


def test_authors_networks_distil_into_the_common_initialisation(tmp_path, shared):
    cli = _cli_or_skip()
    out = tmp_path / "nbrdfs"
    latent_report.train_missing(cli, out, 20_000, source="authors", only=["pink-fabric"])
    net = json.loads((out / "pink-fabric.nbrdf.json").read_text())
    assert net["name"] == "pink-fabric" and net["sampling"]["source"] == "fit"
    assert not list((out / "tables").iterdir()), "the 35 MB tables are removed"
    # The distilled network reproduces the authors' network on the sphere of the AE's loss.
    keras = tmp_path / "authors.nbrdf.json"
    from nbrdf_mitsuba.import_keras import convert

    convert(shared / "data" / "reference-nbrdf" / "merl" / "pink-fabric.h5", keras)
    a, b = latent_report.render_network(keras), latent_report.render_network(out / "pink-fabric.nbrdf.json")
    assert np.abs(a - b).mean() < 0.1 * a.mean()


def test_predictor_eval_scores_fitted_and_predicted_lobes(tmp_path):
    cli = _cli_or_skip()
    folder = tmp_path / "nbrdfs"
    _labelled_networks(folder, "abcde", 10, lambda k: (10.0 * (k + 1), 0.2))
    ae, predictor = tmp_path / "ae.json", tmp_path / "p.json"
    for command in (["ae", "train", "--nbrdfs", folder, "-o", ae, "--epochs", "3", "--warmup", "2", "--quiet"],
                    ["predictor", "train", "--ae", ae, "--nbrdfs", folder, "-o", predictor, "--iterations", "50"],
                    ):
        _nbrdf(cli, *command)
    assert json.loads(predictor.read_text())["provenance"]["loss"] == "variance"
    report = json.loads(_nbrdf(cli, "predictor", "eval", "--ae", ae, "--predictor", predictor, "--nbrdfs", folder))
    (row,) = report["test"]
    assert row["name"] == "c"
    for lobe in (row["fitted"], row["predicted"]):
        assert lobe["exponent"] >= 0 and 0 <= lobe["specular_weight"] <= 1 and lobe["relative_variance"] >= 0
    assert row["rmse_ratio"] == pytest.approx(np.sqrt(row["predicted"]["relative_variance"]
                                                      / row["fitted"]["relative_variance"]), rel=1e-6)
    assert report["rmse_ratio"]["materials"] == 1


def test_extra_networks_train_only_on_training_materials(tmp_path):
    cli = _cli_or_skip()
    folders = {}
    for source, offset in (("main", 20), ("extra", 40)):
        folders[source] = tmp_path / source
        _labelled_networks(folders[source], "abcde", offset, lambda k: (5.0 * (k + 1), 0.3))
    ae, predictor = tmp_path / "ae.json", tmp_path / "p.json"
    for command in (["ae", "train", "--nbrdfs", folders["main"], "--extra-nbrdfs", folders["extra"], "-o", ae,
                     "--epochs", "2", "--warmup", "1", "--quiet"],
                    ["predictor", "train", "--ae", ae, "--nbrdfs", folders["main"], "--extra-nbrdfs", folders["extra"],
                     "-o", predictor, "--iterations", "20", "--members", "2", "--loss", "labels"]):
        _nbrdf(cli, *command)
    model = json.loads(ae.read_text())
    assert model["split"]["test"] == ["c"] and model["provenance"]["extra_nbrdfs"] == str(folders["extra"])
    labels = [entry["name"] for entry in json.loads(predictor.read_text())["provenance"]["labels"]]
    # Both versions of every training material, never the test material.
    assert sorted(labels) == sorted(2 * ["a", "b", "d", "e"])
    assert len(json.loads(predictor.read_text())["ensemble"]) == 1


def test_lobe_loss_and_linear_predictor_from_the_cli(tmp_path):
    """`ae train --lobe-weight` reads each training material's fitted lobe and changes the
    codes (the lobe head pulls them); `predictor train --hidden 0 --weight-decay` gives a
    regularised linear predictor whose lobes are valid."""
    cli = _cli_or_skip()
    folder = tmp_path / "nbrdfs"
    _labelled_networks(folder, "abcde", 60, lambda k: (3.0 ** (k + 1), 0.1 * (k + 1)))

    def nbrdf(*command):
        return _nbrdf(cli, *command)

    codes = {}
    for weight in ("0", "0.5"):
        ae = tmp_path / f"ae-{weight}.json"
        nbrdf("ae", "train", "--nbrdfs", folder, "-o", ae, "--epochs", "4", "--warmup", "2", "--quiet",
              "--lobe-weight", weight)
        assert json.loads(ae.read_text())["provenance"]["lobe_weight"] == float(weight)
        codes[weight] = np.array(json.loads(nbrdf("ae", "encode", "--ae", ae, folder / "c.nbrdf.json")))
    assert codes["0"].shape == (32,) and np.all(np.isfinite(codes["0.5"]))
    assert np.abs(codes["0"] - codes["0.5"]).max() > 1e-4
    predictor = tmp_path / "p.json"
    nbrdf("predictor", "train", "--ae", tmp_path / "ae-0.5.json", "--nbrdfs", folder, "-o", predictor,
          "--iterations", "50", "--members", "2", "--hidden", "0", "--weight-decay", "0.01", "--code-only")
    provenance = json.loads(predictor.read_text())["provenance"]
    assert provenance["architecture"].startswith("32-2, linear") and provenance["weight_decay"] == pytest.approx(0.01)
    assert provenance["highlight_profile"] is False
    report = json.loads(nbrdf("predictor", "eval", "--ae", tmp_path / "ae-0.5.json", "--predictor", predictor,
                              "--nbrdfs", folder))
    (row,) = report["test"]
    assert row["predicted"]["exponent"] > 0 and 0 <= row["predicted"]["specular_weight"] <= 1


def test_seed_selection_keeps_the_best_refined_validation_autoencoder(tmp_path):
    """`ae train --seeds 2` trains seeds 0 and 1 and keeps the one whose refined codes
    reconstruct the validation materials best: the kept decoder is that seed's own, as trained
    alone; `ae eval --split validation` reconstructs exactly those held-out materials."""
    cli = _cli_or_skip()
    folder = tmp_path / "nbrdfs"
    folder.mkdir()
    for k, name in enumerate("abcdefghij"):
        write_network(folder / f"{name}.nbrdf.json", random_layers(seed=80 + k), name=name)

    def nbrdf(*command):
        return _nbrdf(cli, *command)

    common = ["--epochs", "3", "--warmup", "2", "--quiet", "--mixup", "8"]
    nbrdf("ae", "train", "--nbrdfs", folder, "-o", tmp_path / "best.json", "--seeds", "2", "--select-refine", "2",
          *common)
    best = json.loads((tmp_path / "best.json").read_text())
    assert best["provenance"]["mixup"] == 8
    candidates = best["provenance"]["selection"]["candidates"]
    assert [c["seed"] for c in candidates] == [0, 1]
    losses = [c["refined_validation_loss"] for c in candidates]
    assert all(np.isfinite(losses)) and losses[0] != losses[1]
    chosen = int(np.argmin(losses))
    for seed in (0, 1):
        nbrdf("ae", "train", "--nbrdfs", folder, "-o", tmp_path / f"seed{seed}.json", "--seed", seed, *common)
        alone = json.loads((tmp_path / f"seed{seed}.json").read_text())
        assert (alone["decoder"] == best["decoder"]) == (seed == chosen)
    report = json.loads(nbrdf("ae", "eval", "--ae", tmp_path / "best.json", "--nbrdfs", folder, "--split",
                              "validation", "--refine", "2", "--pca-tables", "nbrdf"))
    validation = best["split"]["validation"]
    assert validation and [r["name"] for r in report["materials"]] == validation
    assert not set(validation) & set(best["split"]["test"])


def test_default_predictor_reads_the_highlight_profile_and_cross_validates(tmp_path):
    """`predictor train` predicts from the code and the network's 27-value highlight profile
    (its inputs are 32 + 27 wide), `--cross-validate K` scores held-out training materials
    before training, and `predict-phong` stores a valid lobe from it."""
    cli = _cli_or_skip()
    folder = tmp_path / "nbrdfs"
    _labelled_networks(folder, "abcdefg", 120, lambda k: (4.0 ** (k + 1), 0.1 * (k + 1)))
    ae, predictor = tmp_path / "ae.json", tmp_path / "p.json"
    _nbrdf(cli, "ae", "train", "--nbrdfs", folder, "-o", ae, "--epochs", "3", "--warmup", "2", "--quiet")
    out = _nbrdf(cli, "predictor", "train", "--ae", ae, "--nbrdfs", folder, "-o", predictor, "--iterations", "50",
                 "--members", "2", "--cross-validate", "2")
    assert "2-fold cross-validation over the training split" in out
    model = json.loads(predictor.read_text())
    assert model["highlight_profile"] is True and len(model["code_mean"]) == 32 + 27
    assert model["provenance"]["architecture"].startswith("59-32-2, tanh hidden")
    cv = model["provenance"]["cross_validation"]
    train = json.loads(ae.read_text())["split"]["train"]
    rows = cv["materials_ratio"]
    assert sorted(r["name"] for r in rows) == sorted(train) and cv["materials"] == len(train)
    ratios = np.array([r["rmse_ratio"] for r in rows])
    assert np.all(np.isfinite(ratios)) and np.all(ratios > 0)
    assert cv["within_1_25"] == int((ratios <= 1.25).sum())
    assert cv["geometric_mean"] == pytest.approx(float(np.exp(np.log(ratios).mean())), rel=1e-9)
    assert cv["max"] == pytest.approx(ratios.max())
    one_fold = subprocess.run([str(cli), "predictor", "train", "--ae", str(ae), "--nbrdfs", str(folder), "-o",
                               str(tmp_path / "q.json"), "--cross-validate", "1"], capture_output=True, text=True)
    assert one_fold.returncode != 0 and "at least 2 folds" in one_fold.stderr
    test_name = json.loads(ae.read_text())["split"]["test"][0]
    dst = tmp_path / "predicted.nbrdf.json"
    _nbrdf(cli, "predict-phong", "--ae", ae, "--predictor", predictor, folder / f"{test_name}.nbrdf.json", "-o", dst)
    lobe = json.loads(dst.read_text())["sampling"]
    assert lobe["source"] == "predicted" and lobe["exponent"] > 0 and 0 <= lobe["specular_weight"] <= 1


def test_missing_networks_are_reported_before_any_work(tmp_path, capsys, monkeypatch):
    """Without networks and without --train-missing the report stops at once and says what to
    pass (it used to die inside `nbrdf ae train` with a swallowed error)."""
    cli = _cli_or_skip()
    out = tmp_path / "latent"
    assert latent_report.main(["--cli", str(cli), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "--train-missing" in err and str(out / "nbrdfs") in err
    assert not out.exists()
    assert latent_report.main(["--cli", str(tmp_path / "no-cli"), "--out", str(out)]) == 2
    assert "nbrdf CLI" in capsys.readouterr().err
    monkeypatch.setenv("NBRDF_SHARED", str(tmp_path / "nonexistent"))
    assert latent_report.main(["--cli", str(cli), "--source", "authors", "--train-missing", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "authors' MERL networks" in err and str(tmp_path / "nonexistent") in err
    assert not out.exists()
