"""Hardening of the Mitsuba plugins (issue 16, plugin side): atomic parameter updates, NaN-safe
traced network, degenerate directions, sharp lobes (zoomed chi^2), wide networks, the rust
backend from any thread, and messages that say what a file is.

References are independent of the code under test: the float64 NumPy Blinn-Phong pdf of
``nbrdf_testing``, the Rust library through the other backend, and Mitsuba's chi^2 test."""

from __future__ import annotations

import gc
import json
import math
import os
import threading

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import nbrdf_mitsuba
from nbrdf_testing import (bsdf_eval, bsdf_eval_pdf, bsdf_pdf, bsdf_sample, f32, is_jit, nbrdf_reference, phong_pdf,
                           random_layers, random_pairs, read_network_layers, write_merl, write_network)

PHONG = {"sampling": "phong", "exponent": 40.0, "specular_weight": 0.6}


def _value(x: float):
    return mi.Float(x) if is_jit() else mi.Vector1f(x)


def _check_pdf(bsdf, exponent, weight, view, light):
    np.testing.assert_allclose(bsdf_pdf(bsdf, view, light), phong_pdf(view, light, exponent, weight),
                               rtol=2e-3, atol=1e-6)


def _error_chain(error) -> str:
    messages = []
    while error is not None:
        messages.append(str(error))
        error = error.__cause__ or error.__context__
    return " | ".join(messages)


# ---------------------------------------------------------------------------------------------
# Atomic parameter updates


def test_rejected_update_keeps_state_and_later_updates_apply(variant, merl_table):
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table), **PHONG})
    params = mi.traverse(bsdf)
    view, light = (f32(a) for a in random_pairs(64 if is_jit() else 12, 5))
    params["exponent"] = _value(float("nan"))
    with pytest.raises(Exception, match="NaN") as info:
        params.update()
    assert "update rejected" in str(info.value)
    assert float(np.asarray(params["exponent"]).reshape(-1)[0]) == 40.0  # written back
    _check_pdf(bsdf, 40.0, 0.6, view, light)
    params["exponent"] = _value(10.0)
    params.update()
    _check_pdf(bsdf, 10.0, 0.6, view, light)
    assert "exponent = 10" in str(bsdf)
    # Both parameters in one update: one bad value rejects both.
    params["exponent"] = _value(30.0)
    params["specular_weight"] = _value(-0.5)
    with pytest.raises(Exception, match="specular_weight"):
        params.update()
    _check_pdf(bsdf, 10.0, 0.6, view, light)
    params["specular_weight"] = _value(0.25)
    params.update()
    _check_pdf(bsdf, 10.0, 0.25, view, light)


def test_random_update_sequences_end_in_the_last_valid_state(variant, merl_table):
    """Seeded random sequences of valid and invalid updates: the BSDF always equals the last
    valid state (checked through its pdf against the NumPy formula)."""
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table), **PHONG})
    params = mi.traverse(bsdf)
    view, light = (f32(a) for a in random_pairs(32 if is_jit() else 6, 9))
    rng = np.random.default_rng(16)
    state = (40.0, 0.6)
    bad_exponents = [float("nan"), float("inf"), -float("inf"), -1.0, 2e6, 3.4e38]
    bad_weights = [float("nan"), float("inf"), -0.1, 1.5]
    for _ in range(60 if is_jit() else 40):
        exponent = float(np.float32(10 ** rng.uniform(0, 4))) if rng.uniform() < 0.6 else \
            bad_exponents[rng.integers(len(bad_exponents))]
        weight = float(np.float32(rng.uniform(0, 1))) if rng.uniform() < 0.7 else \
            bad_weights[rng.integers(len(bad_weights))]
        valid = math.isfinite(exponent) and 0 <= exponent <= 1e6 and math.isfinite(weight) and 0 <= weight <= 1
        params["exponent"] = _value(exponent)
        params["specular_weight"] = _value(weight)
        if valid:
            params.update()
            state = (exponent, weight)
        else:
            with pytest.raises(Exception, match="update rejected"):
                params.update()
        _check_pdf(bsdf, *state, view, light)


def test_exponent_is_capped(variant, merl_table):
    with pytest.raises(Exception, match=r"above the maximum 1e\+06"):
        mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "phong",
                      "exponent": 2e6, "specular_weight": 0.5})
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "phong",
                         "exponent": 1e6, "specular_weight": 0.5})
    params = mi.traverse(bsdf)
    params["exponent"] = _value(1.5e6)
    with pytest.raises(Exception, match=r"maximum 1e\+06"):
        params.update()
    assert "exponent = 1e+06" in str(bsdf)


def _scene(bsdf: dict, integrator: str = "direct", spp: int = 2) -> dict:
    return {
        "type": "scene",
        "integrator": {"type": integrator},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, -3, 2.5], target=[0, 0, 0], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": 24, "height": 16, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "plate": {"type": "rectangle", "bsdf": bsdf},
        "light": {"type": "sphere", "center": [0.0, -1.0, 4.0], "radius": 0.3,
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 20.0}}},
    }


@pytest.mark.parametrize("jit_weights", ["literal", "opaque"])
def test_non_finite_weights_are_rejected_on_update(llvm_variant, network_file, jit_weights):
    scene = mi.load_dict(_scene({"type": "nbrdf", "filename": str(network_file), "jit_weights": jit_weights}))
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("weights"))
    good = np.array(params[key])
    before = np.array(mi.render(scene, seed=1))
    assert before.max() > 0
    rng = np.random.default_rng(7)
    for bad, name in ((float("nan"), "NaN"), (float("inf"), r"\+inf"), (-float("inf"), "-inf")):
        corrupt = good.copy()
        k = int(rng.integers(corrupt.size))
        corrupt[k] = bad
        params[key] = mi.Float(corrupt)
        with pytest.raises(Exception, match=f"value {k} .* is {name}") as info:
            params.update()
        assert "layer" in str(info.value)
        np.testing.assert_array_equal(np.array(params[key]), good)  # written back
        np.testing.assert_array_equal(np.array(mi.render(scene, seed=1)), before)
    darker = good.copy()
    darker[-3:] -= 30.0  # output biases: the plate goes black
    params[key] = mi.Float(darker)
    params.update()
    assert np.array(mi.render(scene, seed=1)).max() == 0


def test_random_weight_update_sequences_end_in_the_last_valid_network(llvm_variant, network_file):
    """Seeded random sequences of weight updates (perturbations, NaN/inf corruptions, wrong
    counts): the BSDF always evaluates the last valid network (float64 NumPy oracle)."""
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(network_file), "jit_weights": "opaque"})
    params = mi.traverse(bsdf)
    key = next(k for k in params.keys() if k.endswith("weights"))
    shapes = [(w.shape, b.shape) for w, b in read_network_layers(network_file)]
    state = np.array(params[key], dtype=np.float32)
    view, light = (f32(a) for a in random_pairs(64, 13))
    rng = np.random.default_rng(160)
    for _ in range(25):
        candidate = state + rng.normal(0, 0.02, state.size).astype(np.float32)
        kind = rng.uniform()
        if kind < 0.3:
            candidate[rng.integers(candidate.size, size=rng.integers(1, 4))] = rng.choice([np.nan, np.inf, -np.inf])
        elif kind < 0.4:
            candidate = candidate[: -int(rng.integers(1, 5))]
        params[key] = mi.Float(candidate)
        if kind < 0.4:
            with pytest.raises(Exception, match="update rejected"):
                params.update()
        else:
            params.update()
            state = candidate
        layers, offset = [], 0
        for (w_shape, b_shape) in shapes:
            w = state[offset:offset + np.prod(w_shape)].reshape(w_shape).astype(np.float64)
            offset += w.size
            b = state[offset:offset + b_shape[0]].astype(np.float64)
            offset += b.size
            layers.append((w, b))
        reference = nbrdf_reference(layers, light, view)
        got = bsdf_eval(bsdf, view, light)
        assert np.all(np.abs(got - reference) <= 1e-5 * (1 + reference) + 1e-5 * reference)


# ---------------------------------------------------------------------------------------------
# NaN-safety of the traced network and degenerate directions


def _pair(plugin, path, **extra):
    base = {"type": plugin, "filename": str(path), **extra}
    return mi.load_dict({**base, "backend": "rust"}), mi.load_dict({**base, "backend": "jit"})


def test_huge_finite_weights_give_the_same_finite_values_in_both_backends(llvm_variant, tmp_path):
    rng = np.random.default_rng(4)
    layers = random_layers(hidden=8, seed=3)
    layers = [(np.float32(3e38) * np.sign(w), b) if k == 0 else (w * np.float32(1e30), b * np.float32(1e30))
              for k, (w, b) in enumerate(layers)]
    layers[0][0][rng.uniform(size=layers[0][0].shape) < 0.3] = 0.0
    path = write_network(tmp_path / "huge.nbrdf.json", layers)
    rust, traced = _pair("nbrdf", path, sampling="cosine")
    view, light = (f32(a) for a in random_pairs(500, 8))
    a, b = bsdf_eval(rust, view, light), bsdf_eval(traced, view, light)
    assert np.all(np.isfinite(b)) and np.all(b >= 0)
    np.testing.assert_allclose(b, a, rtol=1e-5)
    image = np.array(mi.render(mi.load_dict(_scene({"type": "nbrdf", "filename": str(path), "sampling": "cosine"}))))
    assert np.all(np.isfinite(image))


def _degenerate_pairs(seed: int, n: int):
    """(view, light) with non-unit lengths over 50 decades, zero, NaN and infinite vectors."""
    view, light = random_pairs(n, seed)
    rng = np.random.default_rng(seed)
    view = view * 10.0 ** rng.uniform(-18, 18, n)
    light = light * 10.0 ** rng.uniform(-18, 18, n)
    for v in (view, light):
        pick = rng.uniform(size=n)
        v[:, pick < 0.05] = 0.0
        v[0, (pick >= 0.05) & (pick < 0.1)] = np.nan
        v[2, (pick >= 0.1) & (pick < 0.15)] = np.inf
        v[1, (pick >= 0.15) & (pick < 0.2)] = -np.inf
    fixed = [(np.array([0.0, 0, 3]), np.array([1.0, 1, 1])), (np.array([0, 0, 1e-30]), np.array([0, 1e-30, 1e-30])),
             (np.array([0, 0, 1e30]), np.array([1e30, 0, 1e30])), (np.array([1.0, 0, 0]), np.array([-1.0, 0, 0]))]
    view = np.concatenate([view, np.stack([p[0] for p in fixed], axis=1)], axis=1)
    light = np.concatenate([light, np.stack([p[1] for p in fixed], axis=1)], axis=1)
    return view.astype(np.float32), light.astype(np.float32)


@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
def test_degenerate_directions_agree_between_backends(llvm_variant, plugin, network_file, merl_table):
    path = network_file if plugin == "nbrdf" else merl_table
    rust, traced = _pair(plugin, path, **PHONG)
    view, light = _degenerate_pairs(12, 400)
    value_r, pdf_r = bsdf_eval_pdf(rust, view, light)
    value_j, pdf_j = bsdf_eval_pdf(traced, view, light)
    assert np.all(np.isfinite(value_j)) and np.all(np.isfinite(pdf_j))
    np.testing.assert_array_equal(value_j > 0, value_r > 0)
    np.testing.assert_allclose(value_j, value_r, rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(pdf_j, pdf_r, rtol=1e-3, atol=1e-6)
    u = np.random.default_rng(2).uniform(0, 1, (3, view.shape[1])).astype(np.float32)
    u[:, :6] = [[np.nan, -1, 2, 0, 1, np.nan], [0.5, np.nan, 0.2, -3, 7, 0.5], [np.nan, 0.3, 0.1, 0, 1, 2]]
    wo_r, weight_r, spdf_r, _ = bsdf_sample(rust, view, u)
    wo_j, weight_j, spdf_j, _ = bsdf_sample(traced, view, u)
    assert np.all(np.isfinite(wo_j)) and np.all(np.isfinite(weight_j)) and np.all(np.isfinite(spdf_j))
    np.testing.assert_array_equal(spdf_j > 0, spdf_r > 0)
    valid = spdf_r > 0
    np.testing.assert_allclose(wo_j[:, valid], wo_r[:, valid], atol=2e-5)
    np.testing.assert_allclose(spdf_j[valid], spdf_r[valid], rtol=1e-3)
    np.testing.assert_allclose(weight_j, weight_r, rtol=2e-3, atol=1e-6)


def test_rust_backend_sample_takes_python_floats(llvm_variant, network_file):
    rust, traced = _pair("nbrdf", network_file, **PHONG)
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.wi = mi.Vector3f(0.3, 0.1, 0.9)
    results = []
    for bsdf in (rust, traced):
        bs, weight = bsdf.sample(mi.BSDFContext(), si, 0.3, mi.Point2f(0.2, 0.7))
        results.append((np.array(bs.wo).ravel(), float(bs.pdf[0]), np.array(weight).ravel()))
    np.testing.assert_allclose(results[1][0], results[0][0], atol=2e-5)
    assert results[0][1] > 0 and results[1][1] == pytest.approx(results[0][1], rel=1e-3)
    np.testing.assert_allclose(results[1][2], results[0][2], rtol=2e-3)


# ---------------------------------------------------------------------------------------------
# Sharp lobes: chi^2 in a domain zoomed on the mirror direction


class MirrorConeDomain:
    """Directions within a small cone around the mirror direction ``r`` of the view, in r's own
    frame as ``(phi, s)`` with ``s = sqrt(1 - cos alpha)`` (alpha the angle to r). ``s`` is
    computed from the components orthogonal to r, so float32 resolves cones far narrower than
    ``1 - cos`` could, and a lobe ``exp(-n (1 - cos))`` is a smooth Gaussian in ``s`` that
    Mitsuba's trapezoid rule integrates well even where grazing views stretch it.
    ``d omega = 2 s ds dphi``: :meth:`pdf` multiplies the BSDF's density by ``2 s`` (the test
    integrates densities over the parameter domain)."""

    def __init__(self, view: np.ndarray, t_max: float):
        r = np.array([-view[0], -view[1], view[2]], dtype=np.float64)
        r /= np.linalg.norm(r)
        e1 = np.cross([0.0, 1.0, 0.0], r) if abs(r[1]) < 0.9 else np.cross([1.0, 0.0, 0.0], r)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(r, e1)
        self.frame = [mi.ScalarVector3f(*map(float, a)) for a in (e1, e2, r)]
        self.s_max = math.sqrt(t_max)

    def bounds(self):
        return mi.ScalarBoundingBox2f([-dr.pi, 0.0], [dr.pi, self.s_max])

    def aspect(self):
        return 1

    def map_forward(self, p):
        e1, e2, r = self.frame
        t = p.y * p.y
        sin_alpha = dr.safe_sqrt(t * (2.0 - t))
        sin_phi, cos_phi = dr.sincos(p.x)
        return e1 * (sin_alpha * cos_phi) + e2 * (sin_alpha * sin_phi) + r * (1.0 - t)

    def map_backward(self, w):
        e1, e2, r = self.frame
        a, b, c = dr.dot(w, e1), dr.dot(w, e2), dr.dot(w, r)
        t = dr.fma(a, a, b * b) / (1.0 + c)
        return mi.Vector2f(dr.atan2(b, a), dr.sqrt(t))

    def inside(self, w):
        return (self.map_backward(w).y < self.s_max) & (dr.dot(w, self.frame[2]) > 0)

    def adapt(self, sample_func, pdf_func):
        """(sample, pdf) functions for ChiSquareTest: samples outside the cone count with
        weight 0 (the test then compares sub-probabilities), densities per unit parameter area."""
        def sample(u):
            wo, w = sample_func(u)
            keep = self.inside(wo)
            return dr.select(keep, wo, mi.Vector3f(self.frame[2])), dr.select(keep, w, 0.0)

        def pdf(wo):
            return pdf_func(wo) * 2.0 * self.map_backward(wo).y

        return sample, pdf


def _zoomed_chi2(plugin, path, backend, exponent, theta, pdf_exponent=None):
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest

    view = np.array([math.sin(theta), 0.0, math.cos(theta)])
    # The half vector's 1 - cos is ~Exp(n); the light's cone is ~4x as wide in 1 - cos near the
    # normal, and wider at grazing angles. This keeps most samples inside.
    domain = MirrorConeDomain(view, t_max=40.0 / exponent)
    description = {"type": plugin, "filename": str(path), "backend": backend, "sampling": "phong",
                   "exponent": exponent, "specular_weight": 0.9}
    sample_func, pdf_func = BSDFAdapter(plugin, description, wi=mi.Vector3f(*map(float, view)))
    if pdf_exponent is not None:
        _, pdf_func = BSDFAdapter(plugin, {**description, "exponent": pdf_exponent},
                                  wi=mi.Vector3f(*map(float, view)))
    sample_func, pdf_func = domain.adapt(sample_func, pdf_func)
    chi2 = ChiSquareTest(domain=domain, sample_func=sample_func, pdf_func=pdf_func, sample_dim=3,
                         sample_count=300_000, res=31, ires=10)
    ok = chi2.run(significance_level=0.01, test_count=8, quiet=True)
    return ok, chi2.messages


@pytest.mark.parametrize("exponent", [1e4, 1e6])
@pytest.mark.parametrize("theta", [0.4, 1.45])
def test_sharp_lobes_pass_zoomed_chi2_jit(llvm_variant, merl_table, exponent, theta):
    ok, messages = _zoomed_chi2("merl", merl_table, "jit", exponent, theta)
    assert ok, messages


@pytest.mark.parametrize("exponent", [1e4, 1e6])
@pytest.mark.parametrize("theta", [0.4, 1.45])
def test_sharp_lobes_pass_zoomed_chi2_rust(llvm_variant, merl_table, exponent, theta):
    ok, messages = _zoomed_chi2("merl", merl_table, "rust", exponent, theta)
    assert ok, messages


def test_traced_log1m_is_relatively_exact_near_zero(llvm_variant):
    """ln(1 - x) of the traced pdfs against float64 log1p over 12 decades: a sharp lobe's pdf
    is exp(n ln(1 - x)) with x ~ 1/n, so a 1e-7 absolute error (CUDA's approximate log near 1)
    would be a 10 % error at n = 1e6."""
    from nbrdf_mitsuba.jit import sampling

    x = np.concatenate([np.geomspace(1e-12, 0.999, 4000), [0.0, 0.0625, np.nextafter(0.0625, 0)]]).astype(np.float32)
    got = np.asarray(sampling._log1m(mi.Float(x)).numpy(), np.float64)
    want = np.log1p(-x.astype(np.float64))
    small = x < 0.0625
    np.testing.assert_allclose(got[small], want[small], rtol=1e-6, atol=0)
    # Above 1/16 the backend's own log (CUDA's is good to 2^-22.6 in log2, ~1.1e-7 in ln) is
    # accurate enough: there a lobe of n >= 16 is already below exp(-1) of its peak.
    np.testing.assert_allclose(got[~small], want[~small], rtol=1e-6, atol=2.5e-7)


@pytest.mark.parametrize("backend", ["jit", "rust"])
def test_zoomed_chi2_detects_a_five_percent_error_in_the_exponent(llvm_variant, merl_table, backend):
    """The zoomed test can fail: sampling n = 0.95e6 against the pdf of n = 1e6 is rejected."""
    ok, _ = _zoomed_chi2("merl", merl_table, backend, 0.95e6, 0.4, pdf_exponent=1e6)
    assert not ok


# ---------------------------------------------------------------------------------------------
# Wide networks


def test_wide_networks_go_to_the_rust_backend_or_are_refused(llvm_variant, tmp_path):
    from nbrdf_mitsuba.bsdf import JIT_MAX_HIDDEN_WIDTH

    path = write_network(tmp_path / "wide.nbrdf.json", random_layers(hidden=JIT_MAX_HIDDEN_WIDTH + 1))
    with pytest.raises(Exception, match=f"above {JIT_MAX_HIDDEN_WIDTH}"):
        mi.load_dict({"type": "nbrdf", "filename": str(path), "backend": "jit"})
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(path)})
    assert "backend = rust" in str(bsdf)
    narrow = write_network(tmp_path / "narrow.nbrdf.json", random_layers(hidden=JIT_MAX_HIDDEN_WIDTH))
    assert "backend = jit" in str(mi.load_dict({"type": "nbrdf", "filename": str(narrow)}))
    # No traced twin for it: in symbolic mode it fails every time, with the remedy.
    scene = mi.load_dict(_scene({"type": "nbrdf", "filename": str(path)}))
    for _ in range(2):
        with pytest.raises(Exception) as info:
            mi.render(scene)
        assert "use_wavefront_mode" in _error_chain(info.value) and "hidden width" in _error_chain(info.value)
    try:
        nbrdf_mitsuba.use_wavefront_mode()
        image = np.array(mi.render(scene))
    finally:
        dr.set_flag(dr.JitFlag.SymbolicLoops, True)
        dr.set_flag(dr.JitFlag.SymbolicCalls, True)
    assert image.max() > 0 and np.all(np.isfinite(image))
    del bsdf, scene, info  # a live instance is traced by every symbolic call
    gc.collect()


# ---------------------------------------------------------------------------------------------
# The rust backend and threads


def test_rust_backend_renders_whichever_thread_built_it(llvm_variant, network_file):
    """Plugins are built on worker threads and Dr.Jit's flags are per thread: a scene built on
    the rendering thread or on another one renders the same, in symbolic mode (through the
    traced twin) and in wavefront mode (through the library), and the two agree."""
    description = _scene({"type": "nbrdf", "filename": str(network_file), "backend": "rust", **PHONG}, "path")
    scenes = [mi.load_dict(description)]
    built = []
    worker = threading.Thread(target=lambda: built.append(mi.load_dict(description)))
    worker.start()
    worker.join()
    scenes += built
    assert dr.flag(dr.JitFlag.SymbolicLoops) and dr.flag(dr.JitFlag.SymbolicCalls)  # untouched
    symbolic = [np.array(mi.render(scene, seed=3)) for scene in scenes * 2]
    try:
        nbrdf_mitsuba.use_wavefront_mode()
        wavefront = [np.array(mi.render(scene, seed=3)) for scene in scenes]
    finally:
        dr.set_flag(dr.JitFlag.SymbolicLoops, True)
        dr.set_flag(dr.JitFlag.SymbolicCalls, True)
    reference = wavefront[0]
    assert reference.max() > 0 and np.all(np.isfinite(reference))
    np.testing.assert_array_equal(wavefront[1], reference)
    for image in symbolic:
        np.testing.assert_array_equal(image, symbolic[0])
    # Same seed and spp: the same paths up to float32 rounding (as test_backends.test_renders_match).
    assert np.abs(symbolic[0] - reference).mean() <= 1e-3 * reference.mean()


def test_a_live_rust_bsdf_does_not_break_other_symbolic_renders(llvm_variant, network_file, merl_table):
    """Dr.Jit traces a symbolic call through every live BSDF instance, used or not."""
    keep = [mi.load_dict({"type": plugin, "filename": str(path), "backend": "rust"})
            for plugin, path in (("nbrdf", network_file), ("merl", merl_table))]
    scene = mi.load_dict(_scene({"type": "merl", "filename": str(merl_table)}))
    image = np.array(mi.render(scene, seed=2))
    assert image.max() > 0 and np.all(np.isfinite(image)) and len(keep) == 2


# ---------------------------------------------------------------------------------------------
# Messages


def _load_error(plugin, path) -> str:
    with pytest.raises(Exception) as info:
        mi.load_dict({"type": plugin, "filename": str(path)})
    return _error_chain(info.value)


def test_wrong_file_kinds_are_named(network_file, merl_table, tmp_path):
    mi.set_variant("scalar_rgb")
    message = _load_error("nbrdf", merl_table)
    assert "this is a MERL table; the nbrdf BSDF reads *.nbrdf.json" in message and "merl BSDF" in message
    assert "UTF-8" not in message
    message = _load_error("merl", network_file)
    assert "this is a JSON file" in message and "nbrdf BSDF" in message
    assert "538970747" not in message
    odd = tmp_path / "odd.binary"  # a MERL-like file with other dimensions
    odd.write_bytes(np.array([90, 90, 90], "<i4").tobytes() + merl_table.read_bytes()[12:1000])
    assert "this is binary data, not an *.nbrdf.json network" in _load_error("nbrdf", odd)


def test_paths_appear_once(tmp_path):
    mi.set_variant("scalar_rgb")
    broken = tmp_path / "broken.nbrdf.json"
    broken.write_text('{"format": "nbrdf", "version": 1, "name": "x", "layers": [')
    message = str(_load_error("nbrdf", broken)).split(" | ")[0]
    assert message.count(str(broken)) == 1, message


def test_special_files_are_refused_without_blocking(tmp_path):
    mi.set_variant("scalar_rgb")
    fifo = tmp_path / "pipe.binary"
    os.mkfifo(fifo)
    assert "not a regular file" in _load_error("merl", fifo)
    assert "not a regular file" in _load_error("nbrdf", "/dev/zero")


def test_tables_are_checked_in_float32(tmp_path):
    mi.set_variant("scalar_rgb")
    stored = np.full((3, 90 * 90 * 180), 1.0)
    stored[1, 1234] = 1e300
    message = _load_error("merl", write_merl(tmp_path / "huge.binary", stored))
    assert "beyond the float32 range" in message and "1e300" in message
    message = _load_error("merl", write_merl(tmp_path / "empty.binary", np.full((3, 90 * 90 * 180), -1.0)))
    assert "no valid cell" in message


def test_nan_update_message_names_nan(variant, network_file):
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(network_file), **PHONG})
    params = mi.traverse(bsdf)
    params["specular_weight"] = _value(float("nan"))
    with pytest.raises(Exception, match="specular_weight is NaN"):
        params.update()


# ---------------------------------------------------------------------------------------------
# What the library itself (through the C ABI) refuses too: the plugin checks these in Python
# before calling it; the CLI and other C ABI users rely on the library (docs/hardening.md).


def test_library_caps_the_exponent():
    from nbrdf_mitsuba import _native

    with pytest.raises(_native.NbrdfError, match="1e6|1000000"):
        _native.Sampler("phong", 2e6, 0.5)


def test_library_refuses_tables_beyond_float32(tmp_path):
    from nbrdf_mitsuba import _native

    stored = np.full((3, 90 * 90 * 180), 1.0)
    stored[1, 5] = 1e300
    with pytest.raises(_native.NbrdfError, match="float32"):
        _native.Material(write_merl(tmp_path / "huge.binary", stored))


def test_library_refuses_tables_without_a_valid_cell(tmp_path):
    from nbrdf_mitsuba import _native

    with pytest.raises(_native.NbrdfError, match="valid"):
        _native.Material(write_merl(tmp_path / "empty.binary", np.full((3, 90 * 90 * 180), -1.0)))


def test_library_names_nan_in_network_json(tmp_path, network_file):
    from nbrdf_mitsuba import _native

    document = json.loads(network_file.read_text())
    document["layers"][0]["weights"][0] = float("nan")
    bad = tmp_path / "nan.nbrdf.json"
    bad.write_text(json.dumps(document))  # Python writes the non-standard token NaN
    with pytest.raises(_native.NbrdfError, match="NaN"):
        _native.Material(bad)
