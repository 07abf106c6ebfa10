"""The fidelity report's fitting code against closed forms and independent implementations, and
the report end to end on a tiny setting.

* The NumPy GGX conductor against Mitsuba's ``roughconductor`` ``eval``; Mitsuba's
  ``roughplastic`` is linear in its two reflectances (what the roughplastic fit relies on).
* The NumPy ABC and SGD forms against the Rust ones: tables written by ``nbrdf synth`` hold
  ``f_r`` at their cell centres.
* Fits recover the known parameters of synthetic Blinn-Phong and GGX data from its own samples.
"""

from __future__ import annotations

import json
import shlex
import subprocess

import nbrdf_mitsuba  # noqa: F401  (first: points Dr.Jit at a usable libLLVM)
import numpy as np
import pytest

from nbrdf_testing import SCALE, cell_centre_angles, from_angles, read_merl
from nbrdf_tools.common import analytic_fit as af
from nbrdf_tools.common import compare_materials as cm
from nbrdf_tools.pages import fidelity as fidelity_report
from nbrdf_tools.common.paths import default_cli


def _cli():
    cli = default_cli()
    if not cli.is_file():
        pytest.skip(f"the nbrdf CLI {cli} is not built (make build)")
    return cli


def _directions(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(view, light) uniform over the hemisphere above 1 degree."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        z = rng.uniform(0.02, 1.0, n)
        phi = rng.uniform(0, 2 * np.pi, n)
        s = np.sqrt(1 - z * z)
        out.append(np.stack([s * np.cos(phi), s * np.sin(phi), z]))
    return out[0], out[1]


def test_numpy_anisotropic_ggx_matches_mitsuba_roughconductor():
    cm.set_variant()
    import mitsuba as mi

    view, light = _directions(4000, 6)
    for x in ([0.9, 0.5, 0.2, 0.05, 0.3], [1.0, 1.0, 1.0, 0.4, 0.02], [0.3, 0.6, 0.9, 0.2, 0.2]):
        expect = cm.eval_cos(mi.load_dict(af.roughconductor_dict(x)), view, light)
        got = af.ggx_aniso_conductor_eval_cos(x, view, light)
        np.testing.assert_allclose(got, expect, rtol=2e-4, atol=1e-6 * expect.max())
        if x[3] == x[4]:  # equal alphas: the isotropic form
            np.testing.assert_allclose(got, af.ggx_conductor_eval_cos(x[:4], view, light), rtol=1e-12)
    # Swapping the alphas is not the same BSDF (the tangent is local x): the test can tell them apart.
    swapped = af.ggx_aniso_conductor_eval_cos([0.9, 0.5, 0.2, 0.3, 0.05], view, light)
    assert np.max(np.abs(swapped - af.ggx_aniso_conductor_eval_cos([0.9, 0.5, 0.2, 0.05, 0.3], view, light))) > 0.1


def test_numpy_ggx_matches_mitsuba_roughconductor():
    cm.set_variant()
    import mitsuba as mi

    view, light = _directions(4000, 1)
    for x in ([0.9, 0.5, 0.2, 0.3], [1.0, 1.0, 1.0, 0.02], [0.3, 0.6, 0.9, 0.8]):
        expect = cm.eval_cos(mi.load_dict(af.roughconductor_dict(x)), view, light)
        got = af.ggx_conductor_eval_cos(x, view, light)
        # Mitsuba evaluates in float32: relative 1e-4, plus an absolute floor for the zeros of
        # a sharp lobe's tails.
        np.testing.assert_allclose(got, expect, rtol=2e-4, atol=1e-6 * expect.max())


def test_roughplastic_is_linear_in_its_reflectances():
    cm.set_variant()
    import mitsuba as mi

    view, light = _directions(2000, 2)
    basis = af.RoughPlasticBasis()
    x = [0.6, 0.3, 0.1, 0.7, 0.15]
    expect = cm.eval_cos(mi.load_dict(af.roughplastic_dict(x[:3], x[3], x[4])), view, light)
    np.testing.assert_allclose(basis.eval_cos(x, view, light), expect, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("model, material", [("abc", "alum-bronze"), ("sgd", "gold-metallic-paint"),
                                             ("sgd", "black-phenolic")])
def test_numpy_abc_sgd_match_rust_tables(model, material, tmp_path):
    cli = _cli()
    table = tmp_path / f"{material}.binary"
    subprocess.run([str(cli), "synth", "--model", model, "--material", material, "-o", str(table)], check=True,
                   capture_output=True)
    stored = read_merl(table)
    rng = np.random.default_rng(3)
    idx = [rng.integers(0, n, 3000) for n in (90, 90, 180)]
    light, view = from_angles(cell_centre_angles(*idx)[0], 0.0, *cell_centre_angles(*idx)[1:])
    keep = (light[2] > 1e-3) & (view[2] > 1e-3)
    expect = stored[:, idx[0], idx[1], idx[2]][:, keep] * SCALE[:, None]
    abc, sgd = af.published_fits()
    x = dict(abc if model == "abc" else sgd)[material]
    form = af.abc_eval_cos if model == "abc" else af.sgd_eval_cos
    got = form(x, view[:, keep], light[:, keep]) / light[2, keep]
    np.testing.assert_allclose(got, expect, rtol=1e-9, atol=1e-12)


def _synthetic(form, x, n=6000):
    view, light = af.fit_directions(n, seed=5)
    return af.FitData(view, light, form(np.asarray(x, float), view, light))


def test_fit_recovers_blinn_phong():
    truth = [0.2, 0.1, 0.05, 0.3, 0.4, 0.5, 80.0]
    fit = af.fit_model(af.blinn_phong_model(), _synthetic(af.blinn_phong_eval_cos, truth))
    np.testing.assert_allclose(fit.x, truth, rtol=1e-3)
    assert fit.loss < 1e-10


def test_fit_recovers_ggx_conductor():
    truth = [0.8, 0.6, 0.3, 0.15]
    fit = af.fit_model(af.ggx_conductor_model(), _synthetic(af.ggx_conductor_eval_cos, truth))
    np.testing.assert_allclose(fit.x, truth, rtol=1e-3)
    assert fit.loss < 1e-10


def test_fit_recovers_anisotropic_ggx_conductor():
    truth = [0.8, 0.6, 0.3, 0.06, 0.25]
    view, light = af.fit_directions(6000, seed=5, turned=True)
    data = af.FitData(view, light, af.ggx_aniso_conductor_eval_cos(np.asarray(truth), view, light))
    fit = af.fit_model(af.ggx_aniso_conductor_model(), data)
    np.testing.assert_allclose(fit.x, truth, rtol=1e-3)
    assert fit.loss < 1e-10
    # The isotropic GGX cannot: its best loss is orders of magnitude above.
    assert af.fit_model(af.ggx_conductor_model(), data).loss > 1e-4


def test_turned_directions_cover_the_azimuth():
    """Adaptive pairs have phi_h = 0; turned ones spread it (what an anisotropic fit needs)."""
    for turned, spread in ((False, False), (True, True)):
        view, light = af.fit_directions(2000, seed=1, turned=turned)
        h = view + light
        phi = np.arctan2(h[1], h[0])[:1000]  # the adaptive half
        assert bool(np.std(np.cos(2 * phi)) > 0.5) == spread


def test_numpy_bsdf_renders_its_form():
    cm.set_variant()
    x = np.array([0.2, 0.1, 0.05, 0.3, 0.4, 0.5, 80.0])
    view, light = _directions(500, 4)
    bsdf = af.mitsuba_bsdf("blinn_phong", x)
    np.testing.assert_allclose(cm.eval_cos(bsdf, view, light), af.blinn_phong_eval_cos(x, view, light),
                               rtol=1e-6, atol=1e-9)


def test_weight_counts():
    # 6-21-21-3, the paper's network: 675 weights.
    assert fidelity_report.weight_count(21) == 675
    assert fidelity_report.weight_count(4) == 6 * 4 + 4 + 16 + 4 + 12 + 3


def test_report_runs_end_to_end(merl_table, tmp_path):
    cli = _cli()
    report = tmp_path / "doc" / "fid.md"
    argv = ["--merl", str(merl_table), "--hidden", "4", "--uniform-hidden", "4", "--table-hidden", "4",
            "--samples", "4000", "--epochs", "2", "--models", "roughconductor,blinn_phong", "--fit-samples", "400",
            "--resolution", "16", "--metric-samples", "400", "--work", str(tmp_path / "work"), "--out", str(report),
            "--cli", str(cli), "--no-progress"]
    assert fidelity_report.main(argv) == 0
    text = report.read_text()
    assert text.splitlines()[2:4] == ["```sh", f"python -m nbrdf_tools fidelity --stored-only --data "
                                                f"{report.with_suffix('.json')} --out {report}"]
    assert "python -m nbrdf_tools fidelity " + " ".join(argv) in text
    assert "No anisotropic material was given" in text
    # The stored results alone write the same page.
    again = tmp_path / "again.md"
    assert fidelity_report.main(["--stored-only", "--data", str(report.with_suffix(".json")), "--out", str(again)]) == 0
    assert again.read_text() == text
    document = json.loads(report.with_suffix(".json").read_text())
    rows = {r["method"]: r for r in document["rows"]}
    assert set(rows) == {"merl-table", "roughconductor", "blinn_phong", "nbrdf-adaptive-h4", "nbrdf-uniform-h4"}
    assert rows["nbrdf-adaptive-h4"]["memory_bytes"] == 4 * 63
    assert rows["blinn_phong"]["memory_bytes"] == 4 * 7
    for r in rows.values():
        if r["kind"] != "reference":
            assert all(np.isfinite(v) for v in r["metrics"].values())
            assert 0 < r["metrics"]["ssim"] <= 1
    assert report.with_suffix(".png").stat().st_size > 0
    # A rerun reuses every row (no training, no fitting): the same numbers.
    assert fidelity_report.main(argv) == 0
    again = {r["method"]: r for r in json.loads(report.with_suffix(".json").read_text())["rows"]}
    assert again == rows


def test_anisotropic_table_end_to_end(tmp_path):
    """Built-in and JSON Mitsuba sources make the anisotropic table; the anisotropic NBRDF beats
    the isotropic one against the source, and the anisotropic GGX fits an anisotropic GGX
    conductor almost exactly."""
    cli = _cli()
    report = tmp_path / "fid.md"
    conductor = json.dumps({"type": "roughconductor", "distribution": "ggx", "material": "none",
                            "alpha_u": 0.08, "alpha_v": 0.4})
    argv = ["--mitsuba", "principled_aniso", "--mitsuba", f"ggx={conductor}", "--samples", "60000", "--epochs", "25",
            "--models", "roughconductor", "--fit-samples", "1500", "--resolution", "24", "--metric-samples", "3000",
            "--work", str(tmp_path / "work"), "--out", str(report), "--cli", str(cli), "--no-progress"]
    assert fidelity_report.main(argv) == 0
    text = report.read_text()
    assert "python -m nbrdf_tools fidelity " + shlex.join(argv) in text
    section = text[text.index("## Anisotropic materials"):]
    assert "### principled_aniso" in section and "### ggx" in section and "### Verdict" in section
    rows = json.loads(report.with_suffix(".json").read_text())["rows"]
    for material in ("principled_aniso", "ggx"):
        mine = {r["method"]: r for r in rows if r["material"] == material}
        assert set(mine) == {"source", "roughconductor_aniso", "roughconductor", "nbrdf-aniso-h21", "nbrdf-iso-h21"}
        aniso, iso = mine["nbrdf-aniso-h21"], mine["nbrdf-iso-h21"]
        assert aniso["anisotropic"] is True and iso["anisotropic"] is False
        assert aniso["stored_values"] == iso["stored_values"] == 675
        for key in ("log_error_adaptive", "log_error_uniform", "rmse_tonemapped"):
            assert aniso["metrics"][key] < 0.8 * iso["metrics"][key], (material, key, aniso["metrics"], iso["metrics"])
    fit = {r["method"]: r for r in rows if r["material"] == "ggx"}["roughconductor_aniso"]
    assert abs(fit["fit"]["parameters"]["alpha_u"] - 0.08) < 1e-3 and abs(fit["fit"]["parameters"]["alpha_v"] - 0.4) < 4e-3
    assert fit["metrics"]["log_error_adaptive"] < 1e-4
    assert "**anisotropic GGX `roughconductor` beats the anisotropic NBRDF**" in section
    assert "Mitsuba `roughconductor` (the reference)" in section and "Mitsuba `principled` (the reference)" in section
