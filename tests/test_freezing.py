"""Dr.Jit's frozen functions over renders of the plugin's BSDFs (nbrdf_mitsuba.freezing): each
replay after a parameter update equals an ordinary render of the updated scene, for every weight
mode, a network on a base going from zero to non-zero, a MERL table; a textured material refuses."""

from __future__ import annotations

import gc
import json

import nbrdf_mitsuba  # noqa: F401  (before mitsuba)
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from nbrdf_testing import random_layers, write_network
from textured_fixture import write_textured

SPP = 4


@pytest.fixture(autouse=True)
def no_other_scene():
    """Mitsuba's symbolic call traces every live BSDF, and a recording must find each one's arrays
    among its inputs: the earlier tests' scenes are let go first."""
    gc.collect()


def scene_with(bsdf: dict):
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 24, "height": 24, "rfilter": {"type": "box"}}},
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "light": {"type": "point", "position": [3, 3, 4], "intensity": {"type": "rgb", "value": 40}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.2}}})


def replays_match(scene, update, steps: int = 4) -> None:
    """Records a render, then per step applies ``update(params, k)`` and compares the frozen render
    with an ordinary one of the same seed."""
    params = mi.traverse(scene)
    frozen = dr.freeze(lambda scene, seed: mi.render(scene, spp=SPP, seed=seed))
    for k in range(steps):
        update(params, k)
        params.update()
        image = np.asarray(frozen(scene, dr.opaque(mi.UInt32, 7)).numpy())
        reference = np.asarray(mi.render(scene, spp=SPP, seed=7).numpy())
        assert np.all(np.isfinite(image))
        np.testing.assert_allclose(image, reference, rtol=1e-5, atol=1e-6, err_msg=f"step {k}")
    assert frozen.n_recordings >= 1


@pytest.mark.parametrize("mode", ["opaque", "auto", "literal"])
def test_network_weights_updated_between_replays(mode, tmp_path, llvm_variant):
    path = write_network(tmp_path / "n.nbrdf.json", random_layers(seed=3))
    scene = scene_with({"type": "nbrdf", "filename": str(path), "backend": "jit", "jit_weights": mode})
    key = next(k for k in mi.traverse(scene).keys() if k.endswith("weights"))
    start = np.asarray(mi.traverse(scene)[key].numpy()).copy()

    def update(params, k):
        params[key] = mi.Float((start * (1 + 0.05 * k)).astype(np.float32))

    replays_match(scene, update)


def test_a_base_whose_network_becomes_non_zero(tmp_path, llvm_variant):
    """Recorded while the network is exactly zero (neither evaluated nor sampled outside a
    recording), replayed after it is not."""
    layers = [(np.zeros_like(W), np.zeros_like(b)) for W, b in random_layers(seed=4)]
    path = write_network(tmp_path / "b.nbrdf.json", layers)
    document = json.loads(path.read_text())
    document["base"] = {"type": "roughplastic", "alpha": 0.3}
    path.write_text(json.dumps(document))
    scene = scene_with({"type": "nbrdf", "filename": str(path), "backend": "jit", "jit_weights": "opaque"})
    key = next(k for k in mi.traverse(scene).keys() if k.endswith("weights"))
    size = dr.width(mi.traverse(scene)[key])
    noise = np.random.default_rng(5).standard_normal(size)
    params = mi.traverse(scene)
    frozen = dr.freeze(lambda scene, seed: mi.render(scene, spp=SPP, seed=seed))
    frozen(scene, dr.opaque(mi.UInt32, 7))  # recorded with the zero network
    for k in (1, 2):
        params[key] = mi.Float((0.02 * k * noise).astype(np.float32))
        params.update()
        image = np.asarray(frozen(scene, dr.opaque(mi.UInt32, 7)).numpy())
        reference = np.asarray(mi.render(scene, spp=SPP, seed=7).numpy())
        np.testing.assert_allclose(image, reference, rtol=1e-5, atol=1e-6)


def test_sampling_lobe_updated_between_replays(tmp_path, llvm_variant):
    path = write_network(tmp_path / "p.nbrdf.json", random_layers(seed=6))
    scene = scene_with({"type": "nbrdf", "filename": str(path), "backend": "jit", "sampling": "phong",
                        "exponent": 20.0, "specular_weight": 0.5})

    def update(params, k):
        params["sphere.bsdf.exponent"] = mi.Float(20.0 + 15.0 * k)

    replays_match(scene, update)


def test_merl_table(merl_table, llvm_variant):
    replays_match(scene_with({"type": "merl", "filename": str(merl_table), "backend": "jit"}), lambda params, k: None,
                  steps=2)


def test_a_textured_material_refuses_to_be_frozen(tmp_path, llvm_variant):
    """Dr.Jit 1.5 replays a Python BSDF's gathers from the buffer it recorded (nbrdf_mitsuba.freezing):
    a frozen render of an updated latent texture would show the old one, so it is refused, clearly."""
    path = write_textured(tmp_path / "t.nbrdf.json").path
    scene = scene_with({"type": "nbrdf", "filename": str(path), "backend": "jit", "jit_weights": "opaque"})
    frozen = dr.freeze(lambda scene, seed: mi.render(scene, spp=SPP, seed=seed))
    with pytest.raises(RuntimeError) as raised:
        frozen(scene, dr.opaque(mi.UInt32, 7))
    chain, error = [], raised.value
    while error is not None:  # Dr.Jit chains the BSDF's error under its own traversal's
        chain.append(str(error))
        error = error.__cause__
    assert any("spatially varying material cannot be rendered in a frozen function" in m for m in chain), chain
    image = np.asarray(mi.render(scene, spp=SPP, seed=7).numpy())  # unfrozen renders go on as before
    assert np.all(np.isfinite(image)) and image.max() > 0
