"""The autoencoder and Phong predictor built into ``nbrdf`` (nbrdf-core/data/models/,
docs/results/latent.md "Built-in models"): ``nbrdf predict-phong NET.json`` works with no flags on
a network of ``nbrdf train``, networks of another initialisation are re-learnt first (with a
message; ``--no-relearn`` skips it), and the predicted lobe samples about as well as the one
``nbrdf fit-phong`` searches for, scored by a NumPy oracle of the relative variance.

The networks are trained briefly (speed, not fidelity, matters here: the predictor reads whatever
material the network is) and the one re-learn runs with ``--relearn-epochs 2``. Of the two
materials of the quality check, aluminium misses the stated bound (a strict xfail with its
figures; the whole test split is scored in docs/results/latent.md).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from nbrdf_testing import nbrdf_reference, phong_pdf, random_layers, read_network_layers, write_network

MODELS = Path(__file__).resolve().parents[1] / "nbrdf-core" / "data" / "models"
# Brief training: enough for a plausible material in a few seconds.
QUICK_TRAIN = ["--samples", "100000", "--epochs", "15", "--min-epochs", "0", "-q"]
# The quality check's bound on sqrt(v_pred / v_fit), the sampling RMSE of the predicted lobe over
# the fitted one's. Chosen before measuring: the predictor's own evaluation counts test materials
# within 1.25x; these networks (brief fits of SGD tables) are further from its training set.
RMSE_RATIO_BOUND = 1.5


def _cli_or_skip() -> Path:
    from conftest import _cli

    cli = _cli()
    if cli is None:
        pytest.skip("the nbrdf CLI is not built (target/release/nbrdf)")
    return cli


def _run(cli: Path, *command) -> subprocess.CompletedProcess:
    done = subprocess.run([str(cli), *map(str, command)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return done


def _trained(cli: Path, folder: Path, material: str, seed: int = 0) -> Path:
    table = folder / f"{material}.binary"
    if not table.exists():
        _run(cli, "synth", "--model", "sgd", "--material", material, "-o", table)
    network = folder / f"{material}-seed{seed}.nbrdf.json"
    _run(cli, "train", table, "-o", network, "--seed", seed, *QUICK_TRAIN)
    return network


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("pretrained")


def _sampling(path: Path) -> dict:
    return json.loads(path.read_text())["sampling"]


def test_predict_phong_needs_no_flags(folder):
    cli = _cli_or_skip()
    network = _trained(cli, folder, "gold-metallic-paint")
    before = network.read_text()
    out = folder / "predicted.nbrdf.json"
    done = _run(cli, "predict-phong", network, "-o", out)
    assert "re-learn" not in done.stderr, done.stderr
    assert network.read_text() == before
    sampling = _sampling(out)
    assert sampling["source"] == "predicted" and sampling["model"] == "blinn-phong"
    assert np.isfinite(sampling["exponent"]) and 0 <= sampling["exponent"] <= 1e6
    assert 0 <= sampling["specular_weight"] <= 1
    assert f"exponent {sampling['exponent']:.4f}" in done.stdout
    # The network is the one read: only the sampling changed.
    assert json.loads(out.read_text())["layers"] == json.loads(before)["layers"]
    # In place by default.
    _run(cli, "predict-phong", network)
    assert _sampling(network) == sampling


def test_networks_of_another_initialisation_are_relearnt(folder):
    cli = _cli_or_skip()
    other = _trained(cli, folder, "gold-metallic-paint", seed=5)
    out = folder / "relearnt.nbrdf.json"
    done = _run(cli, "predict-phong", other, "-o", out, "--relearn-epochs", "2")
    assert "trained from seed 5, not the common initialisation (seed 0)" in done.stderr, done.stderr
    assert "re-learning it" in done.stderr and "re-learnt 'gold-metallic-paint' in" in done.stderr
    assert "(2 epochs," in done.stderr
    # What is written is the network given, with the lobe predicted from its re-learnt twin.
    assert json.loads(out.read_text())["layers"] == json.loads(other.read_text())["layers"]
    assert _sampling(out)["source"] == "predicted"

    skipped = _run(cli, "predict-phong", other, "-o", folder / "as-is.nbrdf.json", "--no-relearn")
    assert "re-learning" not in skipped.stderr and "re-learnt" not in skipped.stderr
    assert "warning: encoding 'gold-metallic-paint' as it is (--no-relearn)" in skipped.stderr


def test_foreign_provenance_is_named(folder):
    """A network of the authors' Keras files (as nbrdf_mitsuba.import_keras writes it) or of no
    known trainer: the message says why it is foreign. --no-relearn keeps it cheap."""
    cli = _cli_or_skip()
    keras = write_network(folder / "keras.nbrdf.json", name="keras")
    document = json.loads(keras.read_text())
    document["provenance"] = {"method": "imported from Keras (Sztrajman et al. 2021)"}
    keras.write_text(json.dumps(document))
    done = _run(cli, "ae", "encode", keras, "--no-relearn")
    assert "imported from Keras (Sztrajman et al. 2021): initialised independently" in done.stderr, done.stderr
    assert len(json.loads(done.stdout)) == 32
    unknown = write_network(folder / "unknown.nbrdf.json", name="unknown")
    done = _run(cli, "ae", "encode", unknown, "--no-relearn")
    assert "no provenance of `nbrdf train`" in done.stderr, done.stderr


def test_ae_alone_needs_its_predictor(folder):
    cli = _cli_or_skip()
    network = write_network(folder / "n.nbrdf.json")
    ae = MODELS / "autoencoder.json"
    done = subprocess.run([str(cli), "predict-phong", "--ae", str(ae), str(network)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "needs --predictor" in done.stderr, done.stderr
    clash = subprocess.run([str(cli), "predict-phong", str(network), "--no-relearn", "--relearn-epochs", "2"],
                           capture_output=True, text=True, timeout=60)
    assert clash.returncode == 2, clash.stderr


def _family_folder(folder: Path, provenance: dict | None) -> Path:
    """Five random networks (enough for `ae train`'s split), each with `provenance`."""
    folder.mkdir()
    for k, name in enumerate("abcde"):
        path = write_network(folder / f"{name}.nbrdf.json", random_layers(seed=k), name=name)
        if provenance is not None:
            document = json.loads(path.read_text())
            document["provenance"] = provenance
            path.write_text(json.dumps(document))
    return folder


def test_ae_train_records_the_family_that_encoding_reads_back(tmp_path):
    """`ae train` on networks of `nbrdf train` with one seed records that family; the commands
    that encode then treat another seed as foreign. On networks of unknown origin it records
    none, and nothing is foreign."""
    cli = _cli_or_skip()
    trainer = "nbrdf-core 0.1.0 trainer 1"
    quick = ["--epochs", "3", "--warmup", "2", "--quiet"]
    family = _family_folder(tmp_path / "family", {"trainer": trainer, "seed": 3})
    unknown = _family_folder(tmp_path / "unknown", None)
    ae, ae_unknown = tmp_path / "ae.json", tmp_path / "ae-unknown.json"
    _run(cli, "ae", "train", "--nbrdfs", family, "-o", ae, *quick)
    _run(cli, "ae", "train", "--nbrdfs", unknown, "-o", ae_unknown, *quick)
    recorded = json.loads(ae.read_text())["provenance"]["networks"]
    assert (recorded["initialisation"], recorded["seed"], recorded["hidden"]) == \
        ("common: nbrdf train from one seed", 3, 21)
    assert json.loads(ae_unknown.read_text())["provenance"]["networks"] == {"initialisation": "mixed or unknown"}

    seed0 = write_network(tmp_path / "seed0.nbrdf.json", random_layers(seed=9), name="seed0")
    document = json.loads(seed0.read_text())
    document["provenance"] = {"trainer": trainer, "seed": 0}
    seed0.write_text(json.dumps(document))
    foreign = _run(cli, "ae", "encode", "--ae", ae, seed0, "--no-relearn")
    assert "trained from seed 0, not the common initialisation (seed 3)" in foreign.stderr, foreign.stderr
    assert _run(cli, "ae", "encode", "--ae", ae, family / "a.nbrdf.json").stderr == ""
    assert _run(cli, "ae", "encode", "--ae", ae_unknown, seed0).stderr == ""


def test_models_are_in_the_command_only():
    """The command embeds the models; the C library the plugin loads does not."""
    from conftest import _cli

    cli = _cli()
    library = Path(__file__).resolve().parents[1] / "target" / "release" / "libnbrdf_ffi.so"
    if cli is None or not library.is_file():
        pytest.skip("needs target/release/nbrdf and libnbrdf_ffi.so (make build)")
    # The embedded models' own record of the command that made them (its name at the time).
    marker = b'"made_by":{"command":"python -m nbrdf_tools.pretrained"'
    assert marker in (MODELS / "autoencoder.json").read_bytes()
    assert marker in cli.read_bytes()
    assert marker not in library.read_bytes()


# -- Quality against an independent reference ------------------------------------------------

VIEW_THETAS = np.radians(5.0 + 10.0 * np.arange(9))


def relative_variance(layers, exponent: float, weight: float, s_bins: int = 160, phi_bins: int = 64) -> float:
    """Mean over 9 view elevations of R - 1, R = int g^2 / p / (int g)^2 with g = mean_RGB(f_r) cos
    and p the Blinn-Phong mixture density, by quadrature over the half vector (theta_h = pi/2 s^2).
    The NumPy twin of nbrdf-core/src/fit/lobes/one_lobe.rs (second_moment, quadrature), held to it by
    test_oracle_agrees_with_fit_phong below."""
    s = (np.arange(s_bins) + 0.5) / s_bins
    phi = (np.arange(phi_bins) + 0.5) * np.pi / phi_bins
    s, phi = (a.ravel() for a in np.meshgrid(s, phi, indexing="ij"))
    theta_h = np.pi / 2 * s * s
    half = np.stack([np.sin(theta_h) * np.cos(phi), np.sin(theta_h) * np.sin(phi), np.cos(theta_h)])
    # dω_h over phi in [0, pi], counted twice (isotropic material, view in the xz plane).
    dw_h = 2 * np.sin(theta_h) * np.pi * s / s_bins * np.pi / phi_bins
    moments = []
    for theta_v in VIEW_THETAS:
        view = np.array([np.sin(theta_v), 0.0, np.cos(theta_v)])[:, None]
        v_dot_h = np.sum(view * half, axis=0)
        light = 2 * v_dot_h * half - view
        keep = (v_dot_h > 0) & (light[2] > 0)
        light, v_dot_h, dw = light[:, keep], v_dot_h[keep], 4 * v_dot_h[keep] * dw_h[keep]
        views = np.repeat(view, light.shape[1], axis=1)
        g = nbrdf_reference(layers, light, views).mean(axis=0)
        ok = g > 0
        integral = np.sum(g[ok] * dw[ok])
        pdf = phong_pdf(views[:, ok], light[:, ok], exponent, weight)
        moments.append(np.sum(g[ok] ** 2 * dw[ok] / pdf) / integral ** 2)
    return float(np.mean(moments) - 1)


# The first two materials of the built-in autoencoder's test split (chosen before measuring).
QUALITY_MATERIALS = ["aluminium", "black-oxidized-steel"]


@pytest.fixture(scope="module")
def scored(folder) -> dict[str, dict]:
    """The QUALITY_MATERIALS, each a briefly trained network of its SGD table: fitted and
    predicted lobes."""
    cli = _cli_or_skip()
    test_split = json.loads((MODELS / "autoencoder.json").read_text())["split"]["test"]
    assert test_split[:2] == QUALITY_MATERIALS
    rows = {}
    for material in QUALITY_MATERIALS:
        network = _trained(cli, folder, material)
        fit = json.loads(_run(cli, "fit-phong", network, "--lobes", "1", "--json",
                              "-o", folder / "fit.nbrdf.json").stdout)
        predicted = folder / "quality.nbrdf.json"
        _run(cli, "predict-phong", network, "-o", predicted)
        rows[material] = {"material": material, "layers": read_network_layers(network), "fit": fit,
                          "predicted": _sampling(predicted)}
    return rows


def _fitted_lobe(fit: dict) -> tuple[float, float, float]:
    return fit["exponent"], fit["specular_weight"], fit["relative_variance"]["variance_lobe"]


def test_oracle_agrees_with_fit_phong(scored):
    for row in scored.values():
        n, w, reported = _fitted_lobe(row["fit"])
        assert relative_variance(row["layers"], n, w) == pytest.approx(reported, rel=0.02), row["material"]


def test_predicted_lobe_beats_cosine_sampling(scored):
    for row in scored.values():
        p = row["predicted"]
        v_pred = relative_variance(row["layers"], p["exponent"], p["specular_weight"])
        assert v_pred < relative_variance(row["layers"], 0.0, 0.0), row["material"]


@pytest.mark.parametrize("material", [
    pytest.param("aluminium", marks=pytest.mark.xfail(strict=True, reason=(
        "a known miss (docs/results/latent.md, 'Built-in models'): the SGD fit of aluminium is a "
        "sharper metal (fitted n 3162, w 0.8) than the real one the predictor learnt from (n 1334, "
        "w 0.65); it predicts w 0.40, a sampling RMSE 2.6x the fitted lobe's"))),
    "black-oxidized-steel",
])
def test_predicted_lobe_samples_about_as_well_as_the_fitted_one(scored, material):
    row = scored[material]
    n, w, _ = _fitted_lobe(row["fit"])
    v_fit = relative_variance(row["layers"], n, w)
    p = row["predicted"]
    v_pred = relative_variance(row["layers"], p["exponent"], p["specular_weight"])
    ratio = np.sqrt(max(v_pred, 1e-12) / max(v_fit, 1e-12))
    assert ratio <= RMSE_RATIO_BOUND, ((n, w, v_fit), p, v_pred, ratio)
