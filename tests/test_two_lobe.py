"""The two-lobe sampling mixture ``w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine``
(``sampling = "two_lobe"``) through the plugins: Mitsuba's chi^2 test in both backends (full
sphere, and zoomed on a stiff lobe at normal and grazing views), the pdf against a NumPy
float64 oracle, the file's stored lobes as the default, and atomic parameter updates."""

from __future__ import annotations

import json
import math

import mitsuba as mi
import numpy as np
import pytest

from nbrdf_testing import bsdf_eval_pdf, bsdf_pdf, bsdf_sample, f32, is_jit, phong_pdf, random_pairs
from test_hardening_plugin import MirrorConeDomain, _value

TWO_LOBE = {"exponent": 60.0, "specular_weight": 0.3, "exponent2": 8.0, "specular_weight2": 0.4}


def two_lobe_oracle(view, light, n1, w1, n2, w2):
    """float64 NumPy density: the one-lobe oracle's specular terms (weight 1) and cosine."""
    cosine = phong_pdf(view, light, 0.0, 0.0)
    return w1 * phong_pdf(view, light, n1, 1.0) + w2 * phong_pdf(view, light, n2, 1.0) + (1 - w1 - w2) * cosine


def description(plugin, path, backend, **lobes):
    return {"type": plugin, "filename": str(path), "backend": backend, "sampling": "two_lobe", **lobes}


@pytest.mark.parametrize("backend", ["rust", "jit"])
@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
def test_chi2_full_sphere(llvm_variant, backend, plugin, network_file, merl_table):
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    path = network_file if plugin == "nbrdf" else merl_table
    # Grazing views are in the zoomed test: on the full sphere, the pdf's cut at the horizon is
    # beyond what the grid integrates (as in test_sampling.py's chi^2 test).
    for theta in (0.1, 0.7, 1.3):
        wi = mi.Vector3f(float(np.sin(theta)), 0.0, float(np.cos(theta)))
        sample_func, pdf_func = BSDFAdapter(plugin, description(plugin, path, backend, **TWO_LOBE), wi=wi)
        chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                             sample_dim=3, sample_count=200_000, res=61)
        assert chi2.run(significance_level=0.01, test_count=12, quiet=True), (
            f"{plugin}/{backend} at theta_i = {theta}: {chi2.messages}")


def _zoomed_two_lobe_chi2(path, backend, theta, n1, pdf_n1=None):
    """The stiff lobe (n1, weight 0.5) over a broad one (n2 = 50, weight 0.3) in a cone around
    the mirror direction: the broad lobe and cosine put a small, nearly flat density there."""
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest

    view = np.array([math.sin(theta), 0.0, math.cos(theta)])
    domain = MirrorConeDomain(view, t_max=40.0 / n1)
    lobes = {"exponent": n1, "specular_weight": 0.5, "exponent2": 50.0, "specular_weight2": 0.3}
    wi = mi.Vector3f(*map(float, view))
    sample_func, pdf_func = BSDFAdapter("merl", description("merl", path, backend, **lobes), wi=wi)
    if pdf_n1 is not None:
        _, pdf_func = BSDFAdapter("merl", description("merl", path, backend, **{**lobes, "exponent": pdf_n1}), wi=wi)
    sample_func, pdf_func = domain.adapt(sample_func, pdf_func)
    chi2 = ChiSquareTest(domain=domain, sample_func=sample_func, pdf_func=pdf_func, sample_dim=3,
                         sample_count=300_000, res=31, ires=10)
    return chi2.run(significance_level=0.01, test_count=8, quiet=True), chi2.messages


@pytest.mark.parametrize("backend", ["rust", "jit"])
@pytest.mark.parametrize("theta", [0.4, 1.45])
def test_stiff_lobe_passes_zoomed_chi2(llvm_variant, merl_table, backend, theta):
    ok, messages = _zoomed_two_lobe_chi2(merl_table, backend, theta, 1e4)
    assert ok, messages


@pytest.mark.parametrize("backend", ["rust", "jit"])
def test_zoomed_chi2_detects_a_five_percent_error_in_the_stiff_exponent(llvm_variant, merl_table, backend):
    ok, _ = _zoomed_two_lobe_chi2(merl_table, backend, 0.4, 0.95e4, pdf_n1=1e4)
    assert not ok


def test_pdf_matches_the_float64_oracle_in_both_backends(variant, merl_table):
    lobes = {"exponent": 2000.0, "specular_weight": 0.35, "exponent2": 15.0, "specular_weight2": 0.45}
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "two_lobe", **lobes})
    view, light = (f32(a) for a in random_pairs(400 if is_jit() else 40, 23))
    # Add lights near the mirror directions, where the stiff lobe lives.
    mirror = view * np.array([[-1.0], [-1.0], [1.0]]) + 0.01 * np.random.default_rng(2).normal(size=view.shape)
    view, light = np.concatenate([view, view], axis=1), f32(np.concatenate([light, mirror], axis=1))
    want = two_lobe_oracle(view.astype(np.float64), light.astype(np.float64), 2000.0, 0.35, 15.0, 0.45)
    np.testing.assert_allclose(bsdf_pdf(bsdf, view, light), want, rtol=2e-4, atol=1e-6)


def test_sample_is_consistent_with_pdf(variant, merl_table):
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "two_lobe",
                         "exponent": 1e4, "specular_weight": 0.4, "exponent2": 30.0, "specular_weight2": 0.4})
    n = 600 if is_jit() else 40
    rng = np.random.default_rng(5)
    theta = np.arccos(rng.uniform(0.02, 1, n))
    view = np.stack([np.sin(theta), np.zeros(n), np.cos(theta)])
    u = rng.uniform(0, 1, (3, n))
    u[:, :4] = [[0, 1, 0.4, 0.8], [0, 1, 1, 0], [0, 1, 0.5, 1]]  # interval ends, lobe boundaries
    wo, weight, pdf, _ = bsdf_sample(bsdf, f32(view), u)
    assert np.all(np.isfinite(wo)) and np.all(np.isfinite(weight)) and np.all(pdf >= 0)
    valid = pdf > 0
    assert valid.mean() > 0.5
    _, pdf_again = bsdf_eval_pdf(bsdf, f32(view[:, valid]), f32(wo[:, valid]))
    np.testing.assert_allclose(pdf_again, pdf[valid], rtol=2e-4)


def _two_lobe_file(network_file, tmp_path, second=(40.0, 0.3)):
    data = json.loads(network_file.read_text())
    data["sampling"] = {"model": "blinn-phong", "exponent": 900.0, "specular_weight": 0.5, "source": "manual"}
    if second is not None:
        data["sampling"]["second_lobe"] = {"exponent": second[0], "specular_weight": second[1]}
    path = tmp_path / ("two.nbrdf.json" if second else "one.nbrdf.json")
    path.write_text(json.dumps(data))
    return path


def test_default_sampling_is_what_the_file_stores(variant, network_file, tmp_path):
    two = mi.load_dict({"type": "nbrdf", "filename": str(_two_lobe_file(network_file, tmp_path))})
    assert "sampling = two_lobe" in str(two) and "exponent2 = 40" in str(two)
    one = mi.load_dict({"type": "nbrdf", "filename": str(_two_lobe_file(network_file, tmp_path, None))})
    assert "sampling = phong" in str(one) and "exponent2" not in str(one)
    view, light = (f32(a) for a in random_pairs(64 if is_jit() else 8, 4))
    np.testing.assert_allclose(bsdf_pdf(two, view, light), two_lobe_oracle(view, light, 900.0, 0.5, 40.0, 0.3),
                               rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(bsdf_pdf(one, view, light), phong_pdf(view, light, 900.0, 0.5), rtol=2e-4, atol=1e-6)
    # "phong" on a two-lobe file samples its first lobe with cosine.
    first = mi.load_dict({"type": "nbrdf", "filename": str(_two_lobe_file(network_file, tmp_path)),
                          "sampling": "phong"})
    np.testing.assert_allclose(bsdf_pdf(first, view, light), phong_pdf(view, light, 900.0, 0.5), rtol=2e-4, atol=1e-6)


def test_second_lobe_updates_are_validated_atomically(variant, merl_table):
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "two_lobe", **TWO_LOBE})
    params = mi.traverse(bsdf)
    view, light = (f32(a) for a in random_pairs(32 if is_jit() else 4, 9))
    before = bsdf_pdf(bsdf, view, light)
    for key, value in [("specular_weight2", 0.8), ("exponent2", float("nan")), ("exponent2", 2e6),
                       ("specular_weight2", -0.1)]:
        params[key] = _value(value)
        params["exponent"] = _value(77.0)  # a valid change in the same update must not apply either
        with pytest.raises(ValueError, match="update rejected"):
            params.update()
        assert float(np.asarray(params[key]).ravel()[0]) == pytest.approx(TWO_LOBE[key])
        assert float(np.asarray(params["exponent"]).ravel()[0]) == pytest.approx(60.0)
        np.testing.assert_array_equal(bsdf_pdf(bsdf, view, light), before)
    params["exponent2"] = _value(5.0)
    params["specular_weight2"] = _value(0.6)
    params.update()
    want = two_lobe_oracle(view, light, 60.0, 0.3, 5.0, 0.6)
    np.testing.assert_allclose(bsdf_pdf(bsdf, view, light), want, rtol=2e-4, atol=1e-6)


def test_two_lobe_needs_its_parameters(variant, merl_table):
    with pytest.raises(Exception, match="exponent2"):
        mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "two_lobe",
                      "exponent": 10.0, "specular_weight": 0.5})
    with pytest.raises(Exception, match="above 1"):
        mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "two_lobe",
                      "exponent": 10.0, "specular_weight": 0.7, "exponent2": 2.0, "specular_weight2": 0.5})
