"""Anisotropic NBRDFs in the plugin (issue 18): both backends evaluate an anisotropic network
(file format version 2) with the half vector's azimuth in the shading frame, against a float64
NumPy oracle; the BSDF flags say Anisotropic; and rotating a surface's ``to_world`` about its normal
rotates the network's highlight exactly as it rotates that of Mitsuba's anisotropic
``roughconductor`` (the shading frame's tangent is the x axis of both)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from nbrdf_testing import (apply, bsdf_eval, f32, grazing_pairs, nbrdf_reference, random_layers,
                           random_pairs, rot_z, write_network)


def anisotropic_layers(seed: int = 4):
    """A random network whose value depends strongly on the half vector's x and y."""
    layers = random_layers(hidden=16, seed=seed)
    w1, b1 = layers[0]
    w1 = w1.copy()
    w1[:2] *= 6.0
    return [(w1, b1), *layers[1:]]


@pytest.fixture
def aniso_file(tmp_path):
    return write_network(tmp_path / "aniso.nbrdf.json", anisotropic_layers(), anisotropic=True)


def both(path):
    base = {"type": "nbrdf", "filename": str(path)}
    return {backend: mi.load_dict({**base, "backend": backend}) for backend in ("rust", "jit")}


def test_both_backends_match_the_float64_oracle(llvm_variant, aniso_file):
    view, light = random_pairs(2000, 31)
    g_view, g_light = grazing_pairs(500, 32)
    view, light = f32(np.concatenate([view, g_view], 1)), f32(np.concatenate([light, g_light], 1))
    layers = anisotropic_layers()
    ref = nbrdf_reference([(w.astype(np.float64), b.astype(np.float64)) for w, b in layers], light, view,
                          anisotropic=True)
    iso = nbrdf_reference([(w.astype(np.float64), b.astype(np.float64)) for w, b in layers], light, view)
    # The oracle's phi_h matters for this network: the test can tell the encodings apart.
    assert np.max(np.abs(ref - iso) / (1 + ref)) > 0.1
    for backend, bsdf in both(aniso_file).items():
        got = bsdf_eval(bsdf, view, light)
        err = np.abs(got - ref) / (1 + ref)
        assert np.max(err) <= 2e-5, (backend, np.max(err))


def test_rotation_about_the_normal_follows_the_oracle(llvm_variant, aniso_file):
    """Rotating view and light together about z changes the value as the oracle's phi_h does."""
    view, light = random_pairs(500, 33)
    layers = [(w.astype(np.float64), b.astype(np.float64)) for w, b in anisotropic_layers()]
    angle = np.full(view.shape[1], 0.9)
    rv, rl = f32(apply(rot_z(angle), view)), f32(apply(rot_z(angle), light))
    ref = nbrdf_reference(layers, rl, rv, anisotropic=True)
    assert np.mean(np.abs(ref - nbrdf_reference(layers, f32(light), f32(view), anisotropic=True))) > 0.05 * ref.mean()
    for bsdf in both(aniso_file).values():
        got = bsdf_eval(bsdf, rv, rl)
        assert np.max(np.abs(got - ref) / (1 + ref)) <= 2e-5


def test_flags(llvm_variant, aniso_file, tmp_path):
    iso_file = write_network(tmp_path / "iso.nbrdf.json", anisotropic_layers())
    for backend, bsdf in both(aniso_file).items():
        assert bsdf.flags() & mi.BSDFFlags.Anisotropic, backend
        assert "anisotropic = true" in str(bsdf)
    for backend, bsdf in both(iso_file).items():
        assert not bsdf.flags() & mi.BSDFFlags.Anisotropic, backend


def plate_scene(bsdf: dict, angle_deg: float) -> dict:
    """A square plate turned by ``angle_deg`` about its normal (its tangent frame turns, its
    shape does not), lit by a point light: emitter sampling only, so renders with the same seed
    trace the same paths whatever the BSDF."""
    return {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": {"type": "perspective", "fov": 50,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, -2.5, 2.0], target=[0, 0, 0], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": 40, "height": 32, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 1}},
        "plate": {"type": "rectangle", "to_world": mi.ScalarTransform4f().rotate([0, 0, 1], angle_deg),
                  "bsdf": bsdf},
        "light": {"type": "point", "position": [0.6, 1.2, 2.0], "intensity": {"type": "rgb", "value": 10.0}},
    }


def render(bsdf: dict, angle_deg: float = 0.0) -> np.ndarray:
    return np.array(mi.render(mi.load_dict(plate_scene(bsdf, angle_deg)), seed=3))


def relative_difference(a, b) -> float:
    return float(np.abs(a - b).mean() / max(a.mean(), 1e-12))


@pytest.mark.parametrize("backend", ["rust", "jit"])
def test_to_world_rotates_the_highlight_like_roughconductor(llvm_variant, tmp_path, backend):
    """Turning the plate by 90 degrees turns the tangent: Mitsuba's roughconductor then renders
    as with alpha_u and alpha_v swapped, and the network as the network whose half-vector inputs
    are turned by -90 degrees (``x0' = x1, x1' = -x0``: first-layer rows ``W0' = -W1, W1' = W0``)."""
    symbolic = backend == "jit"
    dr.set_flag(dr.JitFlag.SymbolicLoops, symbolic)
    dr.set_flag(dr.JitFlag.SymbolicCalls, symbolic)

    def conductor(au, av):
        return {"type": "roughconductor", "distribution": "ggx", "alpha_u": au, "alpha_v": av}

    turned = render(conductor(0.05, 0.3), 90)
    assert relative_difference(turned, render(conductor(0.3, 0.05))) < 1e-3
    assert relative_difference(turned, render(conductor(0.05, 0.3))) > 0.1

    layers = anisotropic_layers()
    (w1, b1), rest = layers[0], layers[1:]
    w1_turned = w1.copy()
    w1_turned[0], w1_turned[1] = -w1[1], w1[0]
    path = write_network(tmp_path / "a.nbrdf.json", layers, anisotropic=True)
    path_turned = write_network(tmp_path / "b.nbrdf.json", [(w1_turned, b1), *rest], anisotropic=True)
    net = {"type": "nbrdf", "filename": str(path), "backend": backend}
    turned = render(net, 90)
    assert turned.mean() > 0
    assert relative_difference(turned, render({**net, "filename": str(path_turned)})) < 1e-3
    assert relative_difference(turned, render(net)) > 0.1
    # An isotropic network does not see the turn.
    iso = {**net, "filename": str(write_network(tmp_path / "i.nbrdf.json", layers))}
    assert relative_difference(render(iso, 90), render(iso)) < 1e-3
