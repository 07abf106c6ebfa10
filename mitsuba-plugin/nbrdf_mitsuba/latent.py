"""The pretrained autoencoder's decoder as Dr.Jit arithmetic: a 32-value latent code to the 675
weights of a width-21 NBRDF, differentiable, so that gradients of a render chain through the
network's weights (``jit_weights="opaque"``) to the code.

Twin of ``nbrdf-core/src/latent/autoencoder/mod.rs`` ``AutoEncoder::decode_flat`` (the Rust
reference, which ``nbrdf ae decode`` runs; docs/design.md, "Twins", and section 7):
``w = clamp(tanh(c W1 + b1) W2 + b2) * std + mean`` into the training networks' range
``[min, max]`` per weight, the layers ``y = x W + b`` with ``W`` row-major ``inputs x outputs``.
The output is the flat network ``W1 b1 W2 b2 W3 b3``, the order the ``nbrdf`` BSDF traverses
as ``weights``.

The C ABI carries no models (they are embedded in the ``nbrdf`` command alone), so this module
reads the autoencoder's JSON file itself: ``$NBRDF_AUTOENCODER``, else the copy bundled into
the package by its build, else the repository's ``nbrdf-core/data/models/autoencoder.json``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import drjit as dr
import numpy as np

FORMAT_NAME = "nbrdf-autoencoder"
ENVIRONMENT = "NBRDF_AUTOENCODER"
_HERE = Path(__file__).resolve().parent
_CANDIDATES = (_HERE / "autoencoder.json", _HERE.parent.parent / "nbrdf-core" / "data" / "models" / "autoencoder.json")


class LatentError(ValueError):
    """The autoencoder file is missing or is not one."""


def autoencoder_path(path: str | os.PathLike | None = None) -> Path:
    """``path``, else ``$NBRDF_AUTOENCODER``, else the bundled or repository copy."""
    given = path if path is not None else os.environ.get(ENVIRONMENT)
    if given:
        if not Path(given).is_file():
            raise LatentError(f"autoencoder file {given} does not exist")
        return Path(given)
    for candidate in _CANDIDATES:
        if candidate.is_file():
            return candidate
    raise LatentError(f"the pretrained autoencoder was not found (looked at {', '.join(map(str, _CANDIDATES))}); "
                      f"set {ENVIRONMENT} to nbrdf-core/data/models/autoencoder.json of the nbrdf sources")


def _layer(layer: dict, origin: str) -> tuple[np.ndarray, np.ndarray]:
    n_in, n_out = int(layer["inputs"]), int(layer["outputs"])
    W = np.asarray(layer["weights"], dtype=np.float32)
    b = np.asarray(layer["bias"], dtype=np.float32)
    if W.size != n_in * n_out or b.size != n_out:
        raise LatentError(f"{origin}: a decoder layer {n_in} x {n_out} holds {W.size} weights and {b.size} biases")
    return W.reshape(n_in, n_out), b


class Decoder:
    """The decoder of an autoencoder file (by default the pretrained one).

    ``layers``: ``(W, b)`` float32 NumPy pairs, tanh between them, linear output; ``mean``,
    ``std``, ``low``, ``high``: the per-weight standardisation and clamp range; ``anchors``:
    the training materials' codes (``(k, 32)``), starting points of an estimate."""

    def __init__(self, path: str | os.PathLike | None = None):
        self.path = autoencoder_path(path)
        origin = str(self.path)
        try:
            data = json.loads(self.path.read_text())
        except (OSError, json.JSONDecodeError) as error:
            raise LatentError(f"{origin}: cannot read it as JSON ({error})") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT_NAME:
            raise LatentError(f"{origin}: not an NBRDF autoencoder (format '{FORMAT_NAME}')")
        try:
            self.layers = [_layer(layer, origin) for layer in data["decoder"]["layers"]]
            self.hidden = int(data["nbrdf_hidden"])
            self.mean = np.asarray(data["mean"], dtype=np.float32)
            self.std = np.asarray(data["std"], dtype=np.float32)
            self.low = np.asarray(data.get("min") or [], dtype=np.float32)
            self.high = np.asarray(data.get("max") or [], dtype=np.float32)
            self.anchors = np.asarray(data.get("anchors") or np.zeros((0, self.layers[0][0].shape[0])),
                                      dtype=np.float32)
        except (KeyError, TypeError, ValueError) as error:
            raise LatentError(f"{origin}: malformed autoencoder ({error})") from None
        self.code_size = self.layers[0][0].shape[0]
        self.parameter_count = self.layers[-1][0].shape[1]
        if self.mean.size != self.parameter_count or self.std.size != self.parameter_count:
            raise LatentError(f"{origin}: {self.mean.size} means and {self.std.size} deviations for "
                              f"{self.parameter_count} decoded weights")
        self._device = {}

    def _arrays(self, Float):
        """The decoder's constants as ``Float`` arrays (cached per type): each weight matrix
        transposed, so that output ``j`` reads the contiguous block ``W[:, j]``."""
        if Float not in self._device:
            layers = [(Float(np.ascontiguousarray(W.T).ravel()), Float(b), W.shape[0]) for W, b in self.layers]
            clamp = None
            if self.low.size == self.parameter_count and self.high.size == self.parameter_count:
                clamp = (Float(self.low), Float(self.high))
            self._device[Float] = (layers, Float(self.std), Float(self.mean), clamp)
        return self._device[Float]

    def decode(self, code):
        """The network weights (``W1 b1 W2 b2 W3 b3``) of ``code``, a Dr.Jit array of
        ``code_size`` values; same type (``mi.Float``, or a Float64 type for checks), with
        gradients when ``code`` has them."""
        Float = type(code)
        UInt = dr.uint32_array_t(Float)
        if dr.width(code) != self.code_size:
            raise LatentError(f"a code has {self.code_size} values, got {dr.width(code)}")
        layers, std, mean, clamp = self._arrays(Float)
        x = code
        for k, (Wt, b, n_in) in enumerate(layers):
            n_out = dr.width(b)
            # y_j = sum_i x_i W_ij + b_j: products laid out j-major, summed per block of n_in.
            index = dr.arange(UInt, n_in * n_out) % n_in
            y = dr.block_sum(dr.gather(Float, x, index) * Wt, n_in) + b
            x = dr.tanh(y) if k < len(layers) - 1 else y
        weights = dr.fma(x, std, mean)
        if clamp is not None:
            weights = dr.minimum(dr.maximum(weights, clamp[0]), clamp[1])
        return weights

    def code_distribution(self) -> tuple[np.ndarray, np.ndarray]:
        """The training codes' (anchors') mean and variance per value, float64: the Gaussian a
        code penalty holds an estimate's code to (it has no other notion of "near the training
        materials")."""
        if len(self.anchors) < 2:
            raise LatentError(f"{self.path}: {len(self.anchors)} training codes (anchors): a code prior needs two "
                              "or more")
        anchors = self.anchors.astype(np.float64)
        return anchors.mean(axis=0), anchors.var(axis=0)

    def decode_numpy(self, code) -> np.ndarray:
        """``decode`` of a NumPy code, as float32 NumPy (no gradients)."""
        import mitsuba as mi

        return np.asarray(self.decode(mi.Float(np.asarray(code, dtype=np.float32))).numpy(), dtype=np.float32)
