"""``python -m nbrdf_mitsuba.estimate SCENE.xml --images IMG... --bsdf-id ID -o OUT``: a material
estimated from images of a known scene by differentiable rendering (Mitsuba's ``prb``).

The scene holds the object whose BSDF (the one with id ``ID``, whatever its type) is to be
estimated, its sensors and emitters; image ``i`` (EXR, linear RGB) is the scene seen by its
``i``-th sensor. That BSDF is replaced by the model (``--model``) and the model's parameters
are optimised by Adam on the images' error relative to ``1 + radiance`` (:func:`image_loss`), every
view each step:

* ``nbrdf`` (default): first the 32-value latent code through the pretrained decoder
  (:mod:`nbrdf_mitsuba.latent`: the gradient of the weights, which ``jit_weights="opaque"``
  makes scene parameters, chained to the code), starting from the best of 49 training codes,
  with a Gaussian penalty on the code (the training codes' mean and spread); then the 675
  weights themselves, held near the decoded network by a pull in function space (the squared
  difference of the two networks' log-space outputs at fixed direction pairs over the whole
  hemisphere, so that where no image constrains the BRDF it stays the decoded one). Both
  penalties' strengths are chosen together by a held-out training view (``--prior-weight`` and
  ``--code-prior`` fix them instead): the code is fitted on every view once per strength of
  ``CODE_PRIOR_STRENGTHS`` (the screening of the starts shared); from each decoded code every
  strength of ``PRIOR_STRENGTHS`` fits the weights on all views but the last (the held-out one)
  for a share of the steps; the pair with the lowest loss on the held-out view is kept, and its
  fit goes on over every view for the rest of the weight phase's steps. A candidate or final
  network whose directional albedo exceeds its bound (:func:`albedo_bound`: 1, or the network's
  own albedo where the lights fall square if higher, plus ``ALBEDO_MARGIN``; at most
  ``ALBEDO_BOUND``) is no material and is not kept; the prior is then attempted again with
  other render seeds, up to ``PRIOR_ATTEMPTS`` times, before the estimate falls back to the
  ``nbrdf-no-prior`` estimate itself. A fixed ``--prior-weight`` holds no view out: the
  code's strength is then ``--code-prior``, else 0. Writes an ``*.nbrdf.json`` with ``nbrdf
  fit-phong``'s sampling.
* ``nbrdf-no-prior``: the weights alone, from the common initialisation (the trainer's seed-0
  start, twin of ``network/mod.rs`` ``paper_init``).
* ``principled``, ``roughconductor``, ``roughplastic``: Mitsuba's BSDFs' parameters (colours and
  roughness through a sigmoid into their ranges). Writes the fitted BSDF as a ``mi.load_dict``
  JSON dictionary.

Robust: images of the wrong count or size, non-finite pixels, no BSDF with the id, a variant
without automatic differentiation or images that do not depend on the BSDF are errors (exit
status 2, one line naming the problem). A step whose loss or gradient is not finite (or whose
weights the BSDF rejects), or whose loss has run away to ten times the phase's lowest, is taken
back and the step size halved; no non-finite result is ever written. Deterministic for a seed
(each render's seed derives from it).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from . import _llvm

_llvm.configure()  # must precede the first import of drjit

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

MODELS = ("nbrdf", "nbrdf-no-prior", "principled", "roughconductor", "roughplastic")
#: Share of the steps spent on the latent code before the weights (model ``nbrdf``). The weight
#: phase still lowered the loss steeply at its end with 0.6 (docs/experiments.md, issue 33).
CODE_SHARE = 0.4
#: Adam step sizes per kind of variable. The code's is a fraction of its training spread (about
#: 1.6 per value): at 0.05 the code moved less than one spread in a whole phase and its loss
#: hardly fell (docs/experiments.md, issue 33). The analytic models' 0.1 settled higher than 0.05
#: (principled on colodur_napoli_4f: novel-view RMSE 0.015 against 0.009 at 100 steps).
LEARNING_RATES = {"code": 0.2, "weights": 0.003, "analytic": 0.05}
#: Times the step may halve after non-finite or run-away losses before the estimate gives up.
MAX_HALVINGS = 12
#: A step whose loss is this many times the phase's lowest so far has run away: at 2 spp on
#: 128x128 images a network's loss grew 1.5x a step from 0.009 to 10, a finite loss the
#: non-finite check let through (docs/experiments.md, issue 33, round 20). A step's Monte Carlo
#: noise stays far below this factor.
RUNAWAY_FACTOR = 10.0
#: Training codes tried as starts of the latent phase (evenly spaced through the anchors), each
#: judged by one render per view at a quarter of the samples (a few steps' cost in all): on a
#: MERL truth the best of 49 started 15 % lower in loss than the best of 9, a gap the code phase
#: took its whole length to close (docs/experiments.md, issue 33).
SCREENED_STARTS = 48
#: Strengths of the weight phase's pull toward the decoded network (:func:`output_pull`), one
#: picked per estimate by the held-out training view: a hold, and none at all (the decoded start
#: only). A pull in weight space (the autoencoder's standardised weights) held the weights, not
#: the BRDF, and lost to the network without the prior on a MERL truth by more than this one
#: does; the held-out view never chose a strength of 1 (docs/experiments.md, issue 33, round 10).
PRIOR_STRENGTHS = (1e-1, 0.0)
#: Uniform direction pairs (above the horizon, a fixed draw) at which the pull compares the networks.
PULL_PAIRS = 4096
PULL_SEED = 7
#: The start the estimate falls back to where the prior's network is no material (its albedo above
#: :func:`albedo_bound`): the common initialisation, no pull, the ``nbrdf-no-prior`` estimate. It was a
#: candidate of the held-out choice until round 13; where the view chose it, the decoded network
#: was either better on the novel views (iris_purple_gem, 0.0401 against 0.0484) or no material
#: (albedo 1.6-227), which the albedo check catches (docs/experiments.md, issue 33, round 13).
COMMON_START = "common"
#: The strength where no view can be held out (one image) or no weight step is left to judge.
FALLBACK_STRENGTH = 1e-1
#: Strengths of the code phase's Gaussian penalty (the training codes' mean and spread), each a
#: code phase of its own whose decoded start runs every candidate of the weight phase; the held-out
#: view judges the pairs together. 0 is the code phase without the penalty; 1e-3 kept the codes
#: near the training codes and lowered the novel-view error on five of the seven report materials,
#: raised it on two (docs/experiments.md, issue 33).
CODE_PRIOR_STRENGTHS = (0.0, 1e-3)
#: The code penalty's strength where nothing is chosen (one image, no weight step, or a fixed
#: ``--prior-weight``): none, the code phase as it was before the penalty.
FALLBACK_CODE_PRIOR = 0.0
#: Share of the weight phase's steps each candidate strength is fitted for before it is judged.
CANDIDATE_SHARE = 0.5
#: The held-out view is judged with this many times the samples of a training render (one render
#: per candidate, the same seed for all: the candidates' differences are not Monte Carlo noise).
HELD_OUT_SPP_FACTOR = 4
#: A decoded candidate whose network reflects more than this share of the light it receives (its
#: directional albedo, at some incidence angle and channel) is not a material: it is never chosen,
#: nor kept as the final network. The held-out view cannot see it, because the excess lies where no
#: training light fell: a decoded candidate chosen by the view gave a final network with an albedo
#: of 15 and 5x the novel-view error. Above 1 because an estimate carries the
#: images' noise: paper_white's estimates reach 1.16 (its truth's network 0.98), while the 432
#: decoded training codes stay below 0.73 (docs/experiments.md, issue 33, round 13). The ceiling
#: of :func:`albedo_bound`.
ALBEDO_BOUND = 1.5
#: Incidence angles (degrees, at most) where the lights fall square onto the object: there the
#: images constrain the albedo best, and an estimate's albedo above 1 is what they ask for (paper_white's
#: 1.14 at normal incidence), not light where no image shows it (ibiza_sunset at seed 2: 0.46 up to
#: 45 degrees, 1.42 at 80; docs/experiments.md, issue 33, round 16).
ALBEDO_LIT_INCIDENCE = 45
#: Share above 1 (or above the network's own albedo up to ``ALBEDO_LIT_INCIDENCE``) that the bound
#: allows at any incidence angle: the quadrature's error and the images' noise.
ALBEDO_MARGIN = 0.1
#: Incidence angles (degrees) of the albedo check, and its half-vector grid: ``theta_h`` by
#: ``(pi / 2) u^2`` (dense at the specular peak), ``phi_h`` uniform.
ALBEDO_INCIDENCE = (0, 15, 30, 45, 60, 70, 80, 87)
ALBEDO_GRID = (96, 48)
#: Attempts of the prior (code phases, candidates, final fit) before the fallback to the common
#: start, each with its own render seeds: which code the code phase reaches is decided by the
#: renders' noise (the same screened start at every seed), and on ibiza_sunset a second or third
#: attempt gave a material where the first had not (novel-view RMSE 0.0278 and 0.0248 against the
#: fallback's 0.0367 and 0.0427; docs/experiments.md, issue 33, round 13).
PRIOR_ATTEMPTS = 3
#: Offset of the estimate's seed from one attempt to the next.
ATTEMPT_SEED_STRIDE = 7919
INIT_RANGE = 0.05  # network/mod.rs INIT_RANGE
HIDDEN = 21


class EstimateError(Exception):
    """A user error: printed as one line, exit status 2."""


# -- the common initialisation (twin of network/mod.rs paper_init) --------------------------------

_GAMMA = 0x9E3779B97F4A7C15
_MASK = (1 << 64) - 1
_INIT_STREAM = 3  # rng.rs Stream::Init


def _mix64(z: int) -> int:
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK
    return z ^ (z >> 31)


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


# -- the scene -----------------------------------------------------------------------------------


def parse_defines(items: list[str]) -> dict:
    defines = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise EstimateError(f"-D {item}: expected key=value")
        defines[key] = value
    return defines


def require_differentiable_variant(variant: str | None) -> str:
    """``variant`` or llvm_ad_rgb; an error where the variant cannot differentiate."""
    variant = variant or "llvm_ad_rgb"
    if variant not in mi.variants():
        raise EstimateError(f"Mitsuba variant '{variant}' is not available (these are: {', '.join(mi.variants())})")
    if "_ad_" not in variant or not variant.endswith("_rgb"):
        raise EstimateError(f"variant '{variant}' is not differentiable: the estimate needs an *_ad_rgb variant "
                            "(e.g. llvm_ad_rgb)")
    if variant.startswith("llvm") and _llvm.problem() is not None:
        raise EstimateError(f"variant {variant} cannot run: {_llvm.problem()}")
    mi.set_variant(variant)
    return variant


def _resolver():
    return mi.file_resolver() if hasattr(mi, "file_resolver") else mi.Thread.thread().file_resolver()


def _mitsuba_message(error: Exception) -> str:
    lines = str(error).strip().splitlines()
    return lines[-1] if lines else type(error).__name__


class Scene:
    """The scene XML with the BSDF ``bsdf_id`` replaceable by another element."""

    def __init__(self, path: Path, bsdf_id: str, defines: dict):
        if not path.is_file():
            raise EstimateError(f"{path}: no such file")
        self.path, self.bsdf_id, self.defines = path, bsdf_id, defines
        try:
            self.tree = ET.parse(path)
        except ET.ParseError as error:
            raise EstimateError(f"{path}: not XML: {error}") from None
        self.element = next((e for e in self.tree.iter("bsdf") if e.get("id") == bsdf_id), None)
        _resolver().prepend(str(path.resolve().parent))
        if self.element is None:
            ids = sorted({e.get("id") for e in self.tree.iter("bsdf") if e.get("id")})
            raise EstimateError(f"{path}: no BSDF with id '{bsdf_id}' (BSDF ids there: {', '.join(ids) or 'none'})")

    def load(self, replacement: ET.Element | None = None):
        """The scene, the marked BSDF replaced by ``replacement`` (its id kept)."""
        element = self.element
        parent = next(p for p in self.tree.iter() if element in list(p))
        index = list(parent).index(element)
        if replacement is not None:
            replacement.set("id", self.bsdf_id)
            parent[index] = replacement
        try:
            text = ET.tostring(self.tree.getroot(), encoding="unicode")
            return mi.load_string(text, **self.defines)
        except Exception as error:  # Mitsuba reports malformed scenes as plain exceptions
            raise EstimateError(f"{self.path}: Mitsuba cannot load it: {_mitsuba_message(error)}") from None
        finally:
            parent[index] = element


def load_images(paths: list[Path], scene) -> list:
    """The reference images as ``mi.TensorXf`` (h, w, 3), checked against the scene's sensors."""
    sensors = scene.sensors()
    if len(paths) != len(sensors):
        raise EstimateError(f"{len(paths)} images for {len(sensors)} sensors: give one image per sensor, "
                            "in the scene's order")
    images = []
    for i, (path, sensor) in enumerate(zip(paths, sensors)):
        if not path.is_file():
            raise EstimateError(f"image {i} {path}: no such file")
        try:
            bitmap = mi.Bitmap(str(path)).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
        except Exception as error:
            raise EstimateError(f"image {i} {path}: cannot read it: {_mitsuba_message(error)}") from None
        array = np.array(bitmap, dtype=np.float32)
        width, height = (int(v) for v in sensor.film().crop_size())
        if array.shape[:2] != (height, width):
            raise EstimateError(f"image {i} {path} is {array.shape[1]}x{array.shape[0]}, sensor {i} renders "
                                f"{width}x{height}")
        bad = ~np.isfinite(array)
        if bad.any():
            y, x, _ = np.argwhere(bad)[0]
            raise EstimateError(f"image {i} {path}: {int(bad.any(axis=2).sum())} pixels are NaN or infinite "
                                f"(the first at x={x}, y={y})")
        if (array < 0).any():
            # Renders of measured BSDFs can hold slightly negative values: radiance is never negative.
            print(f"warning: image {i} {path}: {int((array < 0).any(axis=2).sum())} pixels are negative, "
                  "taken as 0", file=sys.stderr)
            array = np.maximum(array, 0.0)
        images.append(mi.TensorXf(array))
    return images


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
    hi, start)`` per parameter, ``key`` the traversed name below the BSDF's id."""

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

    def _apply(self, params, bsdf_id: str, theta) -> None:
        for key, value in self._values(theta).items():
            params[f"{bsdf_id}.{key}"] = value

    def result(self, theta: np.ndarray) -> dict:
        values = {k: np.asarray(dr.detach(v).numpy(), dtype=np.float64).reshape(-1)
                  for k, v in self._values(mi.Float(theta)).items()}
        result = {"type": self.kind}
        for key, value in values.items():
            name = key.split(".")[0]
            result[name] = _rgb(value) if value.size == 3 else float(value[0])
        return result


class Phase:
    """One optimisation: ``theta`` (NumPy) set into the scene by ``apply(params, id, theta_ad)``,
    or, for weights, the gradient of ``weights`` chained by ``chain``; ``penalty(theta)``:
    ``(value, gradient)`` added to the image loss."""

    def __init__(self, kind, theta, steps, apply, penalty):
        self.kind, self.steps, self.apply, self.penalty = kind, steps, apply, penalty
        self.theta = np.asarray(theta, np.float64)


class Network:
    """``nbrdf`` (latent code, then weights near the decoded ones) or ``nbrdf-no-prior``."""

    def __init__(self, prior: bool, prior_weight: float):
        self.prior, self.prior_weight = prior, prior_weight
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
    def _set_weights(params, bsdf_id, weights):
        params[f"{bsdf_id}.weights"] = weights


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


def write_network(path: Path, flat: np.ndarray, name: str, provenance: dict) -> None:
    """An ``*.nbrdf.json`` (docs/design.md section 4) of flat width-21 weights; refuses
    non-finite weights."""
    flat = np.asarray(flat, dtype=np.float32)
    if flat.size != HIDDEN * HIDDEN + 11 * HIDDEN + 3 or not np.all(np.isfinite(flat)):
        raise EstimateError("internal: refusing to write a network with non-finite or missing weights")
    layers = [{"inputs": W.shape[0], "outputs": W.shape[1], "weights": [float(v) for v in W.ravel()],
               "bias": [float(v) for v in b]} for W, b in _layers(flat)]
    document = {"format": "nbrdf", "version": 1, "name": name, "layers": layers, "provenance": provenance}
    path.write_text(json.dumps(document))


# -- the optimisation ------------------------------------------------------------------------------


class Adam:
    """Adam on a NumPy vector (float64, so that a seed gives the same steps everywhere)."""

    def __init__(self, size: int, rate: float, betas=(0.9, 0.999), eps=1e-8):
        self.rate, self.betas, self.eps = rate, betas, eps
        self.m, self.v, self.t = np.zeros(size), np.zeros(size), 0

    def state(self):
        return self.m.copy(), self.v.copy(), self.t

    def restore(self, state) -> None:
        self.m, self.v, self.t = state[0].copy(), state[1].copy(), state[2]

    def step(self, theta: np.ndarray, grad: np.ndarray) -> np.ndarray:
        b1, b2 = self.betas
        self.t += 1
        self.m = b1 * self.m + (1 - b1) * grad
        self.v = b2 * self.v + (1 - b2) * grad * grad
        m_hat = self.m / (1 - b1 ** self.t)
        v_hat = self.v / (1 - b2 ** self.t)
        return theta - self.rate * m_hat / (np.sqrt(v_hat) + self.eps)


def image_loss(images: list, references: list):
    """Mean squared error relative to ``1 + reference``, ``((x - r) / (1 + r))^2``, over every
    view, pixel and channel: the first-order twin of the squared error of ``ln(1 + x)`` (the
    weight keeps highlights from swamping the rest of the object), but linear in the render.
    ``mi.render`` draws the adjoint pass's samples apart from the primal's, so a step's gradient
    is the loss's derivative at the noisy render times an independent derivative of the render;
    linear in the render, that derivative's mean is its value at the mean render, and the fit
    settles where the mean render is the reference. The log's was biased bright where renders
    are noisy, most around a highlight narrower than a pixel, which it fitted 2-3 pixels wide
    (docs/experiments.md, issue 33, round 22). Held to a float64 oracle and to that property by
    tests/test_estimate.py::test_image_loss_is_linear_in_the_render."""
    total = 0.0
    for image, reference in zip(images, references):
        d = (image - reference) / (1.0 + reference)
        total = total + dr.mean(dr.square(d), axis=None)
    return total / len(images)


def render_seed(seed: int, step: int, view: int) -> int:
    return (_mix64((seed << 32) ^ (step << 8) ^ view) >> 33) & 0x7FFFFFFF


class Estimator:
    """The loaded scene with the model in place of the marked BSDF, and its optimiser."""

    def __init__(self, scene_file: Scene, model, images: list[Path], spp: int, seed: int, max_depth: int,
                 workdir: Path):
        self.model, self.spp, self.seed = model, spp, seed
        self.bsdf_id = scene_file.bsdf_id
        self.scene = scene_file.load(model.element(workdir))
        self.references = load_images(images, self.scene)
        #: The views the loss sums over (all but the held-out one while a prior strength is chosen).
        self.views = list(range(len(self.references)))
        self.integrator = mi.load_dict({"type": "prb", "max_depth": max_depth})
        self.params = mi.traverse(self.scene)
        self.halvings = 0
        self.history: list[float] = []
        #: ``on_step(kind, steps_done, theta)`` after each step (a convergence study's snapshots).
        self.on_step = None

    def render_all(self, step: int, spp: int | None = None) -> list:
        return [mi.render(self.scene, self.params, sensor=i, integrator=self.integrator, spp=spp or self.spp,
                          seed=render_seed(self.seed, step, i)) for i in self.views]

    def view_references(self) -> list:
        return [self.references[i] for i in self.views]

    def held_out_loss(self, weights: np.ndarray, view: int) -> float:
        """The image loss of ``weights`` on the training view ``view`` (one render, a fixed seed)."""
        with dr.suspend_grad():
            Network._set_weights(self.params, self.bsdf_id, mi.Float(np.asarray(weights, np.float32)))
            self.params.update()
            image = mi.render(self.scene, self.params, sensor=view, integrator=self.integrator,
                              spp=HELD_OUT_SPP_FACTOR * self.spp, seed=render_seed(self.seed, 1 << 20, view))
            loss = image_loss([image], [self.references[view]])
        return float(np.asarray(loss.numpy()).reshape(-1)[0])

    def loss_and_grad(self, phase: Phase, theta: np.ndarray, step: int):
        """(loss, gradient) at ``theta``, or ``(nan, None)`` where either is not finite or the
        BSDF rejects the values."""
        variable = mi.Float(theta.astype(np.float32))
        dr.enable_grad(variable)
        try:
            phase.apply(self.params, self.bsdf_id, variable)
            self.params.update()
        except ValueError:
            return math.nan, None
        loss = image_loss(self.render_all(step), self.view_references())
        dr.backward(loss)
        grad = np.asarray(dr.grad(variable).numpy(), dtype=np.float64)
        value = float(loss.array[0]) if hasattr(loss, "array") else float(np.asarray(loss.numpy()).reshape(-1)[0])
        if phase.penalty is not None:
            extra, extra_grad = phase.penalty(theta)
            value, grad = value + extra, grad + extra_grad
        if not (math.isfinite(value) and np.all(np.isfinite(grad))):
            return math.nan, None
        return value, grad

    def run(self, phase: Phase, bar, first_step: int) -> np.ndarray:
        adam = Adam(phase.theta.size, LEARNING_RATES[phase.kind])
        theta = phase.theta.copy()
        accepted = (theta.copy(), adam.state())
        best = (math.inf, accepted)
        step = 0
        while step < phase.steps:
            value, grad = self.loss_and_grad(phase, theta, first_step + step)
            runaway = grad is not None and value > RUNAWAY_FACTOR * best[0]
            if grad is None or runaway:
                # A diverging step: back to the last state with a finite loss (where the loss ran
                # away, to the phase's best: the states before it were already running away),
                # half the step.
                self.halvings += 1
                if self.halvings > MAX_HALVINGS:
                    raise EstimateError(f"the optimisation diverged: the loss stayed non-finite or ran away after "
                                        f"{MAX_HALVINGS} halvings of the step")
                back = best[1] if runaway else accepted
                theta = back[0].copy()
                adam.restore(back[1])
                adam.rate *= 0.5
                continue
            accepted = (theta.copy(), adam.state())
            if value < best[0]:
                best = (value, accepted)
            self.history.append(value)
            if step == 0 and first_step == 0 and not np.any(grad != 0):
                raise EstimateError(f"the images do not depend on BSDF '{self.bsdf_id}' (zero gradient at the "
                                    "start): is the object visible to the sensors and lit?")
            theta = adam.step(theta, grad)
            step += 1
            if self.on_step is not None:
                self.on_step(phase.kind, first_step + step, theta)
            bar.update(1)
            bar.set_postfix(loss=f"{value:.4g}", phase=phase.kind)
        return theta if np.all(np.isfinite(theta)) else accepted[0]

    def screen_codes(self, decoder, candidates: np.ndarray) -> np.ndarray:
        """The candidate code whose renders (a quarter of the samples) fit the images best."""
        best, best_loss = candidates[0], math.inf
        for code in candidates:
            with dr.suspend_grad():
                self.params[f"{self.bsdf_id}.weights"] = decoder.decode(mi.Float(code.astype(np.float32)))
                self.params.update()
                loss = image_loss(self.render_all(-1, max(1, self.spp // 4)), self.view_references())
            value = float(np.asarray(loss.numpy()).reshape(-1)[0])
            if value < best_loss:
                best, best_loss = code, value
        return best


def estimate(args, on_step=None) -> dict:
    """Runs the estimate of the parsed ``args``, writes ``args.output``; a summary.
    ``on_step(kind, steps_done, theta)``, if given, is called after every step."""
    require_differentiable_variant(args.variant)
    if args.threads is not None and args.threads < 1:
        raise EstimateError("--threads must be at least 1")
    previous = dr.thread_count()
    try:
        return _estimate(args, on_step)
    finally:
        dr.set_thread_count(previous)


def _estimate(args, on_step=None) -> dict:
    if args.steps < 1 or args.spp < 1:
        raise EstimateError("--steps and --spp must be at least 1")
    for name, value in (("--prior-weight", args.prior_weight), ("--code-prior", args.code_prior)):
        if value is not None and not (value >= 0 and math.isfinite(value)):
            raise EstimateError(f"{name} must be a finite number >= 0")
    scene_file = Scene(args.scene, args.bsdf_id, parse_defines(args.define))
    model = Network(args.model == "nbrdf", args.prior_weight) if args.model.startswith("nbrdf") else Analytic(args.model)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="nbrdf-estimate-") as workdir:
        est = Estimator(scene_file, model, args.images, args.spp, args.seed, args.max_depth, Path(workdir))
        est.on_step = on_step
        if args.threads is not None:
            # One thread fixes the order of the gradients' float sums (bit-identical reruns). Set
            # after loading: Mitsuba builds the Python plugins on its worker threads.
            dr.set_thread_count(args.threads)
        from tqdm import tqdm

        plan = schedule(args.steps, len(est.references), args.prior_weight if model_has_prior(model) else 0.0,
                        args.code_prior)
        codes = len(plan["code_strengths"])
        total = args.steps + (codes - 1) * plan["code"] + (codes * len(plan["strengths"]) - 1) * plan["candidate"]
        with tqdm(total=total, unit="step", desc=f"estimate {args.model}", disable=args.quiet,
                  file=sys.stderr) as bar:
            result = _optimise(est, model, args, bar, plan)
    result["seconds"] = time.perf_counter() - start
    result["loss_first"], result["loss_last"] = est.history[0], est.history[-1]
    result["halvings"] = est.halvings
    return result


def model_has_prior(model) -> bool:
    return isinstance(model, Network) and model.prior


def schedule(steps: int, views: int, prior_weight: float | None, code_prior: float | None = None) -> dict:
    """The prior's plan: steps of the code phase and of the weight phase, the candidate
    strengths of the weight phase's pull and of the code's penalty (one each: no choice), the
    steps of each decoded candidate's weight fit (0: nothing to choose). A fixed ``prior_weight``
    fixes the code's too (``code_prior``, else none)."""
    code = max(1, round(CODE_SHARE * steps)) if steps > 1 else 1
    weights = steps - code
    fixed_code = (code_prior if code_prior is not None else FALLBACK_CODE_PRIOR,)
    if prior_weight is not None:
        strengths, code_strengths = (prior_weight,), fixed_code
    elif views < 2 or weights < 1:
        strengths, code_strengths = (FALLBACK_STRENGTH,), fixed_code
    else:
        strengths = PRIOR_STRENGTHS
        code_strengths = fixed_code if code_prior is not None else CODE_PRIOR_STRENGTHS
    selecting = len(strengths) * len(code_strengths) > 1
    candidate = max(1, round(CANDIDATE_SHARE * weights)) if selecting else 0
    return {"code": code, "weights": weights, "strengths": strengths, "code_strengths": code_strengths,
            "candidate": candidate}


def prior_penalty(center: np.ndarray, variance: np.ndarray, strength: float):
    """``strength`` times the mean squared standardised distance to ``center``, and its gradient:
    the code's Gaussian penalty (the training codes' mean and variance)."""
    if strength == 0:
        return None

    def penalty(x):
        d = x - center
        return strength * float(np.mean(d * d / variance)), strength * 2.0 * d / variance / d.size

    return penalty


def _pull_inputs() -> np.ndarray:
    """The network input (``PULL_PAIRS``, 6) of the pull's direction pairs, each direction uniform
    over the hemisphere (the plugin's own warp and input: ``jit.uniform_hemisphere``,
    ``jit.network_input``)."""
    from . import jit

    u = [mi.Float(row.astype(np.float32)) for row in np.random.default_rng(PULL_SEED).random((4, PULL_PAIRS))]
    x = jit.network_input(jit.uniform_hemisphere(u[0], u[1]), jit.uniform_hemisphere(u[2], u[3]))
    return np.stack([np.zeros(PULL_PAIRS) if c is None else np.asarray(dr.detach(c).numpy(), np.float64).reshape(-1)
                     for c in x], axis=1)


def _hidden_and_output(layers: list, x: np.ndarray):
    """The hidden layers' pre-activations and the output's log-space value ``z`` (``f = max(e^z - 1,
    0)``). Float64 twin of ``jit.TracedNetwork.eval_input`` before its output's ``expm1``; held to
    ``nbrdf_tools.network.forward`` by tests/test_estimate.py::test_output_pull_against_a_float64_oracle."""
    (W1, b1), (W2, b2), (W3, b3) = layers
    z1 = x @ W1 + b1
    z2 = np.maximum(z1, 0) @ W2 + b2
    return z1, z2, np.maximum(z2, 0) @ W3 + b3


def output_pull(center: np.ndarray, strength: float):
    """The weight phase's pull toward the decoded network ``center`` (flat weights): ``strength``
    times the mean squared difference of the two networks' log-space outputs (the ``z`` of ``f =
    e^z - 1``, every channel) at ``PULL_PAIRS`` fixed uniform direction pairs, and its gradient
    (backpropagated by hand, float64 like the optimiser). A pull in function space, not in weight
    space: weights far apart can be the same BRDF and near ones different, while this holds the
    BRDF itself where no image constrains it. ``None`` for strength 0."""
    if strength == 0:
        return None
    x = _pull_inputs()
    target = _hidden_and_output(_layers(np.asarray(center, np.float64)), x)[2]

    def penalty(flat):
        layers = _layers(flat)
        (_, _), (W2, _), (W3, _) = layers
        z1, z2, z3 = _hidden_and_output(layers, x)
        d = z3 - target
        g3 = strength * 2.0 * d / d.size
        g2 = (g3 @ W3.T) * (z2 > 0)
        g1 = (g2 @ W2.T) * (z1 > 0)
        grad = np.concatenate([(x.T @ g1).ravel(), g1.sum(0), (np.maximum(z1, 0).T @ g2).ravel(), g2.sum(0),
                               (np.maximum(z2, 0).T @ g3).ravel(), g3.sum(0)])
        return strength * float(np.mean(d * d)), grad

    return penalty


@functools.cache
def _albedo_quadrature() -> tuple[np.ndarray, np.ndarray]:
    """Network inputs ``(K N, 6)`` and weights ``(K, N)`` of the directional albedo ``a(l) = int
    f(v, l) cos theta_v dv`` at the ``K`` incidence angles of ``ALBEDO_INCIDENCE``: the integral
    over the half vector ``h`` (``v = 2 (h.l) h - l``, ``dv = 4 (h.l) dh``), midpoints of the
    ``ALBEDO_GRID``, so that a narrow specular peak is resolved where a grid over ``v`` would
    alias it. The inputs are the plugin's own (``jit.network_input``)."""
    from . import jit

    n_theta, n_phi = ALBEDO_GRID
    u = (np.arange(n_theta) + 0.5) / n_theta
    theta = 0.5 * np.pi * u * u
    phi = 2 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    theta, phi = (a.ravel() for a in np.meshgrid(theta, phi, indexing="ij"))
    d_area = np.repeat(np.pi * u / n_theta, n_phi) * (2 * np.pi / n_phi) * np.sin(theta)  # d theta d phi sin theta
    h = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    angles = np.radians(ALBEDO_INCIDENCE)
    light = np.stack([np.sin(angles), np.zeros_like(angles), np.cos(angles)], axis=1)
    h_dot_l = light @ h.T  # (K, N)
    view = 2 * h_dot_l[..., None] * h[None] - light[:, None]
    weights = np.where((h_dot_l > 0) & (view[..., 2] > 0), view[..., 2] * 4 * h_dot_l * d_area, 0.0)

    def vector(a):
        return mi.Vector3f(*(mi.Float(a[:, i].astype(np.float32)) for i in range(3)))

    lights = np.repeat(light, h.shape[0], axis=0)
    x = jit.network_input(vector(view.reshape(-1, 3)), vector(lights))
    x = np.stack([np.zeros(len(lights)) if c is None else np.asarray(dr.detach(c).numpy(), np.float64).reshape(-1)
                  for c in x], axis=1)
    return x, weights


def directional_albedo(flat: np.ndarray) -> np.ndarray:
    """The directional albedo ``(K, 3)`` of flat width-21 weights at the incidence angles of
    ``ALBEDO_INCIDENCE`` (:func:`_albedo_quadrature`): at most 1 for a material that conserves
    energy."""
    x, weights = _albedo_quadrature()
    z = _hidden_and_output(_layers(np.asarray(flat, np.float64)), x)[2]
    f = np.maximum(np.expm1(z), 0.0).reshape(*weights.shape, 3)
    return np.einsum("knc,kn->kc", f, weights)


def albedo_bound(albedo: np.ndarray) -> float:
    """The largest directional albedo a network of albedo ``albedo`` (``(K, 3)``, at the incidence
    angles of ``ALBEDO_INCIDENCE``) may have and be a material: 1 (energy conservation), or its
    own largest albedo up to ``ALBEDO_LIT_INCIDENCE`` where that is higher (what the images ask
    for), plus ``ALBEDO_MARGIN``; never above ``ALBEDO_BOUND``."""
    lit = albedo[np.asarray(ALBEDO_INCIDENCE) <= ALBEDO_LIT_INCIDENCE].max()
    return float(min(ALBEDO_BOUND, max(1.0, lit) * (1.0 + ALBEDO_MARGIN)))


def albedo_check(flat: np.ndarray) -> tuple[float, bool]:
    """A network's largest directional albedo over the incidence angles and channels, and
    whether it passes the albedo check (at most :func:`albedo_bound`)."""
    albedo = directional_albedo(flat)
    largest = float(albedo.max())
    return largest, largest <= albedo_bound(albedo)


def candidate_name(candidate, several_codes: bool) -> str:
    """A candidate's key in ``held_out_losses``: the pull's strength, prefixed with the code
    penalty's where several are candidates."""
    code_strength, strength = candidate
    return f"code {code_strength}, pull {strength}" if several_codes else str(strength)


def choose_start(est: Estimator, decoded: dict, plan: dict, bar) -> tuple:
    """The candidate whose short fit on the training views but the held-out one (the last) has
    the lowest loss on the held-out view: a pair (code penalty's strength, strength of the pull
    toward ``decoded[code strength]``); ties go to the first (no code penalty, the tightest pull).
    A candidate whose fit fails the albedo check (:func:`albedo_check`) is not chosen; where none
    is left, ``COMMON_START``. Returns the choice, the held-out losses by candidate, the albedos of the
    rejected ones and the chosen candidate's fitted weights (``None`` for ``COMMON_START``)."""
    held_out = len(est.references) - 1
    on_step, est.on_step = est.on_step, None  # candidates are no snapshots of the estimate
    views, est.views = est.views, list(range(held_out))
    losses, rejected, fits = {}, {}, {}
    try:
        for code_strength, start in decoded.items():
            for strength in plan["strengths"]:
                phase = Phase("weights", start, plan["candidate"], Network._set_weights,
                              output_pull(start, strength))
                fitted = fits[code_strength, strength] = est.run(phase, bar, plan["code"])
                losses[code_strength, strength] = est.held_out_loss(fitted, held_out)
                albedo, material = albedo_check(fitted)
                if not material:
                    rejected[code_strength, strength] = albedo
    finally:
        est.on_step, est.views = on_step, views
    allowed = [k for k in losses if k not in rejected]
    choice = min(allowed, key=losses.__getitem__) if allowed else COMMON_START
    return choice, losses, rejected, fits.get(choice)


def fit_codes(est: Estimator, decoder, plan: dict, bar) -> dict:
    """Per strength of the code penalty: the code fitted through the decoder from the best
    screened training code (the screening shared), each phase with the same render seeds."""
    picks = np.linspace(0, len(decoder.anchors) - 1, SCREENED_STARTS).round().astype(int)
    candidates = np.concatenate([decoder.anchors.mean(axis=0, keepdims=True), decoder.anchors[picks]])
    code0 = est.screen_codes(decoder, candidates)
    spread = decoder.code_distribution() if any(plan["code_strengths"]) else (None, None)

    def apply(params, bsdf_id, code):
        params[f"{bsdf_id}.weights"] = decoder.decode(code)

    return {strength: est.run(Phase("code", code0, plan["code"], apply, prior_penalty(*spread, strength)), bar, 0)
            for strength in plan["code_strengths"]}


def prior_attempt(est: Estimator, decoder, plan: dict, bar) -> tuple:
    """One attempt of the prior at the estimator's seed: the code through the decoder, then the
    weights held near the decoded ones by the chosen strengths. Returns the weights (``None``
    where the albedo check rejected every candidate or the final network), the summary's
    additions, and the rejected albedos by candidate name (``final``: the final network)."""
    selecting = plan["candidate"] > 0
    # The code phase sees every view, the held-out one too: its 32 values are too few to fit that
    # view's noise, and the view's light often decided which code was reached (on iris_purple_gem
    # a material at every seed where without it two of three seeds fell back; docs/experiments.md,
    # issue 33, round 15). The candidates' weights, which can fit noise, are fitted without it.
    codes = fit_codes(est, decoder, plan, bar)
    decoded = {k: decoder.decode_numpy(code).astype(np.float64) for k, code in codes.items()}
    choice, losses, rejected, fitted = (plan["code_strengths"][0], plan["strengths"][0]), {}, {}, None
    if selecting:
        choice, losses, rejected, fitted = choose_start(est, decoded, plan, bar)
    several_codes = len(codes) > 1
    extra = {"held_out_losses": {candidate_name(k, several_codes): v for k, v in losses.items()}} if losses else {}
    rejected = {candidate_name(k, several_codes): v for k, v in rejected.items()}
    # The common start keeps the best decoded candidate's code for the record.
    code_strength = min(losses, key=losses.__getitem__)[0] if choice == COMMON_START else choice[0]
    extra["code"] = [float(c) for c in codes[code_strength]]
    if choice == COMMON_START:
        return None, extra, rejected
    strength = choice[1]
    extra.update({"start": "decoded", "prior_weight": strength, "code_prior": code_strength})
    # The chosen candidate's fit goes on over every view (its first steps' render seeds, as a refit
    # from the decoded start had): refitted from the decoded start instead, the network lost
    # what the held-out view had judged (iris_purple_gem at seed 0: 0.0310 against 0.0247;
    # docs/experiments.md, issue 33, round 16).
    center = decoded[code_strength]
    weights, steps = (center, plan["weights"]) if fitted is None else (fitted, plan["weights"] - plan["candidate"])
    if steps > 0:
        phase = Phase("weights", weights, steps, Network._set_weights, output_pull(center, strength))
        weights = est.run(phase, bar, plan["code"])
    albedo, material = albedo_check(weights)
    if not material:
        rejected["final"] = albedo
        return None, extra, rejected
    extra["albedo_max"] = albedo
    return weights, extra, rejected


def fit_with_prior(est: Estimator, args, plan: dict, bar) -> tuple[np.ndarray, dict]:
    """Up to ``PRIOR_ATTEMPTS`` attempts of the prior, each with its own render seeds, until the
    albedo check keeps a network; else the common start, the nbrdf-no-prior estimate (its start,
    steps and seeds, so the same network). The weights and the summary's additions."""
    from .latent import Decoder, LatentError

    try:
        decoder = Decoder(args.ae)
    except LatentError as error:
        raise EstimateError(str(error)) from None
    # An attempt costs what the progress bar was sized for (code and weight steps add up to --steps).
    seed, rejected_all, attempt_steps = est.seed, {}, bar.total
    try:
        for attempt in range(PRIOR_ATTEMPTS):
            est.seed = seed + ATTEMPT_SEED_STRIDE * attempt
            if attempt > 0:
                bar.total += attempt_steps
            try:
                weights, extra, rejected = prior_attempt(est, decoder, plan, bar)
            except LatentError as error:
                raise EstimateError(str(error)) from None
            prefix = f"attempt {attempt}: " if attempt else ""
            rejected_all.update({prefix + k: v for k, v in rejected.items()})
            if weights is not None:
                extra["attempts"] = attempt + 1
                break
        else:
            # No attempt gave a material: the nbrdf-no-prior estimate; the last attempt's best code is
            # kept for the record.
            est.seed = seed
            bar.total += plan["code"] + plan["weights"]
            extra.update({"start": COMMON_START, "prior_weight": None, "code_prior": None,
                          "attempts": PRIOR_ATTEMPTS})
            weights = est.run(Phase("weights", common_initialisation(), plan["code"] + plan["weights"],
                                    Network._set_weights, None), bar, 0)
    finally:
        est.seed = seed
    if rejected_all:
        extra["albedo_rejected"] = rejected_all
    return weights, extra


def _optimise(est: Estimator, model, args, bar, plan: dict) -> dict:
    summary = {"output": str(args.output), "model": args.model, "steps": args.steps}
    if isinstance(model, Analytic):
        (phase,) = model.phases(args.steps)
        theta = est.run(phase, bar, 0)
        fitted = model.result(theta)
        args.output.write_text(json.dumps(fitted, indent=2) + "\n")
        summary["bsdf"] = fitted
        return summary
    if model.prior:
        weights, extra = fit_with_prior(est, args, plan, bar)
        summary.update(extra)
    else:
        weights = est.run(Phase("weights", model.start, args.steps, Network._set_weights, None), bar, 0)
    material = "albedo_max" in summary  # the prior's kept network has passed already
    if not material:
        summary["albedo_max"], material = albedo_check(weights)
    if not material:
        # Nothing to fall back to (the common start, or no prior asked): written, but not silently.
        print(f"warning: the estimated network reflects up to {summary['albedo_max']:.3g} times the light it "
              "receives (directional albedo; a material reflects at most 1): the images do not constrain it "
              "where their lights do not reach", file=sys.stderr)
    provenance = {"estimated_by": "nbrdf_mitsuba.estimate", "model": args.model, "steps": args.steps,
                  "spp": args.spp, "seed": args.seed, "images": [str(p) for p in args.images],
                  "scene": str(args.scene), "bsdf_id": args.bsdf_id}
    for key in ("code", "start", "prior_weight", "code_prior", "held_out_losses", "albedo_rejected", "attempts",
                "albedo_max"):
        if key in summary:
            provenance[key] = summary[key]
    name = args.output.name.split(".")[0]
    write_network(args.output, weights, name, provenance)
    summary["sampling"] = fit_sampling(args.output)
    return summary


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
        raise EstimateError(f"nbrdf fit-phong {path} failed: {done.stderr.strip().splitlines()[-1:]}")
    return "fit-phong"


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m nbrdf_mitsuba.estimate",
        description="Estimate a material from images of a known scene by differentiable rendering (prb): the BSDF "
                    "with the given id is replaced by the model, whose parameters are fitted to the images.")
    p.add_argument("scene", type=Path, help="the scene (Mitsuba 3 XML): object, sensors, emitters")
    p.add_argument("--images", type=Path, nargs="+", required=True,
                   help="one EXR (linear RGB) per sensor of the scene, in the scene's order")
    p.add_argument("--bsdf-id", required=True, help="the id of the BSDF to estimate")
    p.add_argument("-o", "--output", type=Path, required=True,
                   help="OUT.nbrdf.json (nbrdf models) or OUT.json (analytic models: a mi.load_dict dictionary)")
    p.add_argument("--model", choices=MODELS, default="nbrdf", help="what to fit (default: nbrdf, with the prior)")
    p.add_argument("--steps", type=int, default=200, help="optimisation steps, each rendering every view (default: 200)")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel of each render (default: 16)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the renders (default: 0)")
    p.add_argument("--max-depth", type=int, default=3, help="prb's path depth (default: 3, direct light and one "
                                                            "bounce)")
    p.add_argument("--prior-weight", type=float,
                   help="strength of the pull holding the network's BRDF near the decoded one's (default: chosen among "
                        f"{', '.join(map(str, PRIOR_STRENGTHS))} by the last training view, held out; the common start "
                        f"without the prior only where the albedo check rejects every network of the prior; "
                        f"{FALLBACK_STRENGTH} with one image)")
    p.add_argument("--code-prior", type=float,
                   help="strength of the Gaussian penalty holding the latent code near the training codes (default: "
                        f"chosen among {', '.join(map(str, CODE_PRIOR_STRENGTHS))} together with the weights' "
                        f"strength, by the same held-out view; {FALLBACK_CODE_PRIOR} with one image or a fixed "
                        "--prior-weight)")
    p.add_argument("--ae", type=Path, help="the autoencoder (default: the pretrained one)")
    p.add_argument("-D", dest="define", action="append", default=[], metavar="KEY=VALUE",
                   help="set a scene parameter ($KEY in the XML), as for rendering")
    p.add_argument("--threads", type=int,
                   help="Dr.Jit's worker threads (default: one per core). A seed gives the same result to float "
                        "rounding (the gradients' sums run in thread order); with --threads 1, bit for bit")
    p.add_argument("--variant", help="Mitsuba variant, an *_ad_rgb one (default: llvm_ad_rgb)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        summary = estimate(args)
    except EstimateError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted; nothing written", file=sys.stderr)
        return 130
    print(f"wrote {summary['output']} ({summary['model']}): loss {summary['loss_first']:.4g} -> "
          f"{summary['loss_last']:.4g} in {summary['steps']} steps, {summary['seconds']:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
