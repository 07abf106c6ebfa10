"""The estimate's recorded adjoints (``nbrdf_mitsuba.jit.adjoints``) and the weights' gradient
NumPy computes from them (``estimate.numpy_network.recorded_gradient``): the same gradient as
Dr.Jit's own derivative of the traced network, for the formula alone and for whole estimate steps
(plain, ``twosided`` and shared BSDFs; the weight phase and the code phase through the decoder; a
scene with more evaluations than the first capacity)."""

from __future__ import annotations

from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from test_estimate import AE_FILE, layout_scene, render_views, write_scene


def decoded_mean_network() -> np.ndarray:
    """A realistic network: the autoencoder's decoding of its training codes' mean."""
    from nbrdf_mitsuba.latent import Decoder

    decoder = Decoder(AE_FILE)
    return decoder.decode_numpy(decoder.anchors.mean(axis=0)).astype(np.float64)


def relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def test_recorded_gradient_is_dr_jits(llvm_variant):
    """``sum adjoint * f`` at random direction pairs: NumPy's gradient from the network inputs and
    adjoints equals Dr.Jit's derivative of ``jit.TracedNetwork.eval`` (opaque weights), also where
    some outputs are zero (ReLU) and with a clamped exp argument."""
    from nbrdf_mitsuba import jit
    from nbrdf_mitsuba.estimate.models import _layers
    from nbrdf_mitsuba.estimate.numpy_network import recorded_gradient

    rng = np.random.default_rng(3)
    flat = decoded_mean_network()
    flat[-1] = 85.0  # the blue channel's exp argument clamped: no gradient there
    traced = jit.TracedNetwork(_layers(flat.astype(np.float32)), weights="opaque")
    n = 20000
    u = [mi.Float(row.astype(np.float32)) for row in rng.random((4, n))]
    view, light = jit.uniform_hemisphere(u[0], u[1]), jit.uniform_hemisphere(u[2], u[3])
    adjoint = rng.normal(size=(n, 3))
    dr.enable_grad(traced.flat)
    traced.refresh()
    f = traced.eval(view, light)
    loss = dr.sum(sum(f[c] * mi.Float(adjoint[:, c].astype(np.float32)) for c in range(3)))
    dr.backward(loss)
    reference = np.asarray(dr.grad(traced.flat).numpy(), np.float64)
    x = np.stack([np.zeros(n) if c is None else np.asarray(c.numpy(), np.float64)
                  for c in jit.network_input(view, light)], axis=1)
    gradient = recorded_gradient(flat, x, adjoint)
    blue = [609 + 3 * k + 2 for k in range(21)] + [674]  # W3[:, 2] and b3[2]
    assert np.all(reference[blue] == 0) and np.all(gradient[blue] == 0)
    assert relative_difference(gradient, reference) < 1e-4


def estimator(scene: Path, images: list[Path], workdir: Path, spp: int = 4):
    from nbrdf_mitsuba.estimate.estimator import Estimator
    from nbrdf_mitsuba.estimate.models import Network
    from nbrdf_mitsuba.estimate.scene import Scene

    return Estimator(Scene(scene, "mat", {}), Network(True), images, spp, 0, 3, workdir)


def both_gradients(est, phase, theta) -> tuple[np.ndarray, np.ndarray]:
    """(recorded, Dr.Jit's own traced) gradient of one step, the same render seeds."""
    recorder = est.recorder
    assert recorder is not None
    value, recorded = est.loss_and_grad(phase, theta, 5)
    recorder, est.recorder = est.recorder, None  # None where the step fell back to Dr.Jit's derivative
    dr.set_flag(dr.JitFlag.KernelFreezing, False)  # traced, as written, not replayed
    try:
        reference_value, reference = est.loss_and_grad(phase, theta, 5)
    finally:
        est.recorder = recorder
        dr.set_flag(dr.JitFlag.KernelFreezing, True)
    assert value == pytest.approx(reference_value, rel=1e-6)
    return recorded, reference


@pytest.mark.parametrize("layout", ["top", "twosided", "shared"])
def test_a_weight_step_has_dr_jits_gradient(llvm_variant, tmp_path, layout):
    from nbrdf_mitsuba.estimate.models import Network
    from nbrdf_mitsuba.estimate.optimiser import Phase

    scene = write_scene(tmp_path / "top.xml") if layout == "top" else layout_scene(tmp_path / "s.xml", layout)
    images = render_views(scene, tmp_path, spp=16)
    est = estimator(scene, images, tmp_path)
    theta = decoded_mean_network()
    recorded, reference = both_gradients(est, Phase("weights", theta, 1, Network._set_weights, None), theta)
    assert np.any(reference != 0)
    assert relative_difference(recorded, reference) < 1e-3


def test_a_code_step_has_dr_jits_gradient_through_the_decoder(llvm_variant, tmp_path):
    from nbrdf_mitsuba.estimate.optimiser import Phase
    from nbrdf_mitsuba.latent import Decoder

    scene = write_scene(tmp_path / "scene.xml")
    images = render_views(scene, tmp_path, spp=16)
    est = estimator(scene, images, tmp_path)
    decoder = Decoder(AE_FILE)

    def apply(params, prefix, code):
        params[f"{prefix}.weights"] = decoder.decode(code)

    code = decoder.anchors.mean(axis=0).astype(np.float64)
    recorded, reference = both_gradients(est, Phase("code", code, 1, apply, None), code)
    assert recorded.shape == code.shape and np.any(reference != 0)
    assert relative_difference(recorded, reference) < 1e-3


@pytest.mark.parametrize("most", [None, 16])
def test_more_evaluations_than_the_capacity_grow_it_and_keep_the_gradient(llvm_variant, tmp_path, monkeypatch,
                                                                          most):
    """A second sphere the first reflects (paths of two bounces on the network): a capacity of a
    few evaluations overflows, the step is taken again with room for all, and the gradient is
    Dr.Jit's; where a scene needs more records than ``MAX_RECORDS``, Dr.Jit's own derivative takes
    over for the rest of the estimate."""
    from nbrdf_mitsuba.estimate import estimator as E
    from nbrdf_mitsuba.estimate.models import Network
    from nbrdf_mitsuba.estimate.optimiser import Phase

    if most is not None:
        monkeypatch.setattr(E, "MAX_RECORDS", most)
    scene = layout_scene(tmp_path / "two.xml", "shared")
    images = render_views(scene, tmp_path, spp=16)
    est = estimator(scene, images, tmp_path)
    est.record_capacity = 8
    theta = decoded_mean_network()
    recorded, reference = both_gradients(est, Phase("weights", theta, 1, Network._set_weights, None), theta)
    if most is None:
        assert est.record_capacity > 8 and est.recorder is not None
    else:
        assert est.recorder is None
    assert relative_difference(recorded, reference) < 1e-3


def test_an_overflowing_recorder_says_so_and_isotropic_rgb_only(llvm_variant, tmp_path):
    from nbrdf_mitsuba.estimate import renders
    from nbrdf_mitsuba.jit.adjoints import RecorderOverflow, decode_records

    scene = write_scene(tmp_path / "scene.xml")
    images = render_views(scene, tmp_path, spp=16)
    est = estimator(scene, images, tmp_path)
    recorder = est.recorder
    recorder.start(4)
    images = renders.render_views(est.scene, recorder.parameters, est.integrator, est.views, est.seeds(0), est.spp)
    dr.backward(renders.image_loss(images, est.view_references()))
    with pytest.raises(RecorderOverflow) as raised:
        decode_records(recorder.received(), 4)
    assert raised.value.needed > 4 and "room for 4" in str(raised.value)
    with pytest.raises(ValueError, match="isotropic RGB"):
        recorder.probe([mi.Float(0)] * 3, [mi.Float(0)] * 6, mi.Bool(True))
    recorder.stop()
    assert not recorder.recording()


def weight_steps(est, thetas) -> list[tuple[float, np.ndarray]]:
    from nbrdf_mitsuba.estimate.models import Network
    from nbrdf_mitsuba.estimate.optimiser import Phase

    phase = Phase("weights", thetas[0], len(thetas), Network._set_weights, None)
    return [est.loss_and_grad(phase, theta, step) for step, theta in enumerate(thetas)]


def test_frozen_steps_replay_what_traced_steps_compute(llvm_variant, tmp_path):
    """The recorded step is frozen (``dr.freeze``): after its first recordings the steps are replays,
    and each gives the loss and gradient the same step traced gives (Dr.Jit's freezing switched
    off), at new weights and new render seeds."""
    scene = write_scene(tmp_path / "scene.xml")
    images = render_views(scene, tmp_path, spp=16)
    est = estimator(scene, images, tmp_path)
    start = decoded_mean_network()
    thetas = [start * (1 + 0.02 * k) for k in range(4)]
    frozen = weight_steps(est, thetas)
    assert est._recorded_renders.frozen and est._recorded_renders.recordings < len(thetas)
    dr.set_flag(dr.JitFlag.KernelFreezing, False)
    try:
        traced = weight_steps(est, thetas)
    finally:
        dr.set_flag(dr.JitFlag.KernelFreezing, True)
    assert len({value for value, _ in frozen}) == len(thetas)  # new weights and seeds each step
    for (value, gradient), (traced_value, traced_gradient) in zip(frozen, traced):
        assert value == pytest.approx(traced_value, rel=1e-6)
        assert relative_difference(gradient, traced_gradient) < 1e-5


class HiddenAlbedo:
    """A Python BSDF (made per variant) keeping its albedo where Dr.Jit's traversal does not look:
    in a plain object's attribute."""

    @staticmethod
    def make(props):
        class Hidden(mi.BSDF):
            def __init__(self, props):
                mi.BSDF.__init__(self, props)
                self.hidden = type("Holder", (), {})()
                self.hidden.albedo = mi.Float(np.float32(0.5)) + mi.Float(np.zeros(1, np.float32))
                self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
                self.m_components = [self.m_flags]

            def eval(self, ctx, si, wo, active=True):
                return mi.Color3f(self.hidden.albedo * dr.maximum(wo.z, 0) / dr.pi)

            def pdf(self, ctx, si, wo, active=True):
                return mi.warp.square_to_cosine_hemisphere_pdf(wo)

            def eval_pdf(self, ctx, si, wo, active=True):
                return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

            def sample(self, ctx, si, sample1, sample2, active=True):
                bs = dr.zeros(mi.BSDFSample3f)
                bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
                bs.pdf = self.pdf(ctx, si, bs.wo)
                bs.eta = 1.0
                bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
                return bs, mi.Color3f(self.hidden.albedo)

        return Hidden(props)


def test_another_scene_alive_leaves_the_steps_traced(llvm_variant, tmp_path):
    """A frozen function's recording must find every live BSDF's arrays among its inputs: with a
    BSDF alive that hides them (here another scene's Python BSDF), the first recording fails and
    the steps are traced, with Dr.Jit's gradient."""
    from nbrdf_mitsuba.estimate.models import Network
    from nbrdf_mitsuba.estimate.optimiser import Phase

    mi.register_bsdf("hidden_albedo_test", HiddenAlbedo.make)
    other = mi.load_dict({"type": "scene", "sphere": {"type": "sphere", "bsdf": {"type": "hidden_albedo_test"}}})
    scene = write_scene(tmp_path / "scene.xml")
    images = render_views(scene, tmp_path, spp=16)
    est = estimator(scene, images, tmp_path)
    theta = decoded_mean_network()
    recorded, reference = both_gradients(est, Phase("weights", theta, 1, Network._set_weights, None), theta)
    assert not est._recorded_renders.frozen and other.shapes()
    assert relative_difference(recorded, reference) < 1e-3
