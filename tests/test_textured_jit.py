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
from textured_fixture import (eval_oracle, lobe_parameters, pdf_oracle, random_decoder, random_texture, render,
                              write_textured)

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
    float32 rounding of the sampled directions. A rust-backed BSDF called in symbolic mode
    renders with its twin, the jit backend's kernels."""
    material = write_textured(tmp_path / "m.nbrdf.json", texture=random_texture(5, 4, 3, 1, seed=4))
    images = {}
    for backend, symbolic in (("rust", False), ("jit", True), ("rust", True)):
        dr.set_flag(dr.JitFlag.SymbolicLoops, symbolic)
        dr.set_flag(dr.JitFlag.SymbolicCalls, symbolic)
        scene = mi.load_dict(veach_like({"type": "nbrdf", "filename": str(material.path), "backend": backend}))
        images[backend, symbolic] = np.array(mi.render(scene, seed=7))
    a, b = images["rust", False], images["jit", True]
    assert np.all(np.isfinite(b)) and a.mean() > 0
    assert np.abs(a - b).mean() <= 1e-3 * a.mean(), (np.abs(a - b).mean(), a.mean())
    np.testing.assert_array_equal(images["rust", True], b)


# ---------------------------------------------------------------------------------------------
# traverse, updates and gradients


def _layers_of(flat: np.ndarray, layers: list) -> list:
    out, offset = [], 0
    for W, b in layers:
        out.append((flat[offset:offset + W.size].reshape(W.shape), flat[offset + W.size:offset + W.size + b.size]))
        offset += W.size + b.size
    return out


def test_traverse_exposes_the_texture_and_the_decoder(llvm_variant, tmp_path):
    material = write_textured(tmp_path / "m.nbrdf.json", texture=random_texture(5, 4, 3, 2), lobes=2)
    for jit_weights, differentiable in (("auto", False), ("opaque", True)):
        params = mi.traverse(mi.load_dict({"type": "nbrdf", "filename": str(material.path), "jit_weights": jit_weights}))
        assert set(params.keys()) == {"latent", "lobes", "weights"}
        np.testing.assert_array_equal(np.array(params["latent"]), material.texture[..., :3])
        np.testing.assert_array_equal(np.array(params["lobes"]), material.texture[..., 3:])
        flat = np.concatenate([np.concatenate([W.ravel(), b]) for W, b in material.layers])
        np.testing.assert_array_equal(np.array(params["weights"]), flat)
        fixed = {key: bool(params.flags(key) & mi.ParamFlags.NonDifferentiable) for key in params.keys()}
        assert fixed == {"latent": False, "lobes": True, "weights": not differentiable}
    rust = mi.load_dict({"type": "nbrdf", "filename": str(material.path), "backend": "rust"})
    assert len(mi.traverse(rust).keys()) == 0  # the library's material is immutable


def test_updates_reach_the_kernels_and_bad_ones_are_refused(llvm_variant, tmp_path):
    """New codes, lobes and weights evaluate as the oracle of the updated material; a wrong shape
    or a non-finite value is refused naming what is wrong, and the BSDF keeps its last good
    parameters (in the traversed values too)."""
    material = write_textured(tmp_path / "m.nbrdf.json", texture=random_texture(5, 4, 3, 1), lobes=1)
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(material.path)})
    params = mi.traverse(bsdf)
    view, light, u = _queries(200, 41)
    uv = hits(view.shape[1], 42, huge=False)

    def agrees():
        got = bsdf_calls(bsdf, view, light, u, uv=uv)
        np.testing.assert_allclose(got["eval"], eval_oracle(material, uv, view, light), rtol=3e-6, atol=1e-6)
        np.testing.assert_allclose(got["pdf"], pdf_oracle(material, uv, view, light), rtol=1e-4, atol=1e-6)

    rng = np.random.default_rng(43)
    material.texture = random_texture(5, 4, 3, 1, seed=44)
    flat = np.array(params["weights"]) * rng.uniform(0.8, 1.2, dr.width(params["weights"])).astype(np.float32)
    material.layers = _layers_of(flat, material.layers)
    params["latent"] = mi.TensorXf(material.texture[..., :3])
    params["lobes"] = mi.TensorXf(material.texture[..., 3:])
    params["weights"] = mi.Float(flat)
    params.update()
    agrees()
    bad_updates = [
        ("latent", mi.TensorXf(np.zeros((4, 6, 3), np.float32)), r'"latent" has shape \(4, 6, 3\), expected \(4, 5, 3\)'),
        ("lobes", mi.TensorXf(np.zeros((4, 5, 1), np.float32)), r'"lobes" has shape \(4, 5, 1\), expected \(4, 5, 2\)'),
        ("latent", mi.TensorXf(np.where(np.arange(60).reshape(4, 5, 3) == 7, np.nan, 0.5).astype(np.float32)),
         r'"latent" texel \(x 2, y 0\) channel 1 is NaN'),
        ("weights", mi.Float(np.where(np.arange(flat.size) == 20, np.inf, flat).astype(np.float32)),
         r'"weights" value 20 \(layer 1 weight 20\) is \+inf'),
    ]
    for key, value, message in bad_updates:
        params["latent"] = mi.TensorXf(np.zeros((4, 5, 3), np.float32))  # a good value in the same update
        params[key] = value
        with pytest.raises(Exception, match="update rejected, the BSDF keeps its previous parameters: " + message):
            params.update()
        np.testing.assert_array_equal(np.array(params["latent"]), material.texture[..., :3])
        np.testing.assert_array_equal(np.array(params["weights"]), flat)
        agrees()


def test_prb_gradients_reach_the_texture_and_the_decoder(llvm_variant, tmp_path):
    """prb's gradients of a render reach the latent codes and the decoder's weights (opaque), and
    match central differences of the render (same seed) in one texel's code."""
    material = write_textured(tmp_path / "m.nbrdf.json", layers=random_decoder(3, hidden=8),
                              texture=random_texture(5, 4, 3, 1, seed=4))
    scene = veach_like({"type": "nbrdf", "filename": str(material.path), "jit_weights": "opaque"}, spp=32)
    scene["integrator"] = {"type": "prb", "max_depth": 3}
    scene = mi.load_dict(scene)
    params = mi.traverse(scene)
    latent, weights = (next(k for k in params.keys() if k.endswith(name)) for name in (".latent", ".weights"))
    dr.enable_grad(params[latent])
    dr.enable_grad(params[weights])
    params.update()
    dr.backward(dr.mean(mi.render(scene, params, seed=1, seed_grad=2), axis=None))
    g_latent, g_weights = np.array(dr.grad(params[latent])), np.array(dr.grad(params[weights]))
    assert np.all(np.isfinite(g_latent)) and np.all(np.isfinite(g_weights))
    assert np.count_nonzero(g_latent) > g_latent.size // 2 and np.count_nonzero(g_weights) > g_weights.size // 2
    y, x, k = np.unravel_index(np.argmax(np.abs(g_latent)), g_latent.shape)
    dr.disable_grad(params[latent])
    dr.disable_grad(params[weights])
    codes, eps, renders = np.array(params[latent]), 1e-2, []
    for step in (eps, -eps):
        moved = codes.copy()
        moved[y, x, k] += step
        params[latent] = mi.TensorXf(moved)
        params.update()
        renders.append(np.mean(np.array(mi.render(scene, seed=1)), dtype=np.float64))
    assert (renders[0] - renders[1]) / (2 * eps) == pytest.approx(g_latent[y, x, k], rel=0.05)


def test_a_wide_decoder_goes_to_the_rust_backend(llvm_variant, tmp_path):
    """As a wide network: ``auto`` takes the library (and says so), ``jit`` is refused."""
    from nbrdf_mitsuba.bsdf import JIT_MAX_HIDDEN_WIDTH

    material = write_textured(tmp_path / "m.nbrdf.json", layers=random_decoder(3, hidden=JIT_MAX_HIDDEN_WIDTH + 8))
    assert "backend = rust" in str(mi.load_dict({"type": "nbrdf", "filename": str(material.path)}))
    with pytest.raises(Exception, match=f"hidden width {JIT_MAX_HIDDEN_WIDTH + 8} is above {JIT_MAX_HIDDEN_WIDTH}"):
        mi.load_dict({"type": "nbrdf", "filename": str(material.path), "backend": "jit"})
