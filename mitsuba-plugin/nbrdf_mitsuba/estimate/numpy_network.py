"""The network in float64 NumPy, beside the optimiser's float64 Adam: its forward pass up to the
output's log-space value, the hand-written backward pass, and the weights' gradient of a render
from its recorded adjoints (:mod:`nbrdf_mitsuba.jit.adjoints`)."""

from __future__ import annotations

import numpy as np

from ..jit.fastmath import EXP_ARG_MAX
from .models import _layers


def hidden_and_output(layers: list, x: np.ndarray):
    """The hidden layers' pre-activations and the output's log-space value ``z`` (``f = max(e^z - 1,
    0)``). Float64 twin of ``jit.TracedNetwork.eval_input`` before its output's ``expm1``; held to
    ``nbrdf_tools.common.network.forward`` by tests/test_estimate.py::test_pull_penalty_against_a_float64_oracle."""
    (W1, b1), (W2, b2), (W3, b3) = layers
    z1 = x @ W1
    z1 += b1
    z2 = np.maximum(z1, 0) @ W2
    z2 += b2
    z3 = np.maximum(z2, 0) @ W3
    z3 += b3
    return z1, z2, z3


def backpropagate(layers: list, x: np.ndarray, z1: np.ndarray, z2: np.ndarray, g3: np.ndarray) -> np.ndarray:
    """The flat weights' gradient (``W1 b1 W2 b2 W3 b3``) of ``sum(g3 * z)`` over the rows of ``x``,
    ``z1``, ``z2`` (:func:`hidden_and_output`): the backward pass by hand."""
    (_, _), (W2, _), (W3, _) = layers
    g2 = np.multiply(g3 @ W3.T, z2 > 0)
    g1 = np.multiply(g2 @ W2.T, z1 > 0)
    ones = np.ones(len(x), x.dtype)  # column sums as matrix products: several times faster than sum(0)
    return np.concatenate([(x.T @ g1).ravel(), ones @ g1, (np.maximum(z1, 0).T @ g2).ravel(), ones @ g2,
                           (np.maximum(z2, 0).T @ g3).ravel(), ones @ g3])


def recorded_gradient(flat: np.ndarray, x: np.ndarray, adjoint: np.ndarray) -> np.ndarray:
    """The flat weights' gradient (float64) of a loss whose derivative by the network's output
    ``f`` at the inputs ``x`` (rows) is ``adjoint`` (rows, RGB): ``sum adjoint * df/dw``, in
    float32 like the render that recorded the adjoints (twice as fast as float64). ``df/dz`` is
    ``e^z`` where ``f = e^z - 1`` is positive and the exp argument unclamped, else 0, as the traced
    network (``jit.fastmath``); Dr.Jit's own derivative of it is the twin, held together by
    tests/test_adjoints.py::test_recorded_gradient_is_dr_jits."""
    layers = [(W.astype(np.float32), b.astype(np.float32)) for W, b in _layers(np.asarray(flat, np.float64))]
    x, adjoint = np.asarray(x, np.float32), np.asarray(adjoint, np.float32)
    z1, z2, z = hidden_and_output(layers, x)
    unclamped = (z > 0) & (z < EXP_ARG_MAX)
    g3 = np.multiply(adjoint * np.exp(np.where(unclamped, z, 0.0), dtype=np.float32), unclamped)
    return backpropagate(layers, x, z1, z2, g3).astype(np.float64)
