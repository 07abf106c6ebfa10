"""Parity of the two backends (issue: full-speed rendering): the traced Dr.Jit path and the Rust
reference agree on eval, pdf, sampled directions and weights for the same uniforms, and on whole
renders at equal seed and spp; the traced weights are scene parameters that updates reach."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from nbrdf_testing import (bsdf_eval, bsdf_pdf, bsdf_sample, f32, grazing_pairs, nbrdf_reference,
                           random_pairs, read_network_layers)

PHONG = {"sampling": "phong", "exponent": 40.0, "specular_weight": 0.6}


def pair(plugin, path, **extra):
    """(rust, jit) BSDFs of the same file; the rust one switches wavefront mode on."""
    base = {"type": plugin, "filename": str(path), **extra}
    return mi.load_dict({**base, "backend": "rust"}), mi.load_dict({**base, "backend": "jit"})


def directions(n=3000):
    view, light = random_pairs(n, 21)
    g_view, g_light = grazing_pairs(n // 3, 22)
    return f32(np.concatenate([view, g_view], axis=1)), f32(np.concatenate([light, g_light], axis=1))


@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
def test_eval_and_pdf_agree(jit_variant, plugin, network_file, merl_table):
    path = network_file if plugin == "nbrdf" else merl_table
    rust, jit = pair(plugin, path, **PHONG)
    view, light = directions()
    a, b = bsdf_eval(rust, view, light), bsdf_eval(jit, view, light)
    # The network's float32 output exp(x) - 1 is accurate relative to 1 + f; table lookups
    # see float32 angles in the traced path (float64 in Rust).
    if plugin == "nbrdf":
        assert np.all(np.abs(a - b) <= 1e-5 * (1 + np.abs(a)) + 1e-5 * np.abs(a)), np.max(np.abs(a - b))
    else:
        np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-7)
    np.testing.assert_allclose(bsdf_pdf(jit, view, light), bsdf_pdf(rust, view, light), rtol=1e-4, atol=1e-7)


def test_traced_network_matches_numpy_reference(jit_variant, network_file):
    _, jit = pair("nbrdf", network_file)
    view, light = directions()
    ref = nbrdf_reference(read_network_layers(network_file), light, view)  # f_r cos
    got = bsdf_eval(jit, view, light)
    assert np.all(np.abs(got - ref) <= 1e-5 * (1 + ref) + 1e-5 * ref), np.max(np.abs(got - ref) / (1 + ref))


def test_traced_kernels_leave_out_units_that_never_fire(jit_variant, network_file, tmp_path):
    """A literal kernel drops the hidden units the library proves inactive above the horizon
    (network/pruning.rs), here two planted ones besides any the network has, and evaluates
    exactly what a kernel of every unit (opaque weights) does, on random, grazing and
    retro-reflection pairs; the values also match the float64 NumPy reference."""
    from nbrdf_testing import write_network

    layers = read_network_layers(network_file)
    layers[0][1][0] = -10.0 - np.abs(layers[0][0][:, 0]).sum()  # first hidden layer: never fires
    layers[1][1][1] = -10.0 - np.abs(layers[1][0][:, 1]).sum() * 1e3  # second: never fires
    path = write_network(tmp_path / "dead-units.nbrdf.json", layers)
    literal = mi.load_dict({"type": "nbrdf", "filename": str(path), "backend": "jit"})
    opaque = mi.load_dict({"type": "nbrdf", "filename": str(path), "backend": "jit", "jit_weights": "opaque"})
    first, second = literal._traced.active
    assert not first[0] and not second[1]
    assert opaque._traced.active is None
    view, light = directions()
    retro, _ = random_pairs(500, 23)
    view, light = np.concatenate([view, f32(retro)], axis=1), np.concatenate([light, f32(retro)], axis=1)
    got, full = bsdf_eval(literal, view, light), bsdf_eval(opaque, view, light)
    np.testing.assert_array_equal(got, full)
    ref = nbrdf_reference(read_network_layers(path), light, view)
    assert np.all(np.abs(got - ref) <= 1e-5 * (1 + ref) + 1e-5 * ref), np.max(np.abs(got - ref) / (1 + ref))
    # An update that revives the dead unit is proved again: the unit is back in the kernel.
    for bsdf in (literal, opaque):
        params = mi.traverse(bsdf)
        values = np.array(params["weights"].numpy())
        values[layers[0][0].size] = 0.5  # layer 1, bias of unit 0
        params["weights"] = mi.Float(values)
        params.update()
    assert literal._traced.active[0][0]
    np.testing.assert_array_equal(bsdf_eval(literal, view, light), bsdf_eval(opaque, view, light))
    assert not np.array_equal(bsdf_eval(literal, view, light), got)


def test_a_layer_that_never_fires_traces_and_renders(jit_variant, network_file, tmp_path):
    """No unit of the first hidden layer fires: the literal kernel computes only the one unit the
    library keeps for the layer's width, and the BSDF is what a kernel of every unit computes,
    alone and in a rendered scene (a symbolic call); a traced network told that a whole layer is
    dead computes the rest from the next layer's biases."""
    from nbrdf_mitsuba import jit
    from nbrdf_testing import write_network

    layers = read_network_layers(network_file)
    layers[0][1][:] = -10.0 - np.abs(layers[0][0]).sum()  # no unit of the first layer fires
    path = write_network(tmp_path / "dead-layer.nbrdf.json", layers)
    literal = mi.load_dict({"type": "nbrdf", "filename": str(path), "backend": "jit"})
    opaque = mi.load_dict({"type": "nbrdf", "filename": str(path), "backend": "jit", "jit_weights": "opaque"})
    assert np.count_nonzero(literal._traced.active[0]) <= 1
    view, light = directions()
    got = bsdf_eval(literal, view, light)
    np.testing.assert_array_equal(got, bsdf_eval(opaque, view, light))
    assert np.all(np.isfinite(got))
    image = mi.render(mi.load_dict(veach_like({"type": "nbrdf", "filename": str(path), "backend": "jit"}, spp=2)))
    assert np.all(np.isfinite(np.array(image)))
    dead = [np.zeros(len(layers[0][1]), bool), np.ones(len(layers[1][1]), bool)]
    traced = jit.TracedNetwork(layers, weights="literal", active=dead)
    up = mi.Vector3f(0.0, 0.0, 1.0)
    f = np.array([v[0] for v in traced.eval(up, up)])
    (_, _), (_, b2), (W3, b3) = [(W.astype(np.float64), b.astype(np.float64)) for W, b in layers]
    np.testing.assert_allclose(f, np.maximum(np.expm1(np.maximum(b2, 0) @ W3 + b3), 0), rtol=1e-5, atol=1e-7)


def test_the_traced_network_is_the_one_the_library_loaded(jit_variant, network_file):
    """One load: the plugin's kernels take the parameters and the active-unit proof from the
    library's handle (nbrdf_material_network), not from a second read of the file; they are the
    file's weights, read here independently, and what the library proves for those weights
    through its other entry point (nbrdf_material_active_units)."""
    from nbrdf_mitsuba import _native

    literal = mi.load_dict({"type": "nbrdf", "filename": str(network_file), "backend": "jit"})
    layers = read_network_layers(network_file)
    want = np.concatenate([np.concatenate([W.ravel(), b]) for W, b in layers]).astype(np.float32)
    np.testing.assert_array_equal(literal._traced.good, want)
    assert literal._traced.shapes == [W.shape for W, _ in layers]
    proved = _native.Material(network_file).active_units(want)
    for got, expected in zip(literal._traced.active, proved, strict=True):
        np.testing.assert_array_equal(got, expected)


def test_traced_expm1_is_relatively_exact(jit_variant):
    """The traced network's output function (twin of fastmath.rs expm1_with) against float64
    over the clamped argument range, tiny arguments (small reflectances) included: relative
    error within a few float32 roundings, and it is 0 at 0."""
    from nbrdf_mitsuba import jit

    z = np.concatenate([np.linspace(jit.EXP_ARG_MIN, jit.EXP_ARG_MAX, 200_001),
                        np.geomspace(1e-30, 1e-1, 2001), -np.geomspace(1e-30, 1e-1, 2001)]).astype(np.float32)
    got = np.array(jit.expm1(mi.Float(z)), dtype=np.float64)
    want = np.expm1(z.astype(np.float64))
    relative = np.abs(got - want) / np.abs(want).clip(min=1e-38)
    assert relative.max() < 3e-7, (relative.max(), z[np.argmax(relative)])
    assert float(jit.expm1(mi.Float(0.0))[0]) == 0.0


@pytest.mark.parametrize("sampling", ["phong", "cosine", "uniform"])
def test_same_uniforms_give_the_same_samples(jit_variant, sampling, network_file):
    extra = PHONG if sampling == "phong" else {"sampling": sampling}
    rust, jit = pair("nbrdf", network_file, **extra)
    view, _ = directions(2000)
    u = np.random.default_rng(3).uniform(0, 1, (3, view.shape[1])).astype(np.float32)
    u[:, :4] = [[0, 1, 0, 1], [0, 0, 1, 1], [0, 1, 1, 0]]  # interval ends
    wo_r, weight_r, pdf_r, _ = bsdf_sample(rust, view, u)
    wo_j, weight_j, pdf_j, _ = bsdf_sample(jit, view, u)
    np.testing.assert_array_equal(pdf_r > 0, pdf_j > 0)
    valid = pdf_r > 0
    np.testing.assert_allclose(wo_j[:, valid], wo_r[:, valid], atol=2e-5)
    # float32 rounding of the direction (2e-5) moves a lobe of exponent n by ~n * 2e-5.
    np.testing.assert_allclose(pdf_j[valid], pdf_r[valid], rtol=1e-3)
    np.testing.assert_allclose(weight_j[:, valid], weight_r[:, valid], rtol=2e-3, atol=1e-6)


def veach_like(bsdf: dict, spp: int = 8) -> dict:
    return {
        "type": "scene",
        "integrator": {"type": "direct"},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, -3, 2.5], target=[0, 0, 0], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": 32, "height": 24, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "plate": {"type": "rectangle", "bsdf": bsdf},
        "light": {"type": "sphere", "center": [0.0, -1.0, 4.0], "radius": 0.3,  # out of view
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 20.0}}},
    }


@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
def test_renders_match(jit_variant, plugin, network_file, merl_table):
    path = network_file if plugin == "nbrdf" else merl_table
    images = {}
    for backend in ("rust", "jit"):
        symbolic = backend == "jit"
        dr.set_flag(dr.JitFlag.SymbolicLoops, symbolic)
        dr.set_flag(dr.JitFlag.SymbolicCalls, symbolic)
        scene = mi.load_dict(veach_like({"type": plugin, "filename": str(path), "backend": backend, **PHONG}))
        images[backend] = np.array(mi.render(scene, seed=7))
    a, b = images["rust"], images["jit"]
    assert np.all(np.isfinite(b)) and a.mean() > 0
    # Same seed and spp: the same paths up to float32 rounding of the sampled directions.
    assert np.abs(a - b).mean() <= 1e-3 * a.mean(), (np.abs(a - b).mean(), a.mean())


@pytest.mark.parametrize("jit_weights", ["literal", "opaque"])
def test_weights_are_scene_parameters(jit_variant, network_file, jit_weights):
    scene = mi.load_dict(veach_like({"type": "nbrdf", "filename": str(network_file), "jit_weights": jit_weights}, spp=2))
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("weights"))
    assert dr.width(params[key]) == 675
    assert (params.flags(key) & mi.ParamFlags.NonDifferentiable) == (jit_weights == "literal")
    before = np.array(mi.render(scene, seed=1))
    weights = np.array(params[key])
    weights[-3:] -= 30.0  # output biases: exp(-30) - 1 ~ -1, clamped to 0 -> black plate
    params[key] = mi.Float(weights)
    params.update()
    after = np.array(mi.render(scene, seed=1))
    assert before.max() > 0 and after.max() == 0


def test_opaque_weights_carry_gradients(jit_variant, network_file):
    scene = mi.load_dict(veach_like({"type": "nbrdf", "filename": str(network_file), "jit_weights": "opaque"}, spp=2))
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("weights"))
    dr.enable_grad(params[key])
    params.update()
    image = mi.render(scene, params, seed=1)
    dr.backward(dr.mean(image, axis=None))
    grad = np.array(dr.grad(params[key]))
    assert np.all(np.isfinite(grad)) and np.abs(grad[-3:]).max() > 0  # output biases matter
