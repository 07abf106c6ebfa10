"""What a step renders, written to be frozen (``dr.freeze``) by :class:`.estimator.Estimator`:
the image loss, the render seeds and the three step functions (a recorded network step, a step
Dr.Jit differentiates, a loss without gradients). Everything a step function reads is an argument
or made inside it, so that a replay sees the scene's current values."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..jit.adjoints import AdjointRecorder
from .models import _mix64


def image_loss(images: list, references: list):
    """Mean squared error relative to ``1 + reference``, ``((x - r) / (1 + r))^2``, over every
    view, pixel and channel: the first-order twin of the squared error of ``ln(1 + x)`` (the
    weight keeps highlights from swamping the rest of the object), but linear in the render.
    ``mi.render`` draws the adjoint pass's samples apart from the primal's, so a step's gradient
    is the loss's derivative at the noisy render times an independent derivative of the render;
    linear in the render, that derivative's mean is its value at the mean render, and the fit
    settles where the mean render is the reference. The log's was biased bright where renders
    are noisy, most around a highlight narrower than a pixel, which it fitted too wide
    (docs/experiments.md, Estimation: "The image loss linear in the render"). Held to a float64
    oracle and to that property by tests/test_estimate.py::test_image_loss_is_linear_in_the_render."""
    total = 0.0
    for image, reference in zip(images, references):
        d = (image - reference) / (1.0 + reference)
        total = total + dr.mean(dr.square(d), axis=None)
    return total / len(images)


def render_seed(seed: int, step: int, view: int) -> int:
    return (_mix64((seed << 32) ^ (step << 8) ^ view) >> 33) & 0x7FFFFFFF


def render_views(scene, params, integrator, views, seeds, spp) -> list:
    """One render of each of ``views`` (sensor indices) at its seed; ``params``: what the renders
    differentiate (None: nothing)."""
    return [mi.render(scene, params, sensor=view, integrator=integrator, spp=spp, seed=seed)
            for view, seed in zip(views, seeds)]


def recorded_renders(recorder: AdjointRecorder):
    """The renders of a recorded step and their backward pass, ``f(scene, integrator, references,
    seeds, views, spp, capacity) -> (loss, recorder.received())``: what :class:`Estimator` freezes.
    Everything it reads is an argument or made inside (the recorder's buffers), so that a replay
    sees the scene's current values; ``views``, ``spp`` and ``capacity`` are part of the frozen
    function's key (a new value records anew)."""

    def renders(scene, integrator, references, seeds, views, spp, capacity):
        recorder.start(capacity)
        try:
            loss = image_loss(render_views(scene, recorder.parameters, integrator, views, seeds, spp), references)
            dr.backward(loss)
            return loss, recorder.received()
        finally:
            recorder.stop()

    return renders


def differentiated_renders(params: mi.SceneParameters):
    """The renders of a step differentiated by Dr.Jit (analytic models, or a network without a
    recorder), ``f(scene, integrator, references, seeds, views, spp) -> loss``, its backward pass
    done: the gradients reach the variables ``params`` were set from. What :class:`Estimator`
    freezes for the analytic models (a frozen function takes gradients to what its inputs depend
    on); a network's is traced."""

    def renders(scene, integrator, references, seeds, views, spp):
        loss = image_loss(render_views(scene, params, integrator, views, seeds, spp), references)
        dr.backward(loss)
        return loss

    return renders


def forward_loss(scene, integrator, references, seeds, views, spp):
    """The image loss of one render per view, without gradients: what :class:`Estimator` freezes for
    the screening of codes and the held-out view's judgement (``views`` and ``spp`` are part of the
    frozen function's key)."""
    with dr.suspend_grad():
        return image_loss(render_views(scene, None, integrator, views, seeds, spp), references)
