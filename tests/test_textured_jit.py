"""Spatially varying materials (issue 61) in JIT variants: the traced twin
(``nbrdf_mitsuba.jit.textured``) against the library (C ABI) to float32 precision, its chi^2 at
texels, renders in every variant, and ``traverse``: updates of the texture and the decoder, their
validation, and gradients with ``prb``."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from conftest import bsdf_calls, use_variant
from nbrdf_testing import f32, grazing_pairs, random_pairs, sph
from test_backends import veach_like
from test_textured_plugin import SKEW, TEXELS, _moderate_lobes, column, hits
from textured_fixture import lobe_parameters, random_texture, render, write_textured

LUMINANCE = np.array([0.212671, 0.715160, 0.072169])  # Mitsuba's luminance (tests/test_variants.py)


def test_exact_remainders_of_float32_integers_of_any_size(llvm_variant):
    """The traced texel wrap's remainder against Python's integers, over float32's whole range."""
    from nbrdf_mitsuba.jit.textured import _rem_euclid

    rng = np.random.default_rng(1)
    x = np.floor((rng.uniform(-1, 1, 50_000) * 10.0 ** rng.uniform(0, 38.5, 50_000)).astype(np.float32))
    x[:6] = [0.0, -1.0, 2.0**24 + 2, -(2.0**53), 3.4e38, -3.4e38]
    for m in (1, 3, 7, 4096, 16383, 32768):
        got = _rem_euclid(mi.Float(x), m).numpy()
        np.testing.assert_array_equal(got, [int(v) % m for v in x.astype(np.float64)], err_msg=f"mod {m}")


def _queries(n: int, seed: int):
    view, light = random_pairs(n, seed)
    g_view, g_light = grazing_pairs(n // 4, seed + 1)
    view, light = f32(np.concatenate([view, g_view], axis=1)), f32(np.concatenate([light, g_light], axis=1))
    u = np.random.default_rng(seed + 2).random((3, view.shape[1])).astype(np.float32)
    u[:, :4] = [[0, 1, 0, 1], [0, 1, 1, 0], [0, 1, 0.5, 1]]  # interval ends
    return view, light, u


@pytest.mark.parametrize("lobes", [0, 1, 2])
@pytest.mark.parametrize("filter_", ["bilinear", "nearest"])
@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp"])
def test_traced_twin_matches_the_library(jit_variant, tmp_path, wrap, filter_, lobes):
    """eval, pdf and sample of the jit backend against the C ABI at random and grazing
    directions and UVs near, outside and far outside [0, 1] (1e6, 1e30), not finite, over NaN and
    inf texels, with and without a to_uv, to float32 precision."""
    from nbrdf_mitsuba import _native

    texture = random_texture(7, 3, 4, lobes, seed=3)
    texture[1, 2, 1] = np.nan
    texture[2, 5, 4 if lobes else 0] = np.inf
    view, light, u = _queries(3000, 21)
    n = view.shape[1]
    for to_uv in (None, SKEW):
        material = write_textured(tmp_path / "m.nbrdf.json", texture=texture, channels=4, lobes=lobes, wrap=wrap,
                                  filter=filter_, to_uv=to_uv, precision="float32")
        native = _native.Material(material.path)
        bsdf = mi.load_dict({"type": "nbrdf", "filename": str(material.path), "backend": "jit"})
        uv = hits(n, 5)
        got = bsdf_calls(bsdf, view, light, u, uv=uv)
        rgb, pdf = native.eval_uv(uv, view, light)
        wo, weight, sample_pdf = native.sample_uv(uv, view, u)
        for key in got:
            assert np.all(np.isfinite(got[key])), key
        a, b = rgb, got["eval"]
        assert np.all(np.abs(a - b) <= 1e-5 * (1 + np.abs(a))), np.max(np.abs(a - b))
        np.testing.assert_array_equal(got["eval_pdf.value"], b)
        np.testing.assert_allclose(got["pdf"], pdf, rtol=1e-4, atol=1e-7)
        np.testing.assert_array_equal(got["eval_pdf.pdf"], got["pdf"])
        valid = sample_pdf > 0
        np.testing.assert_array_equal(got["sample.pdf"] > 0, valid)
        np.testing.assert_allclose(got["sample.wo"][:, valid], wo[:, valid], atol=2e-5)
        np.testing.assert_allclose(got["sample.pdf"][valid], sample_pdf[valid], rtol=1e-3)
        np.testing.assert_allclose(got["sample.weight"][:, valid], weight[:, valid], rtol=2e-3, atol=1e-5)
        assert np.all(got["sample.weight"][:, ~valid] == 0)


@pytest.mark.parametrize("backend", ["jit", "rust"])
@pytest.mark.parametrize("uv", TEXELS)
def test_chi2_at_texels(llvm_variant, tmp_path, backend, uv):
    """Mitsuba's chi^2 test of sample() against pdf() at a texel, for both backends."""
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    material = write_textured(tmp_path / "m.nbrdf.json", texture=_moderate_lobes(3), channels=2, lobes=1)
    xml = f'<string name="filename" value="{material.path}"/><string name="backend" value="{backend}"/>'
    for theta in (0.2, 1.1):
        wi = mi.Vector3f(float(np.sin(theta)), 0.0, float(np.cos(theta)))
        sample_func, pdf_func = BSDFAdapter("nbrdf", xml, wi=wi, uv=list(uv))
        chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func, sample_dim=3,
                             sample_count=200_000, res=61)
        assert chi2.run(significance_level=0.01, test_count=2 * len(TEXELS) * 2, quiet=True), (
            f"{backend} at uv {uv}, theta_i = {theta}: {chi2.messages}")


def test_chi2_fails_against_another_texels_pdf(llvm_variant, tmp_path):
    """The chi^2 test above can fail: samples drawn at one texel against the pdf at another."""
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    material = write_textured(tmp_path / "m.nbrdf.json", texture=_moderate_lobes(3), channels=2, lobes=1)
    xml = f'<string name="filename" value="{material.path}"/>'
    wi = mi.Vector3f(float(np.sin(0.5)), 0.0, float(np.cos(0.5)))
    sample_func, _ = BSDFAdapter("nbrdf", xml, wi=wi, uv=list(TEXELS[0]))
    _, pdf_func = BSDFAdapter("nbrdf", xml, wi=wi, uv=list(TEXELS[1]))
    chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func, sample_dim=3,
                         sample_count=200_000, res=61)
    assert not chi2.run(significance_level=0.01, test_count=1, quiet=True)


@pytest.mark.parametrize("backend", ["jit", "rust"])
def test_pdf_integrates_to_the_lobes_mass_above_the_horizon(llvm_variant, tmp_path, backend):
    """As the scalar test, on a finer grid, at three texels in one wavefront."""
    material = write_textured(tmp_path / "m.nbrdf.json", texture=_moderate_lobes(5), channels=2, lobes=1)
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(material.path), "backend": backend})
    n_t, n_p = 200, 96
    t = (np.arange(n_t) + 0.5) / n_t
    alpha, d_alpha = np.pi / 2 * t**2, np.pi * t / n_t
    A, P = np.meshgrid(alpha, (np.arange(n_p) + 0.5) / n_p * 2 * np.pi, indexing="ij")
    light = f32(sph(A.ravel(), P.ravel()))
    m = light.shape[1]
    for uv in TEXELS:
        got = bsdf_calls(bsdf, column([0.0, 0.0, 1.0], m), light, np.zeros((3, m)), uv=column(uv, m))
        integral = np.sum(got["pdf"].reshape(n_t, n_p) * np.sin(A) * d_alpha[:, None] * (2 * np.pi / n_p))
        n1, w1, _, _ = lobe_parameters(material, column(uv, 1))[0]
        assert integral == pytest.approx(1 - w1 * np.sqrt(0.5) ** (n1 + 1), abs=1e-3)


# ---------------------------------------------------------------------------------------------
# Variants and renders

VARIANTS = ["scalar_mono", "llvm_ad_mono", "scalar_rgb_polarized", "llvm_ad_rgb_polarized", "llvm_ad_mono_polarized",
            "scalar_spectral", "scalar_spectral_polarized", "llvm_ad_spectral", "llvm_ad_spectral_polarized"]


@pytest.mark.parametrize("backend", ["jit", "rust"])
@pytest.mark.parametrize("variant", VARIANTS)
def test_values_follow_the_rgb_variant(tmp_path, variant, backend, restore_variant):
    """The decoder's RGB value as each variant has it (as for RGB networks, tests/test_variants.py
    and tests/test_spectral.py): monochrome, its luminance; spectral, Mitsuba's uplift at the
    lane's wavelengths; polarized, the depolarizer times that (the value at [0, 0], zero
    elsewhere). Pdfs and sampled directions as in the RGB variant."""
    from test_spectral import CIE_MAX, CIE_MIN, uplift_oracle

    use_variant(variant)
    if backend == "jit" and variant.startswith("scalar"):
        pytest.skip("the jit backend needs a JIT variant")
    material = write_textured(tmp_path / "m.nbrdf.json", lobes=2, texture=random_texture(5, 4, 3, 2))
    view, light, u = _queries(64, 31)
    uv = hits(view.shape[1], 6)
    wavelengths = np.random.default_rng(7).uniform(CIE_MIN, CIE_MAX, (4, view.shape[1])).astype(np.float32)
    scene = {"type": "nbrdf", "filename": str(material.path), "backend": backend}
    got = bsdf_calls(mi.load_dict(scene), view, light, u, wavelengths, uv=uv)
    mi.set_variant("scalar_rgb" if variant.startswith("scalar") else "llvm_ad_rgb")
    rgb = bsdf_calls(mi.load_dict(scene), view, light, u, uv=uv)
    assert np.max(rgb["eval"]) > 0
    for key in ("pdf", "eval_pdf.pdf", "sample.wo", "sample.pdf"):
        np.testing.assert_allclose(got[key], rgb[key], rtol=1e-6, atol=1e-7, err_msg=key)
    for key in ("eval", "eval_pdf.value", "sample.weight"):
        value, expected = got[key], rgb[key]
        if "polarized" in variant:
            off_diagonal = value.copy()
            off_diagonal[0, 0] = 0.0
            assert np.all(off_diagonal == 0.0), key
            value = value[0, 0]
        if "mono" in variant:
            np.testing.assert_allclose(value, (LUMINANCE @ expected)[None], rtol=1e-5, atol=1e-7, err_msg=key)
        elif "spectral" in variant:
            scale = 2.0 * expected.max(axis=0)
            uplifted = uplift_oracle(expected, wavelengths.astype(np.float64))
            assert np.all(np.abs(value - uplifted) <= 1e-4 * scale + 1e-7), key
        else:
            np.testing.assert_allclose(value, expected, rtol=1e-5, atol=1e-7, err_msg=key)


@pytest.mark.parametrize("variant", ["llvm_ad_rgb", "llvm_ad_mono", "llvm_ad_spectral", "llvm_ad_spectral_polarized"])
def test_jit_renders_are_finite_and_deterministic(tmp_path, variant, restore_variant):
    """Renders over NaN and inf texels read far outside [0, 1]: finite, the same for a seed."""
    use_variant(variant)
    texture = random_texture(5, 4, 3, 1, seed=2)
    texture[1, 1, 0], texture[2, 3, 2] = np.nan, np.inf
    for to_uv in (None, [[1e6, 0, 0], [0, 1e6, 0], [0, 0, 1]]):
        material = write_textured(tmp_path / "m.nbrdf.json", texture=texture, to_uv=to_uv, wrap="mirror")
        image = render(material.path, seed=3, size=16)
        assert np.all(np.isfinite(image)) and image.max() > 0
        np.testing.assert_array_equal(render(material.path, seed=3, size=16), image)


def test_renders_of_both_backends_match(llvm_variant, tmp_path):
    """The library in wavefront mode and the twin, at equal seed and spp: the same paths up to
    float32 rounding of the sampled directions."""
    material = write_textured(tmp_path / "m.nbrdf.json", texture=random_texture(5, 4, 3, 1, seed=4))
    images = {}
    for backend in ("rust", "jit"):
        dr.set_flag(dr.JitFlag.SymbolicLoops, backend == "jit")
        dr.set_flag(dr.JitFlag.SymbolicCalls, backend == "jit")
        scene = mi.load_dict(veach_like({"type": "nbrdf", "filename": str(material.path), "backend": backend}))
        images[backend] = np.array(mi.render(scene, seed=7))
    a, b = images["rust"], images["jit"]
    assert np.all(np.isfinite(b)) and a.mean() > 0
    assert np.abs(a - b).mean() <= 1e-3 * a.mean(), (np.abs(a - b).mean(), a.mean())
