"""Importance sampling through the plugins: Mitsuba's chi^2 test, the Blinn-Phong pdf against
docs/design.md section 6 and by quadrature, and the consistency of sample/eval/pdf."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from nbrdf_testing import (bsdf_eval, bsdf_eval_pdf, bsdf_pdf, bsdf_sample, f32, is_jit, normalize, phong_pdf,
                           random_pairs, sph)

PHONG = {"exponent": 60.0, "specular_weight": 0.7}


def make(plugin, sampling, network_file, merl_table, **extra):
    filename = network_file if plugin == "nbrdf" else merl_table
    params = {"type": plugin, "filename": str(filename), "sampling": sampling, **extra}
    if sampling == "phong":
        params = {**PHONG, **params}
    return mi.load_dict(params)


@pytest.mark.parametrize("backend", ["rust", "jit"])
@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
@pytest.mark.parametrize("sampling", ["phong", "cosine"])
def test_chi2(llvm_variant, backend, plugin, sampling, network_file, merl_table):
    """Mitsuba's chi^2 goodness-of-fit test of sample() against pdf() for both backends
    (vectorised variants only: mitsuba.chi2 runs on Dr.Jit arrays)."""
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    filename = network_file if plugin == "nbrdf" else merl_table
    xml = (f'<string name="filename" value="{filename}"/><string name="sampling" value="{sampling}"/>'
           f'<string name="backend" value="{backend}"/>')
    if sampling == "phong":
        xml += '<float name="exponent" value="60"/><float name="specular_weight" value="0.7"/>'
    for theta in (0.1, 0.7, 1.3):
        wi = mi.Vector3f(float(np.sin(theta)), 0.0, float(np.cos(theta)))
        sample_func, pdf_func = BSDFAdapter(plugin, xml, wi=wi)
        chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                             sample_dim=3, sample_count=200_000, res=61)
        assert chi2.run(significance_level=0.01, test_count=12, quiet=True), (
            f"{plugin}/{sampling} at theta_i = {theta}: {chi2.messages}")


@pytest.mark.parametrize("exponent", [0.0, 5.0, 50.0, 500.0])
def test_phong_pdf_integrates_to_one(variant, exponent, merl_table):
    """Quadrature of the plugin's pdf over the hemisphere for a view at the normal, in
    coordinates centred on the mirror direction and refined near it. The mass of the lobe below
    the horizon is known there (half vectors beyond 45 degrees): P = (1/sqrt 2)^(n+1), which
    is negligible for moderate exponents and 50-70 % for n = 0 and 5."""
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "phong",
                         "exponent": exponent, "specular_weight": 0.8})
    n_t, n_p = (400, 128) if is_jit() else (48, 24)
    # alpha = angle to the mirror direction (+z here), alpha = (pi/2) t^2, midpoint rule in t.
    t = (np.arange(n_t) + 0.5) / n_t
    alpha = np.pi / 2 * t**2
    d_alpha = np.pi * t / n_t
    phi = (np.arange(n_p) + 0.5) / n_p * 2 * np.pi
    A, P = np.meshgrid(alpha, phi, indexing="ij")
    light = sph(A.ravel(), P.ravel())
    view = np.tile(np.array([[0.0], [0.0], [1.0]]), (1, light.shape[1]))
    pdf = bsdf_pdf(bsdf, f32(view), f32(light)).reshape(n_t, n_p)
    integral = np.sum(pdf * np.sin(A) * d_alpha[:, None] * (2 * np.pi / n_p))
    weight = 0.8
    expected = (1 - weight) + weight * (1 - np.sqrt(0.5) ** (exponent + 1))
    assert integral == pytest.approx(expected, abs=2e-3 if is_jit() else 2e-2)
    if exponent >= 50:
        assert integral == pytest.approx(1.0, abs=3e-3 if is_jit() else 2e-2)


def test_pdf_matches_design_formula(variant, merl_table):
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "phong",
                         "exponent": 35.0, "specular_weight": 0.35})
    view, light = (f32(a) for a in random_pairs(300 if is_jit() else 40, 17))
    np.testing.assert_allclose(bsdf_pdf(bsdf, view, light), phong_pdf(view, light, 35.0, 0.35), rtol=1e-4, atol=1e-7)
    cosine = mi.load_dict({"type": "merl", "filename": str(merl_table)})
    np.testing.assert_allclose(bsdf_pdf(cosine, view, light), normalize(light)[2] / np.pi, rtol=1e-5, atol=1e-7)
    uniform = mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "uniform"})
    np.testing.assert_allclose(bsdf_pdf(uniform, view, light), 1 / (2 * np.pi), rtol=1e-5)


@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
@pytest.mark.parametrize("sampling", ["phong", "cosine", "uniform"])
def test_sample_is_consistent_with_eval_and_pdf(variant, plugin, sampling, network_file, merl_table):
    bsdf = make(plugin, sampling, network_file, merl_table)
    n = 400 if is_jit() else 40
    rng = np.random.default_rng(3)
    view = sph(np.arccos(rng.uniform(0.05, 1, n)), rng.uniform(-np.pi, np.pi, n))
    u = rng.uniform(0, 1, (3, n))
    u[:, :4] = [[0, 1, 0, 1], [0, 1, 1, 0], [0, 1, 0.5, 1]]  # interval ends
    wo, weight, pdf, types = bsdf_sample(bsdf, f32(view), u)
    assert np.all(np.isfinite(wo)) and np.all(np.isfinite(weight)) and np.all(np.isfinite(pdf))
    valid = pdf > 0
    assert valid.mean() > 0.5
    assert np.all(weight[:, ~valid] == 0)
    assert np.all(types[valid] == int(mi.BSDFFlags.GlossyReflection))
    assert np.all(wo[2, valid] > 0)
    np.testing.assert_allclose(np.linalg.norm(wo[:, valid], axis=0), 1, atol=1e-5)
    view_v, wo_v = f32(view[:, valid]), f32(wo[:, valid])
    value, pdf_again = bsdf_eval_pdf(bsdf, view_v, wo_v)
    np.testing.assert_allclose(pdf_again, pdf[valid], rtol=2e-4)
    np.testing.assert_allclose(value, bsdf_eval(bsdf, view_v, wo_v), rtol=1e-6)
    np.testing.assert_allclose(weight[:, valid], value / pdf[valid], rtol=5e-4, atol=1e-6)


@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
def test_zero_below_the_horizon(variant, plugin, network_file, merl_table):
    bsdf = make(plugin, "phong", network_file, merl_table)
    up = sph([0.3, 1.0, 1.5], [0.0, 2.0, -1.0])
    down = up * np.array([[1], [1], [-1]])
    for view, light in ((down, up), (up, down), (down, down)):
        assert np.all(bsdf_eval(bsdf, view, light) == 0)
        assert np.all(bsdf_pdf(bsdf, view, light) == 0)
        value, pdf = bsdf_eval_pdf(bsdf, view, light)
        assert np.all(value == 0) and np.all(pdf == 0)
    _, weight, pdf, _ = bsdf_sample(bsdf, down, np.full((3, 3), 0.4))
    assert np.all(weight == 0) and np.all(pdf == 0)


@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
def test_finite_on_degenerate_directions(variant, plugin, network_file, merl_table):
    bsdf = make(plugin, "phong", network_file, merl_table)
    z = np.array([0.0, 0.0, 1.0])
    g = np.array([1.0, 0.0, 1e-7])  # grazing, not unit length
    pairs = [
        (z, z),  # l = v = n: theta_h = theta_d = 0
        (sph(0.5, 0.3), sph(0.5, 0.3)),  # l = v
        (sph(0.5, 0.3), sph(0.5, 0.3 + np.pi)),  # mirror: theta_h = 0, phi_h undefined
        (np.array([1.0, 0, 0]), np.array([-1.0, 0, 0])),  # l + v = 0, both on the horizon
        (g, g), (g, z), (z, g),
        (np.array([0.0, 0.0, 3.0]), np.array([1.0, 1.0, 1.0])),  # not unit length
        (np.array([0.0, 0.0, 0.0]), z),  # zero vector
    ]
    view = np.stack([p[0] for p in pairs], axis=1)
    light = np.stack([p[1] for p in pairs], axis=1)
    value, pdf = bsdf_eval_pdf(bsdf, view, light)
    assert np.all(np.isfinite(value)) and np.all(value >= 0)
    assert np.all(np.isfinite(pdf)) and np.all(pdf >= 0)
    u = np.tile(np.linspace(0, 1, view.shape[1]), (3, 1))
    wo, weight, pdf, _ = bsdf_sample(bsdf, view, u)
    assert np.all(np.isfinite(wo)) and np.all(np.isfinite(weight)) and np.all(np.isfinite(pdf))


def test_component_selection(variant, merl_table):
    """A context that excludes glossy reflection sees a black BSDF that cannot be sampled."""
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table)})
    ctx = mi.BSDFContext(mi.TransportMode.Radiance, int(mi.BSDFFlags.DiffuseReflection), 0)
    view, light = (f32(a) for a in random_pairs(8, 1))
    assert np.all(bsdf_eval(bsdf, view, light, ctx) == 0)
    assert np.all(bsdf_pdf(bsdf, view, light, ctx) == 0)
    _, weight, pdf, _ = bsdf_sample(bsdf, view, np.full((3, 8), 0.3), ctx)
    assert np.all(weight == 0) and np.all(pdf == 0)
    assert bsdf.flags() == int(mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide)
    assert bsdf.component_count() == 1
    assert dr.all(mi.has_flag(bsdf.flags(), mi.BSDFFlags.Glossy))


def test_empty_wavefront(llvm_variant, merl_table):
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table)})
    ctx, si, wo = mi.BSDFContext(), dr.zeros(mi.SurfaceInteraction3f, 0), dr.zeros(mi.Vector3f, 0)
    assert dr.width(bsdf.eval(ctx, si, wo)) == 0 and dr.width(bsdf.pdf(ctx, si, wo)) == 0
    value, pdf = bsdf.eval_pdf(ctx, si, wo)
    assert dr.width(value) == 0 and dr.width(pdf) == 0
    bs, weight = bsdf.sample(ctx, si, dr.zeros(mi.Float, 0), dr.zeros(mi.Point2f, 0))
    assert dr.width(weight) == 0 and dr.width(bs.wo) == 0
