"""The ``nbrdf`` plugin evaluates the authors' Keras NBRDFs like an independent float64 NumPy
implementation of docs/design.md sections 2 and 4 reading the same ``.h5`` weights."""

from __future__ import annotations

import json

import mitsuba as mi
import numpy as np
import pytest

from nbrdf_testing import (bsdf_eval, f32, grazing_pairs, is_jit, keras_layers, nbrdf_reference, network_input,
                           normalize, random_layers, random_pairs, write_network)

RTOL = 1e-5
ATOL = 1e-7  # f_r cos is computed in float32: exp(z) - 1 near z = 0 loses ~6e-8 absolute
ULPS = 4


def f32_conditioning(layers, light, view) -> np.ndarray:
    """How far the float64 reference moves when its six inputs carry ULPS float32 rounding errors
    (linearised): the float32 floor of any implementation fed with float32 directions. The
    input components are computed from unit vectors, so their errors are absolute, ~2^-23, but
    the half vector is formed as ``l + v``: where the two nearly cancel (grazing, opposite
    azimuths) the unit vectors' own rounding is amplified by ``1 / |l + v|`` (up to ~10 near the
    horizon), and how far depends on the CPU's float32 normalisation (rsqrt)."""
    ref = nbrdf_reference(layers, light, view)
    x = network_input(light, view)
    (w1, b1), (w2, b2), (w3, b3) = layers
    cos_l = normalize(light)[2]
    cancellation = 1.0 / np.maximum(np.linalg.norm(normalize(light) + normalize(view), axis=0), 1e-3)
    bound = np.zeros_like(ref)
    for i in range(6):
        xp = x.copy()
        xp[:, i] += 1e-6
        y = np.maximum(np.maximum(xp @ w1 + b1, 0) @ w2 + b2, 0)
        moved = np.maximum(np.exp(y @ w3 + b3) - 1, 0).T * np.where(cos_l > 0, cos_l, 0)
        bound += np.abs(moved - ref) / 1e-6 * 2.0**-23
    return ULPS * bound * np.maximum(cancellation, 1.0)


def test_matches_keras_reference(variant, keras_networks):
    n = 400 if is_jit() else 40
    worst = 0.0
    for h5, network in keras_networks:
        bsdf = mi.load_dict({"type": "nbrdf", "filename": str(network)})
        layers = keras_layers(h5)
        for kind, (view, light) in (("random", random_pairs(n, 1)), ("grazing", grazing_pairs(n, 2))):
            view, light = f32(view), f32(light)  # what the plugin receives
            got = bsdf_eval(bsdf, view, light)
            ref = nbrdf_reference(layers, light, view)
            tolerance = RTOL * np.abs(ref) + ATOL + f32_conditioning(layers, light, view)
            excess = np.abs(got - ref) / tolerance
            worst = max(worst, float(excess.max()))
            c, i = np.unravel_index(np.argmax(excess), excess.shape)
            assert excess.max() <= 1.0, (
                f"{h5.name} {kind}: channel {c} of view {view[:, i]} light {light[:, i]}: "
                f"plugin {got[c, i]:.9g} vs reference {ref[c, i]:.9g} (tolerance {tolerance[c, i]:.3g})")
            assert np.all(np.isfinite(got)) and np.all(got >= 0)
            # Most points are well conditioned: there the plain 1e-5 relative bound holds.
            plain = np.abs(got - ref) <= RTOL * np.abs(ref) + ATOL
            assert plain.mean() > 0.95, f"{h5.name} {kind}: only {plain.mean():.1%} within 1e-5 relative"
    print(f"worst error / tolerance: {worst:.2f}")


def test_grid_of_angles_including_the_specular_direction(variant, keras_networks):
    """Angles on a regular grid, including the mirror configuration (theta_h = 0) approached
    from both sides."""
    h5, network = keras_networks[2]
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(network)})
    layers = keras_layers(h5)
    theta_v = np.radians([0.0, 20.0, 45.0, 70.0, 85.0])
    offsets = np.radians([0.0, 0.05, 1.0, 10.0, 40.0])
    tv, off = np.meshgrid(theta_v, offsets, indexing="ij")
    tv, off = tv.ravel(), off.ravel()
    tl = np.clip(tv + off, 0, np.radians(89.0))
    view = np.stack([np.sin(tv), np.zeros_like(tv), np.cos(tv)])
    light = np.stack([-np.sin(tl), np.zeros_like(tl), np.cos(tl)])
    view, light = f32(view), f32(light)
    got = bsdf_eval(bsdf, view, light)
    ref = nbrdf_reference(layers, light, view)
    tolerance = RTOL * np.abs(ref) + ATOL + f32_conditioning(layers, light, view)
    assert np.all(np.abs(got - ref) <= tolerance), np.max(np.abs(got - ref) / tolerance)


def test_imported_weights_are_exact(keras_networks):
    for h5, network in keras_networks:
        document = json.loads(network.read_text())
        assert document["format"] == "nbrdf" and document["version"] == 1
        assert document["name"] == h5.name.removesuffix(".h5")
        assert document["provenance"]["source_file"] == h5.name
        assert document["provenance"]["method"] == "imported from Keras"
        assert "sampling" not in document
        for layer, (kernel, bias) in zip(document["layers"], keras_layers(h5)):
            assert (layer["inputs"], layer["outputs"]) == kernel.shape
            np.testing.assert_array_equal(np.float32(layer["weights"]), np.float32(kernel).ravel())
            np.testing.assert_array_equal(np.float32(layer["bias"]), np.float32(bias))


def test_default_sampling_of_imported_networks_is_cosine(variant, network_file):
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(network_file)})
    text = str(bsdf)
    assert "sampling = cosine" in text and "hidden_width = 21" in text and "parameter_count = 675" in text


def test_reciprocity_as_the_reference(variant, keras_networks):
    """NBRDFs are only approximately reciprocal (swapping l and v negates d.x and d.y at the
    network input); the plugin is exactly as reciprocal as the reference."""
    h5, network = keras_networks[0]
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(network)})
    layers = keras_layers(h5)
    view, light = (f32(a) for a in random_pairs(200 if is_jit() else 30, 7))
    forward = bsdf_eval(bsdf, view, light) / normalize(light)[2]
    backward = bsdf_eval(bsdf, light, view) / normalize(view)[2]
    ref_forward = nbrdf_reference(layers, light, view) / normalize(light)[2]
    ref_backward = nbrdf_reference(layers, view, light) / normalize(view)[2]
    np.testing.assert_allclose(forward - backward, ref_forward - ref_backward, rtol=1e-3,
                               atol=1e-4 * np.abs(ref_forward).max())
    asymmetry = np.abs(forward - backward) / (forward + backward + 1e-9)
    assert np.median(asymmetry) < 0.05


@pytest.mark.parametrize("hidden", [4, 32])
def test_other_hidden_widths(variant, tmp_path, hidden):
    layers = random_layers(hidden, seed=hidden)
    path = write_network(tmp_path / "random.nbrdf.json", layers, name=f"random-{hidden}", sampling={
        "model": "blinn-phong", "exponent": 25.0, "specular_weight": 0.4, "source": "manual"})
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(path)})
    assert f"hidden_width = {hidden}" in str(bsdf) and "sampling = phong" in str(bsdf)
    view, light = (f32(a) for a in random_pairs(100 if is_jit() else 20, 3))
    ref_layers = [(w.astype(np.float64), b.astype(np.float64)) for w, b in layers]
    got = bsdf_eval(bsdf, view, light)
    ref = nbrdf_reference(ref_layers, light, view)
    tolerance = RTOL * np.abs(ref) + ATOL + f32_conditioning(ref_layers, light, view)
    assert np.all(np.abs(got - ref) <= tolerance)
