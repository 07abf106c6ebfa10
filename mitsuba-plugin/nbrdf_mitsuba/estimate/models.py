"""The models an estimate fits (a Mitsuba BSDF's parameters, or a network's) and the files it
writes."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from .errors import EstimateFailed
from .optimiser import Phase

MODELS = ("nbrdf", "nbrdf-no-prior", "principled", "roughconductor", "roughplastic")
#: Hidden width of the decoder's networks and of the common initialisation (network/mod.rs
#: DEFAULT_HIDDEN).
HIDDEN = 21


# -- the common initialisation (twin of network/mod.rs paper_init) --------------------------------
# Each constant is the Rust one's twin, held to the Rust source by tests/test_estimate_constants.py.

#: Half-width of the uniform initial weights (network/mod.rs INIT_RANGE).
INIT_RANGE = 0.05
#: SplitMix64's increment (rng.rs GOLDEN_GAMMA), and its output function's shifts and
#: multipliers (rng.rs mix64).
_GAMMA = 0x9E3779B97F4A7C15
_MIX_SHIFTS = (30, 27, 31)
_MIX_MULTIPLIERS = (0xBF58476D1CE4E5B9, 0x94D049BB133111EB)
#: The stream of the initial weights (rng.rs Stream::Init).
_INIT_STREAM = 3
_MASK = (1 << 64) - 1


def _mix64(z: int) -> int:
    (first, second, last), (m1, m2) = _MIX_SHIFTS, _MIX_MULTIPLIERS
    z = ((z ^ (z >> first)) * m1) & _MASK
    z = ((z ^ (z >> second)) * m2) & _MASK
    return z ^ (z >> last)


def common_initialisation(hidden: int = HIDDEN, seed: int = 0) -> np.ndarray:
    """The flat weights ``W1 b1 W2 b2 W3 b3`` every network of the autoencoder was trained
    from (``paper_init``: ``SplitMix64(seed, Init, 0)``, weights ``0.05 (2 u - 1)`` in float32
    with ``u = next_f64`` rounded to float32, zero biases)."""
    state = (_mix64(seed ^ _mix64(_INIT_STREAM + 1))) & _MASK
    flat = []
    for n_in, n_out in ((6, hidden), (hidden, hidden), (hidden, 3)):
        for _ in range(n_in * n_out):
            state = (state + _GAMMA) & _MASK
            u = np.float32((_mix64(state) >> 11) * (1.0 / (1 << 53)))
            flat.append(np.float32(INIT_RANGE) * (np.float32(2.0) * u - np.float32(1.0)))
        flat.extend([np.float32(0.0)] * n_out)
    return np.asarray(flat, dtype=np.float32)


# -- the models ------------------------------------------------------------------------------------


def _sigmoid(x):
    return dr.rcp(1.0 + dr.exp(-x))


def _logit(p: float) -> float:
    p = min(max(p, 1e-4), 1 - 1e-4)
    return math.log(p / (1 - p))


def _rgb(value) -> dict:
    return {"type": "rgb", "value": [float(v) for v in value]}


class Analytic:
    """A Mitsuba BSDF's parameters, each ``lo + (hi - lo) sigmoid(theta)``: ``(key, size, lo,
    hi, start)`` per parameter, ``key`` the traversed name below the BSDF's own."""

    PARAMETERS = {
        "principled": [("base_color.value", 3, 0.0, 1.0, 0.5), ("roughness.value", 1, 0.01, 1.0, 0.4),
                       ("metallic.value", 1, 0.0, 1.0, 0.2), ("specular", 1, 0.0, 1.0, 0.5)],
        "roughconductor": [("specular_reflectance.value", 3, 0.0, 1.0, 0.5), ("alpha.value", 1, 0.01, 1.0, 0.2)],
        "roughplastic": [("diffuse_reflectance.value", 3, 0.0, 1.0, 0.5), ("alpha", 1, 0.01, 1.0, 0.2)],
    }

    def __init__(self, kind: str):
        self.kind = kind
        self.parameters = self.PARAMETERS[kind]

    def element(self, workdir: Path) -> ET.Element:
        element = ET.Element("bsdf", type=self.kind)
        for key, size, _, _, start in self.parameters:
            name = key.split(".")[0]
            if size == 3:
                ET.SubElement(element, "rgb", name=name, value=f"{start}, {start}, {start}")
            else:
                ET.SubElement(element, "float", name=name, value=str(start))
        return element

    def phases(self, steps: int):
        theta = np.concatenate([[_logit((start - lo) / (hi - lo))] * size for _, size, lo, hi, start in self.parameters])
        return [Phase("analytic", theta, steps, self._apply, None)]

    def _values(self, theta):
        out, at = {}, 0
        for key, size, lo, hi, _ in self.parameters:
            # One gather per component: indexing a Dr.Jit array (value[0]) would detach it.
            parts = [lo + (hi - lo) * _sigmoid(dr.gather(type(theta), theta, at + k)) for k in range(size)]
            out[key] = mi.Color3f(*parts) if size == 3 else parts[0]
            at += size
        return out

    def _apply(self, params, prefix: str, theta) -> None:
        for key, value in self._values(theta).items():
            params[f"{prefix}.{key}"] = value

    def result(self, theta: np.ndarray) -> dict:
        values = {k: np.asarray(dr.detach(v).numpy(), dtype=np.float64).reshape(-1)
                  for k, v in self._values(mi.Float(theta)).items()}
        result = {"type": self.kind}
        for key, value in values.items():
            name = key.split(".")[0]
            result[name] = _rgb(value) if value.size == 3 else float(value[0])
        return result


class Network:
    """``nbrdf`` (latent code, then weights near the decoded ones) or ``nbrdf-no-prior``."""

    def __init__(self, prior: bool):
        self.prior = prior
        self.start = common_initialisation()

    def element(self, workdir: Path) -> ET.Element:
        path = workdir / "start.nbrdf.json"
        write_network(path, self.start, "start", {})
        element = ET.Element("bsdf", type="nbrdf")
        ET.SubElement(element, "string", name="filename", value=str(path))
        ET.SubElement(element, "string", name="jit_weights", value="opaque")
        ET.SubElement(element, "string", name="backend", value="jit")
        return element

    @staticmethod
    def _set_weights(params, prefix, weights):
        params[f"{prefix}.weights"] = weights


def _layers(flat: np.ndarray) -> list:
    """``(W, b)`` views of flat width-21 weights, ``W`` (inputs, outputs) as in the file (docs/design.md
    section 4: per layer the weights row-major, then the biases)."""
    layers, at = [], 0
    for n_in, n_out in ((6, HIDDEN), (HIDDEN, HIDDEN), (HIDDEN, 3)):
        W = flat[at:at + n_in * n_out].reshape(n_in, n_out)
        at += n_in * n_out
        layers.append((W, flat[at:at + n_out]))
        at += n_out
    return layers


def write_network(path: Path, flat: np.ndarray, name: str, provenance: dict, base: dict | None = None) -> None:
    """An ``*.nbrdf.json`` (docs/design.md section 4) of flat width-21 weights, on the analytic
    ``base`` (a ``mi.load_dict`` dictionary) where one is given; refuses non-finite weights."""
    flat = np.asarray(flat, dtype=np.float32)
    if flat.size != HIDDEN * HIDDEN + 11 * HIDDEN + 3 or not np.all(np.isfinite(flat)):
        raise EstimateFailed("internal: refusing to write a network with non-finite or missing weights")
    layers = [{"inputs": W.shape[0], "outputs": W.shape[1], "weights": [float(v) for v in W.ravel()],
               "bias": [float(v) for v in b]} for W, b in _layers(flat)]
    document = {"format": "nbrdf", "version": 1, "name": name, "layers": layers,
                **({"base": base} if base is not None else {}), "provenance": provenance}
    write_text(path, json.dumps(document))


def write_text(path: Path, text: str) -> None:
    """Writes a result; a failure is the estimate's (its work is lost), not the user's."""
    try:
        path.write_text(text)
    except OSError as error:
        raise EstimateFailed(f"{path}: cannot write the result: {error.strerror or error}") from None


def nbrdf_command() -> str | None:
    beside = Path(sys.executable).parent / "nbrdf"
    return str(beside) if beside.is_file() else shutil.which("nbrdf")


def fit_sampling(path: Path) -> str:
    """Stores ``nbrdf fit-phong``'s sampling in the network file (as for a trained network)."""
    command = nbrdf_command()
    if command is None:
        return "not fitted: the nbrdf command is not installed (the file samples the cosine lobe)"
    done = subprocess.run([command, "fit-phong", str(path)], capture_output=True, text=True)
    if done.returncode != 0:
        raise EstimateFailed(f"nbrdf fit-phong {path} failed: {done.stderr.strip().splitlines()[-1:]}")
    return "fit-phong"
