"""Spectral spatially varying materials (issue 61; a version-4 file with a ``spectral`` object):
the decoder gives B-spline coefficients. Their values per wavelength in spectral variants and
their sRGB projection in RGB ones against a float64 NumPy oracle (the decoder through
``textured_fixture.eval_oracle``, SciPy's basis, the CIE projection integrated from Mitsuba's
tables), the library against the traced twin, chi^2 in a spectral variant, renders in every
kind of variant, and a spectral distillation of a blend of gold and copper."""

from __future__ import annotations

import json

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from conftest import bsdf_calls, use_variant
from nbrdf_testing import random_pairs
from test_spectral_networks import LUMINANCE, basis_oracle, srgb_matrix_oracle
from textured_fixture import eval_oracle, render, write_textured

SPECTRAL = {"basis": "cubic_bspline", "count": 16, "min_nm": 360.0, "max_nm": 830.0}
#: Texel centres of the fixture's 5 x 4 texture, and points between them.
UVS = [(0.1, 0.125), (0.5, 0.375), (0.9, 0.875), (0.23, 0.61), (0.77, 0.05)]


@pytest.fixture(scope="module")
def material(tmp_path_factory):
    return write_textured(tmp_path_factory.mktemp("spectex") / "s.nbrdf.json", channels=3, lobes=1,
                          spectral=SPECTRAL, precision="float32")


def spectral_oracle(material, uv, view, light, wavelengths) -> np.ndarray:
    """(m, n) ``f_r(lambda) cos`` at wavelengths (m, n)."""
    c = eval_oracle(material, uv, view, light)
    return np.einsum("jnk,kn->jn", basis_oracle(wavelengths), c)


def queries(n: int, seed: int):
    """float32 view, light, uniforms, 4 wavelengths and a UV per column (mirror pairs first)."""
    view, light = random_pairs(n, seed)
    light[:, : n // 4] = view[:, : n // 4] * np.array([[-1.0], [-1.0], [1.0]])
    rng = np.random.default_rng(seed + 1)
    uv = np.array([UVS[i % len(UVS)] for i in range(n)]).T
    return [a.astype(np.float32) for a in (view, light, rng.random((3, n)), rng.uniform(360.0, 830.0, (4, n)), uv)]


def close(got, expected, rtol, what):
    """Per column, relative to the column's largest value (float32 against float64)."""
    scale = np.max(np.abs(expected), axis=0, keepdims=True) + 1e-7
    worst = np.max(np.abs(got - expected) / scale)
    assert worst <= rtol, f"{what}: worst relative error {worst:.2e}"


def unpolarized(value, polarized: bool):
    return value[0, 0] if polarized else value


def test_the_library_evaluates_the_spectrum_and_projects_it(material, restore_variant):
    """nbrdf_material_eval_spectral (with UVs) and eval_uv against the oracle; a UV read upside
    down would not match."""
    from nbrdf_mitsuba import _native

    use_variant("scalar_rgb")

    native = _native.Material(material.path)
    assert (native.kind, native.spectral_count, native.spectral_range_nm) == ("textured", 16, (360.0, 830.0))
    view, light, _, wavelengths, uv = queries(200, 3)
    got = native.eval_spectral(view, light, wavelengths, uv=uv)
    expected = spectral_oracle(material, uv, view, light, wavelengths)
    assert expected.max() > 0.5
    close(got, expected, 2e-5, "eval_spectral")
    flipped = spectral_oracle(material, np.stack([uv[0], 1 - uv[1]]), view, light, wavelengths)
    assert np.max(np.abs(got - flipped)) > 0.05 * expected.max()
    rgb, _ = native.eval_uv(uv, view, light, pdf=False)
    close(rgb, srgb_matrix_oracle() @ eval_oracle(material, uv, view, light), 5e-4, "eval_uv")
    with pytest.raises(_native.NbrdfError, match="texture coordinates"):
        native.eval_spectral(view, light, wavelengths)


@pytest.mark.parametrize("variant, backend", [("scalar_spectral", "rust"), ("llvm_ad_spectral", "rust"),
                                              ("llvm_ad_spectral", "jit"), ("llvm_ad_spectral_polarized", "jit")])
def test_spectral_variants_evaluate_the_spectrum_at_the_hit(material, variant, backend, restore_variant):
    """eval, eval_pdf and sample's weight are f_r(lambda) cos (/ pdf) at the lane's wavelengths and
    UV (no uplift)."""
    use_variant(variant)
    view, light, u, wavelengths, uv = queries(24 if variant.startswith("scalar") else 200, 5)
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(material.path), "backend": backend})
    got = bsdf_calls(bsdf, view, light, u, wavelengths, uv)
    polarized = "polarized" in variant
    expected = spectral_oracle(material, uv, view, light, wavelengths)
    for key in ("eval", "eval_pdf.value"):
        close(unpolarized(got[key], polarized), expected, 1e-4, key)
    wo, pdf = got["sample.wo"].astype(np.float32), got["sample.pdf"]
    sampled = spectral_oracle(material, uv, view, wo, wavelengths)
    sampled = np.where(pdf > 0, sampled / np.where(pdf > 0, pdf, 1.0), 0.0)
    assert np.count_nonzero(pdf) > 0.5 * pdf.size
    close(unpolarized(got["sample.weight"], polarized), sampled, 1e-4, "sample.weight")


def test_rust_and_jit_agree_to_float32_precision(material, restore_variant):
    use_variant("llvm_ad_spectral")
    view, light, u, wavelengths, uv = queries(400, 7)
    got = {backend: bsdf_calls(mi.load_dict({"type": "nbrdf", "filename": str(material.path), "backend": backend}),
                               view, light, u, wavelengths, uv) for backend in ("rust", "jit")}
    # Sampled directions differ by float32 rounding, which the lobes' pdf and the weight amplify:
    # the tolerances of tests/test_textured_jit.py.
    for key, rtol in (("eval", 1e-5), ("eval_pdf.value", 1e-5), ("pdf", 1e-4), ("sample.pdf", 1e-3),
                      ("sample.weight", 2e-3)):
        close(got["jit"][key], got["rust"][key], rtol, key)
    np.testing.assert_allclose(got["jit"]["sample.wo"], got["rust"]["sample.wo"], atol=2e-5)


@pytest.mark.parametrize("variant, backend", [("scalar_rgb", "rust"), ("llvm_ad_rgb", "rust"),
                                              ("llvm_ad_rgb", "jit"), ("llvm_ad_mono", "jit")])
def test_rgb_and_mono_variants_render_the_projection(material, variant, backend, restore_variant):
    """RGB variants: M c cos with M the CIE projection (oracle); mono: its luminance."""
    use_variant(variant)
    view, light, u, wavelengths, uv = queries(24 if variant.startswith("scalar") else 200, 9)
    got = bsdf_calls(mi.load_dict({"type": "nbrdf", "filename": str(material.path), "backend": backend}),
                     view, light, u, wavelengths, uv)
    rgb = srgb_matrix_oracle() @ eval_oracle(material, uv, view, light)
    expected = LUMINANCE @ rgb if "mono" in variant else rgb
    for key in ("eval", "eval_pdf.value"):
        close(got[key].reshape(expected.shape), expected, 5e-4, key)


@pytest.mark.parametrize("backend", ["rust", "jit"])
def test_chi2_at_a_texel_in_a_spectral_variant(tmp_path, backend, restore_variant):
    """Mitsuba's chi^2 test of sample() against pdf() in llvm_ad_spectral at one texel."""
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain
    from test_spectral import _adapter
    from test_textured_plugin import TEXELS, _moderate_lobes

    use_variant("llvm_ad_spectral")
    material = write_textured(tmp_path / "m.nbrdf.json", texture=_moderate_lobes(3), channels=2, lobes=1,
                              spectral=SPECTRAL)
    params = {"type": "nbrdf", "filename": str(material.path), "backend": backend}
    wi = mi.Vector3f(float(np.sin(0.7)), 0.0, float(np.cos(0.7)))
    sample_func, pdf_func = _adapter("nbrdf", params, wi, (420.0, 530.0, 640.0, 780.0), uv=TEXELS[1])
    chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func, sample_dim=3,
                         sample_count=200_000, res=61)
    assert chi2.run(significance_level=0.01, test_count=2, quiet=True), chi2.messages


@pytest.mark.parametrize("variant, backend", [("scalar_spectral", "rust"), ("llvm_ad_spectral", "rust"),
                                              ("llvm_ad_spectral", "jit"), ("llvm_ad_spectral_polarized", "jit"),
                                              ("llvm_ad_mono", "jit")])
def test_renders_are_finite_and_deterministic(material, variant, backend, restore_variant):
    """Small renders, twice at one seed (the rust backend in wavefront mode in JIT variants)."""
    use_variant(variant)
    jit_variant = dr.is_jit_v(mi.Float)
    for flag in (dr.JitFlag.SymbolicLoops, dr.JitFlag.SymbolicCalls):
        if jit_variant:
            dr.set_flag(flag, backend == "jit")
    try:
        first, again = (render(material.path, seed=3, backend=backend) for _ in range(2))
    finally:
        for flag in (dr.JitFlag.SymbolicLoops, dr.JitFlag.SymbolicCalls):
            if jit_variant:
                dr.set_flag(flag, True)
    assert np.all(np.isfinite(first)) and first.max() > 0
    np.testing.assert_array_equal(first, again)


def test_distilling_gold_and_copper_by_a_mask_learns_their_spectra(tmp_path, capsys, restore_variant):
    """A blendbsdf of rough gold and copper by a 16 x 16 mask, distilled in llvm_ad_spectral: at
    texel centres and mirror pairs, the shape of the material's spectrum (each pair's values over
    400-700 nm divided by their mean) follows the source's, much closer than the texture read
    upside down or the material's RGB value uplifted as an RGB material's would be."""
    use_variant("llvm_ad_spectral")
    from nbrdf_mitsuba import _native, distill, jit

    side = 16
    y = (np.mgrid[0:side, 0:side][0] + 0.5) / side
    mask = tmp_path / "mask.exr"
    mi.Bitmap(np.ascontiguousarray((y > 0.6)[..., None], dtype=np.float32)).write(str(mask))
    spec = {"type": "blendbsdf", "weight": {"type": "bitmap", "filename": str(mask), "filter_type": "nearest"},
            "bsdf_0": {"type": "roughconductor", "material": "Au", "alpha": 0.3},
            "bsdf_1": {"type": "roughconductor", "material": "Cu", "alpha": 0.3}}
    source = tmp_path / "metals.json"
    source.write_text(json.dumps(spec))
    out = tmp_path / "metals.nbrdf.json"
    budget = ["--samples", "60000", "--epochs", "20", "--lobes", "0", "--seed", "1", "-q"]
    status = distill.main([str(source), "--spatial", "--variant", "llvm_ad_spectral", "-o", str(out), *budget])
    assert status == 0, capsys.readouterr().err
    document = json.loads(out.read_text())
    assert document["spectral"] == SPECTRAL and document["layers"][-1]["outputs"] == 16
    assert document["provenance"]["spectral_target"]["wavelengths"] == 48

    pairs, lam = 40, np.arange(400.0, 701.0, 20.0)
    rng = np.random.default_rng(3)
    texel = rng.integers(0, side * side, pairs)
    view, _ = random_pairs(pairs, seed=9, min_cos=0.3)
    light = view * np.array([[-1.0], [-1.0], [1.0]])
    # Each pair at every wavelength: one column per (pair, wavelength).
    uv, view, light = (np.repeat(a, lam.size, axis=1) for a in (
        np.stack([(texel % side + 0.5) / side, (texel // side + 0.5) / side]), view, light))
    wavelengths = np.tile(lam, pairs)[None]
    reference = bsdf_calls(mi.load_dict(spec), *(a.astype(np.float32) for a in (
        view, light, np.full(view.shape, 0.5), np.repeat(wavelengths, 4, axis=0))), uv=uv.astype(np.float32))["eval"][0]
    native = _native.Material(out)
    rgb, _ = native.eval_uv(uv, view, light, pdf=False)
    found = {"material": native.eval_spectral(view, light, wavelengths, uv=uv)[0],
             "flipped": native.eval_spectral(view, light, wavelengths, uv=np.stack([uv[0], 1 - uv[1]]))[0],
             "uplifted": np.asarray(jit.spectrum_from_rgb(mi.Color3f(rgb), mi.UnpolarizedSpectrum(
                 np.repeat(wavelengths, 4, axis=0))).numpy())[0]}

    def shape(values):
        rows = values.reshape(pairs, lam.size)
        return rows / rows.mean(axis=1, keepdims=True)

    errors = {name: float(np.mean(np.abs(shape(v) - shape(reference)))) for name, v in found.items()}
    # The material's shape error is about 0.013; the flipped and uplifted ones 0.08 to 0.10.
    assert errors["material"] < 0.03 and min(errors["flipped"], errors["uplifted"]) > 0.06, errors
    magnitude = np.mean(np.abs(found["material"] - reference)) / np.mean(reference)
    assert magnitude < 0.1, magnitude
