"""The NBRDF network in NumPy (float64): its input and its forward pass, for the scripts' figures
(sphere images of networks and of interpolated weights).

A deliberate second copy: the Rust twin is ``nbrdf_core::network`` (input: the half-vector
parametrisation of the paper, ``[sin th_h, 0, cos th_h, d.x, d.y, d.z]`` with ``d`` the light in
the half-vector frame; forward pass: two ReLU layers, then ``max(exp(x) - 1, 0)``), and
``tests/test_latent_report.py::test_numpy_network_matches_the_plugin`` holds them together by
comparing :func:`evaluate` with the ``nbrdf`` BSDF's Rust backend on random directions.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

Layers = list[tuple[np.ndarray, np.ndarray]]


def read_layers(path: Path) -> Layers:
    """(W, b) pairs of an ``*.nbrdf.json`` file, float64; W is (inputs, outputs)."""
    net = json.loads(Path(path).read_text())
    return [(np.array(layer["weights"], dtype=np.float64).reshape(layer["inputs"], layer["outputs"]),
             np.array(layer["bias"], dtype=np.float64)) for layer in net["layers"]]


def network_input(view: np.ndarray, light: np.ndarray) -> np.ndarray:
    """(..., 6) network input of local unit directions ``view`` and ``light`` (..., 3)."""
    h = light + view
    h = h / (np.linalg.norm(h, axis=-1, keepdims=True) + 1e-30)
    sin_th = np.hypot(h[..., 0], h[..., 1])
    safe = sin_th > 1e-7
    cos_ph = np.where(safe, h[..., 0] / np.where(safe, sin_th, 1.0), 1.0)
    sin_ph = np.where(safe, h[..., 1] / np.where(safe, sin_th, 1.0), 0.0)
    # The light rotated by -phi_h about z, then by -theta_h about y: d in the half-vector frame.
    tx = cos_ph * light[..., 0] + sin_ph * light[..., 1]
    ty = -sin_ph * light[..., 0] + cos_ph * light[..., 1]
    dx = h[..., 2] * tx - sin_th * light[..., 2]
    dz = sin_th * tx + h[..., 2] * light[..., 2]
    return np.stack([sin_th, np.zeros_like(sin_th), h[..., 2], dx, ty, dz], -1)


def forward(layers: Layers, inputs: np.ndarray) -> np.ndarray:
    """f_r (..., 3) of network inputs (..., 6): ReLU hidden layers, ``max(expm1(x), 0)`` output
    (the argument clamped at 80 against overflow)."""
    a = inputs.reshape(-1, inputs.shape[-1])
    for i, (w, b) in enumerate(layers):
        a = a @ w + b
        if i < len(layers) - 1:
            a = np.maximum(a, 0.0)
    return np.maximum(np.expm1(np.minimum(a, 80.0)), 0.0).reshape(*inputs.shape[:-1], -1)


def evaluate(layers: Layers, view: np.ndarray, light: np.ndarray) -> np.ndarray:
    """f_r (..., 3) of local unit directions (..., 3) (no horizon test: the caller masks)."""
    return forward(layers, network_input(view, light))


def lerp(a: Layers, b: Layers, t: float) -> Layers:
    """The weights ``(1 - t) a + t b``."""
    return [((1 - t) * wa + t * wb, (1 - t) * ba + t * bb) for (wa, ba), (wb, bb) in zip(a, b)]
