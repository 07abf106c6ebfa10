"""Spectral variants (issue 31): the RGB value of either BSDF, in either backend, is uplifted per
evaluation as Mitsuba uplifts unbounded RGB data. The reference is independent of the plugin: the
RGB variant's value, Mitsuba's own ``mi.srgb_model_fetch`` coefficients and the sigmoid
polynomial written out here in float64. Sampling and pdf do not see the wavelengths (chi^2 in a
spectral variant; the same draws at other wavelengths); bad wavelengths give 0."""

from __future__ import annotations

import nbrdf_mitsuba  # noqa: F401  (before mitsuba)
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from conftest import bsdf_calls, use_variant
from nbrdf_testing import random_pairs, write_merl, write_network

PHONG = {"sampling": "phong", "exponent": 40.0, "specular_weight": 0.6}
N = 48
CIE_MIN, CIE_MAX = 360.0, 830.0  # MI_CIE_MIN, MI_CIE_MAX (include/mitsuba/core/spectrum.h)
VALUES = ("eval", "eval_pdf.value", "sample.weight")
DENSITY = ("pdf", "eval_pdf.pdf", "sample.wo", "sample.pdf")


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("spectral")
    return {"nbrdf": write_network(folder / "n.nbrdf.json"), "merl": write_merl(folder / "m.binary")}


def _queries(n: int = N, seed: int = 5):
    view, light = random_pairs(n, seed)
    light[:, : n // 4] = view[:, : n // 4] * np.array([[-1.0], [-1.0], [1.0]])  # mirror pairs: peaks above 1
    rng = np.random.default_rng(seed + 1)
    u = rng.random((3, n))
    wavelengths = rng.uniform(CIE_MIN, CIE_MAX, (4, n))
    return [a.astype(np.float32) for a in (view, light, u, wavelengths)]


def sigmoid_polynomial(coeff: np.ndarray, wavelengths: np.ndarray) -> np.ndarray:
    """Jakob and Hanika's smooth spectrum, float64: S(x) = 1/2 + x / (2 sqrt(1 + x^2)),
    x = c0 l^2 + c1 l + c2 (``coeff``: (3, n); ``wavelengths``: (k, n), nanometres)."""
    x = (coeff[0] * wavelengths + coeff[1]) * wavelengths + coeff[2]
    return 0.5 + x / (2.0 * np.sqrt(1.0 + x * x))


def uplift_oracle(rgb: np.ndarray, wavelengths: np.ndarray) -> np.ndarray:
    """Mitsuba's uplift of unbounded RGB data (src/volumes/grid.cpp): scale = 2 max(rgb), the
    coefficients of rgb / scale from ``mi.srgb_model_fetch``, value = scale S(lambda)."""
    scale = 2.0 * rgb.max(axis=0)
    normalised = rgb / np.maximum(1e-8, scale)
    coeff = np.array([list(mi.srgb_model_fetch(mi.ScalarColor3f(*map(float, c)))) for c in normalised.T]).T
    return scale * sigmoid_polynomial(coeff.reshape(3, -1), wavelengths)


def _scene(plugin, files, backend):
    return {"type": plugin, "filename": str(files[plugin]), "backend": backend, **PHONG}


def _skip_scalar_jit(variant, backend):
    if backend == "jit" and variant.startswith("scalar"):
        pytest.skip("the jit backend needs a JIT variant")


def _rgb_variant(variant: str) -> str:
    return "scalar_rgb" if variant.startswith("scalar") else "llvm_ad_rgb"


@pytest.mark.parametrize("backend", ["rust", "jit"])
@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
@pytest.mark.parametrize("variant", ["scalar_spectral", "scalar_spectral_polarized", "llvm_ad_spectral",
                                     "llvm_ad_spectral_polarized"])
def test_spectral_value_is_the_uplift_of_the_rgb_value(variant, plugin, backend, files, restore_variant):
    """Polarized: the depolarizer times that value ([0, 0], zeros elsewhere)."""
    use_variant(variant)
    _skip_scalar_jit(variant, backend)
    queries = _queries()
    got = bsdf_calls(mi.load_dict(_scene(plugin, files, backend)), *queries)
    mi.set_variant(_rgb_variant(variant))
    rgb = bsdf_calls(mi.load_dict(_scene(plugin, files, backend)), *queries)
    assert max(np.max(rgb[key]) for key in VALUES) > 1.0  # values above 1: the unbounded case matters
    for key in DENSITY:
        np.testing.assert_array_equal(got[key], rgb[key], err_msg=key)
    for key in VALUES:
        value = got[key]
        if "polarized" in variant:
            assert value.shape[:2] == (4, 4), key
            rest = value.copy()
            rest[0, 0] = 0.0
            assert np.all(rest == 0.0), key
            value = value[0, 0]
        expected = uplift_oracle(rgb[key], queries[3].astype(np.float64))
        assert value.shape == expected.shape, key
        scale = 2.0 * rgb[key].max(axis=0)
        # float32 coefficients and sigmoid against float64: relative to the scale of each value.
        assert np.all(np.abs(value - expected) <= 1e-4 * scale + 1e-7), (
            key, np.max(np.abs(value - expected) / np.maximum(scale, 1e-12)))


BAD = [float("nan"), float("inf"), float("-inf"), 0.0, -500.0, 359.0, 831.0, 1e30]


@pytest.mark.parametrize("backend", ["rust", "jit"])
@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
@pytest.mark.parametrize("variant", ["scalar_spectral", "llvm_ad_spectral"])
def test_bad_wavelengths_give_zero(variant, plugin, backend, files, restore_variant):
    """Non-finite or outside [MI_CIE_MIN, MI_CIE_MAX]: 0, never NaN; good wavelengths beside them
    in the same spectrum keep their values, and the density is untouched."""
    use_variant(variant)
    _skip_scalar_jit(variant, backend)
    view, light, u, good = _queries(len(BAD), seed=9)
    wavelengths = good.copy()
    wavelengths[1] = BAD  # one bad wavelength per column, three good ones
    bsdf = mi.load_dict(_scene(plugin, files, backend))
    got, reference = bsdf_calls(bsdf, view, light, u, wavelengths), bsdf_calls(bsdf, view, light, u, good)
    for key in VALUES:
        assert np.all(np.isfinite(got[key])), key
        assert np.all(got[key][1] == 0.0), key
        np.testing.assert_array_equal(got[key][[0, 2, 3]], reference[key][[0, 2, 3]], err_msg=key)
        assert np.max(reference[key][1]) > 0, key
    for key in DENSITY:
        np.testing.assert_array_equal(got[key], reference[key], err_msg=key)


def test_traced_fetch_is_mitsubas(restore_variant):
    """The per-lane coefficient lookup of JIT variants against ``mi.srgb_model_fetch`` (Mitsuba's
    scalar function), on colours that reach every branch: grey, black, one or two zero
    components, ties for the largest, values above 1 (clamped), the 0.5 maximum of the uplift."""
    use_variant("llvm_ad_spectral")
    from nbrdf_mitsuba import jit

    rng = np.random.default_rng(3)
    c = rng.random((3, 600))
    c[:, :60] = c[0, :60]
    c[:, 60:120] *= rng.random((3, 60)) > 0.5
    c[:, 120:240] = 0.5 * c[:, 120:240] / c[:, 120:240].max(axis=0)
    c[:, 240:300] *= 3.0
    c[:, 300:320] = 0.0
    c[1, 320:360] = c[0, 320:360]
    c = c.astype(np.float32)
    got = np.asarray(jit.srgb_model().fetch(mi.Color3f(c)).numpy(), np.float64)
    expected = np.array([list(mi.srgb_model_fetch(mi.ScalarColor3f(*map(float, col)))) for col in c.T]).T
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6)


def _adapter(plugin, params, wi, wavelengths, uv=None):
    """mitsuba.chi2.BSDFAdapter with wavelengths set: its zero-wavelength interactions would zero
    every sampled weight (wavelengths outside the visible range give 0) and discard the samples;
    ``uv``: the hit's texture coordinates (default 0)."""
    def interaction(n):
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = wi
        si.wavelengths = mi.UnpolarizedSpectrum(*wavelengths)
        if uv is not None:
            si.uv = mi.Point2f(*uv)
        return si

    def sample_func(sample, *args):
        bsdf = mi.load_dict(params)
        bs, weight = bsdf.sample(mi.BSDFContext(), interaction(dr.width(sample)), sample[0],
                                 mi.Point2f(sample[1], sample[2]))
        w = dr.full(mi.Float, 1.0, dr.width(weight))
        w[dr.all(weight == 0)] = 0
        return bs.wo, w

    def pdf_func(wo, *args):
        return mi.load_dict(params).pdf(mi.BSDFContext(), interaction(dr.width(wo)), wo)

    return sample_func, pdf_func


@pytest.mark.parametrize("backend", ["rust", "jit"])
@pytest.mark.parametrize("plugin, sampling", [("nbrdf", "phong"), ("merl", "tabulated")])
def test_chi2_in_a_spectral_variant(plugin, sampling, backend, files, restore_variant):
    """Mitsuba's chi^2 test of sample() against pdf() in llvm_ad_spectral."""
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    use_variant("llvm_ad_spectral")
    params = {"type": plugin, "filename": str(files[plugin]), "backend": backend, "sampling": sampling}
    if sampling == "phong":
        params.update(exponent=60.0, specular_weight=0.7)
    for theta in (0.3, 1.2):
        wi = mi.Vector3f(float(np.sin(theta)), 0.0, float(np.cos(theta)))
        sample_func, pdf_func = _adapter(plugin, params, wi, (450.0, 550.0, 650.0, 750.0))
        chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                             sample_dim=3, sample_count=100_000, res=41)
        assert chi2.run(significance_level=0.01, test_count=8, quiet=True), (
            f"{plugin}/{sampling}/{backend} at theta_i = {theta}: {chi2.messages}")


@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
def test_veach_renders_follow_the_rgb_render(plugin, files, restore_variant):
    """The Veach scene, tiny (nbrdf_tools.pages.variants's renders): llvm_ad_mono is the luminance
    of llvm_ad_rgb at the same seed (direct lighting is linear in the BSDF value and the lights
    are grey), llvm_ad_spectral_polarized is llvm_ad_spectral, and no image has NaN."""
    from nbrdf_tools.pages.variants import render_variant
    from test_variants import LUMINANCE  # written out from Mitsuba's definition there

    for variant in ("llvm_ad_rgb", "llvm_ad_mono", "llvm_ad_spectral", "llvm_ad_spectral_polarized"):
        use_variant(variant)
    bsdf = {"type": plugin, "filename": str(files[plugin])}
    images = {v: render_variant(v, bsdf, (24, 16), 4, seed=0)[0]
              for v in ("llvm_ad_rgb", "llvm_ad_mono", "llvm_ad_spectral", "llvm_ad_spectral_polarized")}
    for variant, image in images.items():
        assert np.all(np.isfinite(image)) and image.max() > 0, variant
    luminance = images["llvm_ad_rgb"] @ LUMINANCE
    np.testing.assert_allclose(images["llvm_ad_mono"][..., 0], luminance, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(images["llvm_ad_spectral_polarized"], images["llvm_ad_spectral"], rtol=1e-5, atol=1e-6)
