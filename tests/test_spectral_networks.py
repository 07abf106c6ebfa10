"""Spectral networks (issue 31, file format version 3) in Mitsuba: a network whose outputs are the
coefficients of a clamped uniform cubic B-spline over 360-830 nm (docs/design.md, "Spectral
networks").

The references are independent of the plugin and of the library: the network's forward pass in
float64 NumPy (``nbrdf_tools.common.network``), the basis from SciPy's ``BSpline`` and the sRGB
projection integrated here from Mitsuba's CIE 1931 and D65 tables. The Dr.Jit twin of the basis
is held to the C ABI's ``nbrdf_material_eval_spectral``; sampling is checked with Mitsuba's chi^2
test in a spectral variant."""

from __future__ import annotations

import json
from pathlib import Path

import nbrdf_mitsuba  # noqa: F401  (before mitsuba)
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from conftest import bsdf_calls, use_variant
from nbrdf_testing import random_pairs
from nbrdf_tools.common import network

COUNT, MIN_NM, MAX_NM = 16, 360.0, 830.0
PHONG = {"sampling": "phong", "exponent": 30.0, "specular_weight": 0.5}
BAD = [float("nan"), float("inf"), float("-inf"), 0.0, -500.0, 359.0, 831.0, 1e30]
#: Rec. 709 luminance, as Mitsuba's mi.luminance (include/mitsuba/core/spectrum.h).
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])


def spectral_layers(hidden: int = 21, count: int = COUNT, seed: int = 0) -> list:
    """float32 weights of a random smooth spectral network (positive spectra with some shape)."""
    rng = np.random.default_rng(seed)
    layers = [(rng.uniform(-0.5, 0.5, s).astype(np.float32), rng.uniform(-0.1, 0.1, s[1]).astype(np.float32))
              for s in [(6, hidden), (hidden, hidden)]]
    layers.append((rng.uniform(0.0, 0.3, (hidden, count)).astype(np.float32),
                   rng.uniform(0.1, 0.9, count).astype(np.float32)))
    return layers


def write_spectral_network(path: Path, layers=None, count: int = COUNT, min_nm: float = MIN_NM,
                           max_nm: float = MAX_NM) -> Path:
    """A version-3 ``*.nbrdf.json`` file, written from docs/formats.md's description."""
    layers = spectral_layers(count=count) if layers is None else layers
    document = {
        "format": "nbrdf", "version": 3, "name": "spectral", "anisotropic": False,
        "spectral": {"basis": "cubic_bspline", "count": count, "min_nm": min_nm, "max_nm": max_nm},
        "layers": [{"inputs": int(w.shape[0]), "outputs": int(w.shape[1]),
                    "weights": [float(v) for v in np.asarray(w, np.float32).ravel()],
                    "bias": [float(v) for v in np.asarray(b, np.float32)]} for w, b in layers],
        "provenance": {"source": "nbrdf tests"},
    }
    Path(path).write_text(json.dumps(document))
    return Path(path)


def basis_oracle(wavelengths, count: int = COUNT, min_nm: float = MIN_NM, max_nm: float = MAX_NM):
    """(..., count) float64 values of the clamped uniform cubic B-spline basis (SciPy), 0 outside
    the range and at non-finite wavelengths."""
    from scipy.interpolate import BSpline

    wavelengths = np.asarray(wavelengths, np.float64)
    knots = np.concatenate([[min_nm] * 3, np.linspace(min_nm, max_nm, count - 2), [max_nm] * 3])
    flat = wavelengths.reshape(-1)
    out = np.zeros((flat.size, count))
    ok = np.isfinite(flat) & (flat >= min_nm) & (flat <= max_nm)
    out[ok] = BSpline.design_matrix(flat[ok], knots, 3).toarray()
    return out.reshape(*wavelengths.shape, count)


def coefficient_oracle(layers, view, light) -> np.ndarray:
    """(count, n) float64 coefficients times cos(theta_light), zero below the horizon."""
    c = network.evaluate([(np.float64(w), np.float64(b)) for w, b in layers], view.T, light.T).T
    above = (view[2] > 0) & (light[2] > 0)
    return np.where(above, c * (light[2] / np.linalg.norm(light, axis=0)), 0.0)


def spectral_oracle(layers, view, light, wavelengths) -> np.ndarray:
    """(m, n): f_r(lambda) cos(theta_light) at wavelengths (m, n)."""
    c = coefficient_oracle(layers, view, light)
    return np.einsum("jnk,kn->jn", basis_oracle(wavelengths), c)


def srgb_matrix_oracle(count: int = COUNT, step: float = 0.01) -> np.ndarray:
    """(3, count): ``XYZ_TO_SRGB int xyz(l) D65(l) B_k(l) dl * MI_CIE_Y_NORMALIZATION`` by the trapezoid rule on a
    ``step`` nm grid, from Mitsuba's tables (``cie1931_xyz``, ``cie_d65`` and ``xyz_to_srgb``
    in scalar_rgb, read at their 5 nm nodes and interpolated linearly as Mitsuba does)."""
    previous = mi.variant()
    mi.set_variant("scalar_rgb")
    try:
        nodes = np.linspace(360.0, 830.0, 95)
        cmf = np.array([list(mi.cie1931_xyz(float(w))) for w in nodes])
        d65 = np.array([mi.cie_d65(float(w)) for w in nodes])
        to_srgb = np.array([list(mi.xyz_to_srgb(mi.Color3f(*map(float, e)))) for e in np.eye(3)]).T
    finally:
        mi.set_variant(previous)
    grid = np.linspace(MIN_NM, MAX_NM, int(round((MAX_NM - MIN_NM) / step)) + 1)
    weight = np.stack([np.interp(grid, nodes, cmf[:, c]) for c in range(3)], 1) * np.interp(grid, nodes, d65)[:, None]
    # Mitsuba's MI_CIE_Y_NORMALIZATION (1 / the y table's integral as Mitsuba states it).
    xyz = np.trapezoid(weight[:, :, None] * basis_oracle(grid, count)[:, None, :], grid, axis=0) / 106.7502593994140625
    return to_srgb @ xyz


@pytest.fixture(scope="module")
def spectral_file(tmp_path_factory) -> Path:
    return write_spectral_network(tmp_path_factory.mktemp("specnet") / "s.nbrdf.json")


def _queries(n: int, seed: int):
    view, light = random_pairs(n, seed)
    light[:, : n // 4] = view[:, : n // 4] * np.array([[-1.0], [-1.0], [1.0]])  # mirror pairs
    rng = np.random.default_rng(seed + 1)
    return [a.astype(np.float32) for a in (view, light, rng.random((3, n)), rng.uniform(MIN_NM, MAX_NM, (4, n)))]



def _scene(path, backend):
    return {"type": "nbrdf", "filename": str(path), "backend": backend, **PHONG}


def _skip_scalar_jit(variant, backend):
    if backend == "jit" and variant.startswith("scalar"):
        pytest.skip("the jit backend needs a JIT variant")


def _unpolarized(value: np.ndarray, polarized: bool) -> np.ndarray:
    """The [0, 0] entry of a depolarizer (checking the rest is 0), or the value itself."""
    if not polarized:
        return value
    assert value.shape[:2] == (4, 4)
    rest = value.copy()
    rest[0, 0] = 0.0
    assert np.all(rest == 0.0)
    return value[0, 0]


# ---------------------------------------------------------------------------------------------
# The Dr.Jit basis and network, without the library


def test_traced_basis_is_scipys(restore_variant):
    """jit.bspline_weights against SciPy's BSpline design matrix, at random wavelengths, the range's
    ends, knots, and bad wavelengths (all 0); in a Float and in a spectral variant's 4-wide type."""
    use_variant("llvm_ad_rgb")
    from nbrdf_mitsuba import jit

    rng = np.random.default_rng(2)
    knots = np.linspace(MIN_NM, MAX_NM, COUNT - 2)
    lam = np.concatenate([rng.uniform(300.0, 900.0, 4000), knots, BAD]).astype(np.float32)
    got = np.stack([np.asarray(w.numpy()) for w in jit.bspline_weights(mi.Float(lam), COUNT, MIN_NM, MAX_NM)], 1)
    expected = basis_oracle(lam.astype(np.float64))
    np.testing.assert_allclose(got, expected, atol=2e-6)
    inside = (lam >= MIN_NM) & (lam <= MAX_NM)
    np.testing.assert_allclose(got[inside].sum(axis=1), 1.0, atol=1e-6)
    assert np.count_nonzero(got, axis=1).max() <= 4
    use_variant("llvm_ad_spectral")
    wide = lam[:4000].reshape(4, 1000)
    weights = jit.bspline_weights(mi.UnpolarizedSpectrum(wide), COUNT, MIN_NM, MAX_NM)
    got = np.stack([np.asarray(w.numpy()).reshape(4, 1000) for w in weights], -1)
    np.testing.assert_allclose(got, basis_oracle(wide.astype(np.float64)), atol=2e-6)


def test_traced_spectral_network_matches_the_float64_oracle(restore_variant):
    """TracedNetwork with 16 outputs, then jit.spectral_value, against NumPy's forward pass and
    SciPy's basis (relative to the value: float32 against float64)."""
    use_variant("llvm_ad_rgb")
    from nbrdf_mitsuba import jit

    layers = spectral_layers(seed=4)
    view, light, _, wavelengths = _queries(256, 11)
    traced = jit.TracedNetwork(layers)
    coefficients = traced.eval(mi.Vector3f(view), mi.Vector3f(light))
    assert isinstance(coefficients, list) and len(coefficients) == COUNT
    cos = np.asarray(jit.cos_theta(mi.Vector3f(light)).numpy())
    got = np.stack([np.asarray(jit.spectral_value(coefficients, mi.Float(w), MIN_NM, MAX_NM).numpy()) * cos
                    for w in wavelengths])
    expected = spectral_oracle(layers, view.astype(np.float64), light.astype(np.float64), wavelengths)
    assert expected.max() > 1.0
    np.testing.assert_allclose(got, expected, rtol=2e-5, atol=1e-7)


# ---------------------------------------------------------------------------------------------
# Through the library and the BSDF


def _close(got, expected, rtol, what):
    """Per column, relative to the column's largest value (float32 against float64)."""
    scale = np.max(np.abs(expected), axis=0, keepdims=True) + 1e-7
    worst = np.max(np.abs(got - expected) / scale)
    assert worst <= rtol, f"{what}: worst relative error {worst:.2e}"


def test_twin_matches_the_c_abi(spectral_file, restore_variant):
    """The Dr.Jit path (the network from nbrdf_material_network, jit.spectral_value) against
    nbrdf_material_eval_spectral on random pairs and wavelengths, bad wavelengths included."""
    use_variant("llvm_ad_rgb")
    from nbrdf_mitsuba import _native, jit

    material = _native.Material(spectral_file)
    assert (material.spectral_count, tuple(material.spectral_range_nm)) == (COUNT, (MIN_NM, MAX_NM))
    layers, _ = material.network(prove=False)
    view, light, _, wavelengths = _queries(512, 21)
    wavelengths[3, :len(BAD)] = BAD
    native = material.eval_spectral(view, light, wavelengths)
    traced = jit.TracedNetwork(layers, weights="opaque")
    coefficients = traced.eval(mi.Vector3f(view), mi.Vector3f(light))
    cos = jit.cos_theta(mi.Vector3f(light))
    got = np.stack([np.asarray((jit.spectral_value(coefficients, mi.Float(w), MIN_NM, MAX_NM) * cos).numpy())
                    for w in wavelengths])
    assert np.all(np.isfinite(native)) and np.all(native[3, :len(BAD)] == 0.0)
    _close(got, native, 1e-5, "Dr.Jit vs C ABI")
    _close(native, spectral_oracle(layers, view.astype(np.float64), light.astype(np.float64), wavelengths), 2e-5,
           "C ABI vs float64 oracle")


def test_the_librarys_srgb_matrix_is_the_cie_projection(spectral_file, restore_variant):
    """nbrdf_material_spectral_srgb against the projection integrated here from Mitsuba's tables;
    a constant spectrum of 1 (all coefficients 1) is D65's white, (1, 1, 1) in linear sRGB."""
    from nbrdf_mitsuba import _native

    matrix = np.asarray(_native.Material(spectral_file).spectral_srgb_matrix(), np.float64).reshape(3, COUNT)
    oracle = srgb_matrix_oracle()
    np.testing.assert_allclose(matrix, oracle, atol=2e-4 * np.abs(oracle).max())
    np.testing.assert_allclose(oracle.sum(axis=1), 1.0, atol=2e-3)


@pytest.mark.parametrize("backend", ["rust", "jit"])
@pytest.mark.parametrize("variant", ["scalar_spectral", "llvm_ad_spectral", "llvm_ad_spectral_polarized"])
def test_spectral_variants_evaluate_the_spectrum(variant, backend, spectral_file, restore_variant):
    """eval, eval_pdf and sample's weight are f_r(lambda) cos (/ pdf) at the lane's wavelengths
    (no uplift); the density is the RGB variant's (it never sees the wavelengths)."""
    use_variant(variant)
    _skip_scalar_jit(variant, backend)
    layers = network.read_layers(spectral_file)
    view, light, u, wavelengths = _queries(32, 31)
    got = bsdf_calls(mi.load_dict(_scene(spectral_file, backend)), view, light, u, wavelengths)
    polarized = "polarized" in variant
    expected = spectral_oracle(layers, view.astype(np.float64), light.astype(np.float64), wavelengths)
    for key in ("eval", "eval_pdf.value"):
        _close(_unpolarized(got[key], polarized), expected, 1e-4, key)
    wo = got["sample.wo"].astype(np.float32).astype(np.float64)
    pdf = got["sample.pdf"]
    sampled = spectral_oracle(layers, view.astype(np.float64), wo, wavelengths)
    sampled = np.where(pdf > 0, sampled / np.where(pdf > 0, pdf, 1.0), 0.0)
    assert np.count_nonzero(pdf) > 16
    _close(_unpolarized(got["sample.weight"], polarized), sampled, 1e-4, "sample.weight")
    mi.set_variant("scalar_rgb" if variant.startswith("scalar") else "llvm_ad_rgb")
    rgb = bsdf_calls(mi.load_dict(_scene(spectral_file, backend)), view, light, u, wavelengths)
    for key in ("pdf", "eval_pdf.pdf", "sample.wo", "sample.pdf"):
        np.testing.assert_array_equal(got[key], rgb[key], err_msg=key)


@pytest.mark.parametrize("backend", ["rust", "jit"])
@pytest.mark.parametrize("variant", ["scalar_rgb", "llvm_ad_rgb", "scalar_mono", "llvm_ad_mono"])
def test_rgb_and_mono_variants_render_the_projection(variant, backend, spectral_file, restore_variant):
    """RGB variants: M c cos with M the CIE projection (oracle); mono: its luminance (Rec. 709)."""
    use_variant(variant)
    _skip_scalar_jit(variant, backend)
    layers = network.read_layers(spectral_file)
    view, light, u, wavelengths = _queries(32, 41)
    got = bsdf_calls(mi.load_dict(_scene(spectral_file, backend)), view, light, u, wavelengths)
    rgb = srgb_matrix_oracle() @ coefficient_oracle(layers, view.astype(np.float64), light.astype(np.float64))
    expected = LUMINANCE @ rgb if "mono" in variant else rgb
    for key in ("eval", "eval_pdf.value"):
        value = got[key].reshape(expected.shape)
        _close(value, expected, 5e-4, key)
    assert np.all(np.isfinite(got["sample.weight"])) and np.max(got["sample.weight"]) > 0


@pytest.mark.parametrize("backend", ["rust", "jit"])
@pytest.mark.parametrize("variant", ["scalar_spectral", "llvm_ad_spectral"])
def test_bad_wavelengths_give_zero(variant, backend, spectral_file, restore_variant):
    """Non-finite or outside 360-830 nm: 0, never NaN; the good wavelengths beside them keep
    their values."""
    use_variant(variant)
    _skip_scalar_jit(variant, backend)
    view, light, u, good = _queries(len(BAD), 51)
    bad = good.copy()
    bad[2] = BAD
    bsdf = mi.load_dict(_scene(spectral_file, backend))
    got, reference = bsdf_calls(bsdf, view, light, u, bad), bsdf_calls(bsdf, view, light, u, good)
    for key in ("eval", "eval_pdf.value", "sample.weight"):
        assert np.all(np.isfinite(got[key])), key
        assert np.all(got[key][2] == 0.0), key
        np.testing.assert_array_equal(got[key][[0, 1, 3]], reference[key][[0, 1, 3]], err_msg=key)
        assert np.max(reference[key][2]) > 0, key


@pytest.mark.parametrize("backend", ["rust", "jit"])
def test_chi2_in_a_spectral_variant(backend, spectral_file, restore_variant):
    """Mitsuba's chi^2 test of sample() against pdf() in llvm_ad_spectral."""
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain
    from test_spectral import _adapter

    use_variant("llvm_ad_spectral")
    params = _scene(spectral_file, backend)
    for theta in (0.3, 1.2):
        wi = mi.Vector3f(float(np.sin(theta)), 0.0, float(np.cos(theta)))
        sample_func, pdf_func = _adapter("nbrdf", params, wi, (420.0, 530.0, 640.0, 780.0))
        chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                             sample_dim=3, sample_count=100_000, res=41)
        assert chi2.run(significance_level=0.01, test_count=8, quiet=True), (
            f"{backend} at theta_i = {theta}: {chi2.messages}")


def test_distill_in_a_spectral_variant_writes_a_version_3_network(tmp_path, capsys, restore_variant):
    """A tiny budget: the file is version 3 with 16 coefficients, loads, and renders gold-like
    colours (red above blue) in llvm_ad_rgb."""
    use_variant("llvm_ad_spectral")
    from nbrdf_mitsuba import distill

    source = tmp_path / "gold.json"
    source.write_text(json.dumps({"type": "roughconductor", "material": "Au", "alpha": 0.3}))
    out = tmp_path / "gold.nbrdf.json"
    status = distill.main([str(source), "-o", str(out), "--variant", "llvm_ad_spectral", "--samples", "4000",
                           "--epochs", "4", "--threads", "1", "-q"])
    assert status == 0, capsys.readouterr().err
    document = json.loads(out.read_text())
    assert document["version"] == 3
    assert document["spectral"] == {"basis": "cubic_bspline", "count": COUNT, "min_nm": MIN_NM, "max_nm": MAX_NM}
    assert document["layers"][-1]["outputs"] == COUNT
    assert document["provenance"]["distilled_from"]["wavelengths_nm"][:2] == [360.0, 370.0]
    mi.set_variant("llvm_ad_rgb")
    view, light = random_pairs(64, 3)
    light[:, :32] = view[:, :32] * np.array([[-1.0], [-1.0], [1.0]])
    rgb = bsdf_calls(mi.load_dict({"type": "nbrdf", "filename": str(out)}), *(a.astype(np.float32) for a in (
        view, light, np.full((3, 64), 0.5), np.full((4, 64), 500.0))))["eval"]
    assert np.all(np.isfinite(rgb)) and rgb[0].sum() > rgb[2].sum() > 0


def test_distill_evaluates_the_source_at_each_wavelength(restore_variant):
    """distill.eval_cos in spectral variants: row j is the BSDF at wavelength j (a count that is
    not a multiple of Mitsuba's 4 per lane), the same in scalar_spectral and llvm_ad_spectral, and
    equal to evaluations with all four lane wavelengths set to that one."""
    from nbrdf_mitsuba import distill

    spec = {"type": "roughconductor", "material": "Cu", "alpha": 0.25}
    view, light = random_pairs(6, 8)
    light[:, :3] = view[:, :3] * np.array([[-1.0], [-1.0], [1.0]])  # mirror pairs: bright values
    wavelengths = np.array([365.0, 420.0, 500.0, 580.0, 640.0, 700.0, 825.0])
    values = {}
    for variant in ("scalar_spectral", "llvm_ad_spectral"):
        use_variant(variant)
        bsdf = mi.load_dict(spec)
        values[variant] = distill.eval_cos(bsdf, view, light, wavelengths)
        assert values[variant].shape == (len(wavelengths), 6)
        for j, w in enumerate(wavelengths):
            for i in range(6):
                si = dr.zeros(mi.SurfaceInteraction3f)
                si.wi = mi.Vector3f(*map(float, view[:, i]))
                si.wavelengths = mi.UnpolarizedSpectrum(float(w))
                one = np.asarray(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*map(float, light[:, i]))).numpy()
                                 if dr.is_jit_v(mi.Float) else bsdf.eval(mi.BSDFContext(), si,
                                                                          mi.Vector3f(*map(float, light[:, i]))),
                                 np.float64).reshape(-1)
                np.testing.assert_allclose(values[variant][j, i], one[0], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(values["scalar_spectral"], values["llvm_ad_spectral"], rtol=1e-4, atol=1e-7)
    # Copper: red reflects more than blue.
    assert values["scalar_spectral"][5].sum() > 1.5 * values["scalar_spectral"][1].sum() > 0


def test_spectral_report_quick(tmp_path, restore_variant):
    """``python -m nbrdf_tools spectral-networks --quick`` on one material: the page opens with its
    command, states the weights, has a row per network, and the figure is written."""
    use_variant("llvm_ad_spectral")
    from nbrdf_tools.pages import spectral_networks as spectral_report

    out, figure = tmp_path / "spectral.md", tmp_path / "spectral.png"
    argv = ["--quick", "--materials", "Cu", "--out", str(out), "--figure", str(figure), "--work", str(tmp_path)]
    assert spectral_report.main(argv) == 0
    text = out.read_text()
    assert text.startswith("# Spectral networks\n\n```sh\npython -m nbrdf_tools spectral-networks --stored-only "
                           f"--data {out.with_suffix('.json')} --out {out}   #")
    assert "\npython -m nbrdf_tools spectral-networks --quick" in text
    assert "961 (6-21-21-16)" in text and "675 (6-21-21-3): 1.42x" in text
    assert text.count("| Cu | `llvm_ad_") == 4
    assert figure.stat().st_size > 10_000


def test_train_spectral_from_arrays_learns_a_spectral_lambertian(tmp_path):
    """The Python entry point on a closed form: a spectral Lambertian (albedo rising from 0.1 at
    360 nm to 0.7 at 830 nm, sampled every 20 nm) gives a version-3 network whose per-wavelength
    values, through the C ABI, are within 15 % of albedo / pi cos; bad shapes and wavelengths are
    refused, the latter by the library naming the problem."""
    from nbrdf_mitsuba import _native, _train_native as native

    config = native.default_config()
    config.samples, config.max_epochs, config.hidden, config.batch, config.threads = 3000, 30, 8, 128, 1
    view, light, n_validation = native.sample_directions(config)
    wavelengths = np.arange(360.0, 831.0, 20.0)
    albedo = lambda nm: 0.1 + 0.6 * (nm - 360.0) / 470.0  # noqa: E731
    values = albedo(wavelengths)[:, None] / np.pi * light[2][None, :]
    text = native.train_spectral_from_arrays(config, view, light, wavelengths, values, n_validation,
                                             name="lambert", source="closed form")
    document = json.loads(text)
    assert document["version"] == 3 and document["layers"][-1]["outputs"] == COUNT
    file = tmp_path / "lambert.nbrdf.json"
    file.write_text(text)
    v, lt = random_pairs(50, 4, min_cos=0.05)
    probe = np.array([410.0, 555.0, 705.0])
    got = _native.Material(file).eval_spectral(v, lt, np.repeat(probe, 50).reshape(3, 50))
    want = albedo(probe)[:, None] / np.pi * lt[2][None, :]
    np.testing.assert_allclose(got, want, rtol=0.15)
    with pytest.raises(ValueError, match="wavelength-major"):
        native.train_spectral_from_arrays(config, view, light, wavelengths, values.T, n_validation,
                                          name="x", source="x")
    with pytest.raises(native.TrainError, match="strictly increasing"):
        native.train_spectral_from_arrays(config, view, light, wavelengths[::-1], values, n_validation,
                                          name="x", source="x")
