"""The NBRDF network in float64 NumPy: the ``*.nbrdf.json`` layout, the network input and the
forward pass. The one Python copy, shared by the tools (sphere images of networks and of
interpolated weights) and by the tests (``tests/nbrdf_testing.py``'s float64 oracle).

It is written from docs/design.md sections 2 and 4 with trigonometry and rotation matrices rather
than the Rust code's branch-free algebra, so that comparing the two compares two derivations.
Its Rust twins and the tests holding them together: docs/design.md, "Twins" (the twin table).

Directions are local unit vectors in ``(..., 3)`` arrays, in the library's order: view, then light.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

Layers = list[tuple[np.ndarray, np.ndarray]]

#: The largest argument of the output's ``exp`` (docs/design.md section 4): ``e^80`` stays far
#: below float32's maximum; the Rust kernel clamps there too (fastmath.rs, same name).
EXP_ARG_MAX = 80.0


# ---------------------------------------------------------------------------------------------
# The file (docs/design.md section 4)


def read_document(path: Path) -> dict:
    """The parsed ``*.nbrdf.json`` document."""
    return json.loads(Path(path).read_text(encoding="utf-8"))


def layers_of(document: dict) -> Layers:
    """(W, b) pairs of a parsed document, float64; W is (inputs, outputs)."""
    return [(np.asarray(layer["weights"], np.float64).reshape(layer["inputs"], layer["outputs"]),
             np.asarray(layer["bias"], np.float64)) for layer in document["layers"]]


def read_layers(path: Path) -> Layers:
    """(W, b) pairs of an ``*.nbrdf.json`` file, float64; W is (inputs, outputs)."""
    return layers_of(read_document(path))


def parameter_count(path: Path) -> int:
    """Weights and biases of an ``*.nbrdf.json`` file (675 for the paper's 6-21-21-3 network)."""
    return sum(len(layer["weights"]) + len(layer["bias"]) for layer in read_document(path)["layers"])


def sampling_of(path: Path) -> dict:
    """The file's stored sampling strategy (``{}`` when it has none)."""
    return read_document(path).get("sampling") or {}


def is_anisotropic(document: dict) -> bool:
    return bool(document.get("anisotropic", False))


# ---------------------------------------------------------------------------------------------
# Rusinkiewicz coordinates (docs/design.md section 2). Planar (3, n) arrays inside: the rotation
# matrices stack as (3, 3, n).


def rot_z(angle: np.ndarray) -> np.ndarray:
    """Rotations by ``angle`` (n,) about z, (3, 3, n)."""
    c, s = np.cos(angle), np.sin(angle)
    o, i = np.zeros_like(angle), np.ones_like(angle)
    return np.array([[c, -s, o], [s, c, o], [o, o, i]])


def rot_y(angle: np.ndarray) -> np.ndarray:
    """Rotations by ``angle`` (n,) about y, (3, 3, n)."""
    c, s = np.cos(angle), np.sin(angle)
    o, i = np.zeros_like(angle), np.ones_like(angle)
    return np.array([[c, o, s], [o, i, o], [-s, o, c]])


def apply(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotations (3, 3, n) applied to planar vectors (3, n)."""
    return np.einsum("ijn,jn->in", m, v)


def _unit_planar(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=0, keepdims=True)


def _planar(v: np.ndarray) -> np.ndarray:
    # Contiguous rows: NumPy's vectorised transcendentals may differ by an ulp from its strided loops.
    return np.ascontiguousarray(np.asarray(v, np.float64).reshape(-1, 3).T)


def _angles_planar(view: np.ndarray, light: np.ndarray):
    l, v = _unit_planar(light), _unit_planar(view)
    h = _unit_planar(l + v)
    theta_h = np.arccos(np.clip(h[2], -1, 1))
    phi_h = np.arctan2(h[1], h[0])
    d = apply(rot_y(-theta_h), apply(rot_z(-phi_h), l))
    theta_d = np.arccos(np.clip(d[2], -1, 1))
    phi_d = np.arctan2(d[1], d[0])
    return theta_h, phi_h, theta_d, phi_d, d


def rusinkiewicz(view: np.ndarray, light: np.ndarray):
    """``(theta_h, phi_h, theta_d, phi_d, d)`` of directions (..., 3) (normalised here): the angles
    (...), and ``d`` (..., 3), the light in the half vector's frame."""
    view, light = np.broadcast_arrays(np.asarray(view, np.float64), np.asarray(light, np.float64))
    shape = view.shape[:-1]
    theta_h, phi_h, theta_d, phi_d, d = _angles_planar(_planar(view), _planar(light))
    return (*(a.reshape(shape) for a in (theta_h, phi_h, theta_d, phi_d)), d.T.reshape(*shape, 3))


# ---------------------------------------------------------------------------------------------
# The network (docs/design.md section 4)


def network_input(view: np.ndarray, light: np.ndarray, anisotropic: bool = False) -> np.ndarray:
    """(..., 6) network input of directions (..., 3): ``[sin th, 0, cos th, d.x, d.y, d.z]``, or for
    an anisotropic network ``[sin th cos ph, sin th sin ph, cos th, d]`` (the half vector, then the
    difference vector)."""
    view, light = np.broadcast_arrays(np.asarray(view, np.float64), np.asarray(light, np.float64))
    theta_h, phi_h, _, _, d = _angles_planar(_planar(view), _planar(light))
    if not anisotropic:
        phi_h = np.zeros_like(theta_h)
    s = np.sin(theta_h)
    x = np.stack([s * np.cos(phi_h), s * np.sin(phi_h), np.cos(theta_h), d[0], d[1], d[2]], axis=1)
    return x.reshape(*view.shape[:-1], 6)


def forward(layers: Layers, inputs: np.ndarray) -> np.ndarray:
    """f_r (..., 3) of network inputs (..., 6): ReLU hidden layers, ``max(exp(x) - 1, 0)`` output
    (the argument clamped at :data:`EXP_ARG_MAX`, as in the Rust kernel)."""
    a = inputs.reshape(-1, inputs.shape[-1])
    for i, (w, b) in enumerate(layers):
        a = a @ w + b
        if i < len(layers) - 1:
            a = np.maximum(a, 0)
    return np.maximum(np.exp(np.minimum(a, EXP_ARG_MAX)) - 1, 0).reshape(*inputs.shape[:-1], -1)


def evaluate(layers: Layers, view: np.ndarray, light: np.ndarray, anisotropic: bool = False) -> np.ndarray:
    """f_r (..., 3) of directions (..., 3) (no horizon test: the caller masks)."""
    return forward(layers, network_input(view, light, anisotropic))


def lerp(a: Layers, b: Layers, t: float) -> Layers:
    """The weights ``(1 - t) a + t b``."""
    return [((1 - t) * wa + t * wb, (1 - t) * ba + t * bb) for (wa, ba), (wb, bb) in zip(a, b)]
