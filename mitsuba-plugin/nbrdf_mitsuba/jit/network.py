"""The network's input coordinates and forward pass as Dr.Jit arithmetic (:class:`TracedNetwork`).

Weights enter the kernel either as literals (``literal``: constant-folded, fastest, but one kernel
per material), as kernel parameters (``opaque``: one kernel per network shape shared by every
material, the weights passed per instance) or as whichever suits the scene (``auto``: literals for
a few networks, the shared kernel for more).
"""

from __future__ import annotations

import threading
import weakref

import drjit as dr
import mitsuba as mi
import numpy as np

from .directions import both_valid_above, unit_or_normal
from .fastmath import clamp_exp_argument, expm1, relu

#: Below this ``sin(theta_h)`` the half vector's azimuth is undefined and taken as 0 (``coords.rs``,
#: same name).
SIN_THETA_H_EPS_F32 = 1e-7


def network_input(view: mi.Vector3f, light: mi.Vector3f, anisotropic: bool = False) -> list:
    """``[sin th, 0, cos th, d.x, d.y, d.z]`` (docs/design.md section 2), branch-free like the Rust code;
    for an anisotropic network ``[sin th cos ph, sin th sin ph, cos th, d.x, d.y, d.z]``, the half
    vector in the local frame (x: the shading frame's tangent)."""
    lx, ly, lz = unit_or_normal(light.x, light.y, light.z)
    vx, vy, vz = unit_or_normal(view.x, view.y, view.z)
    hx, hy, hz = lx + vx, ly + vy, lz + vz
    h_len2 = dr.fma(hx, hx, dr.fma(hy, hy, hz * hz))
    degenerate = h_len2 <= 0
    hi = dr.select(degenerate, 0.0, dr.rsqrt(h_len2))
    hx, hy = hx * hi, hy * hi
    hz = dr.select(degenerate, 1.0, hz * hi)
    sin_th = dr.sqrt(dr.fma(hx, hx, hy * hy))
    has_azimuth = sin_th > SIN_THETA_H_EPS_F32
    si = dr.select(has_azimuth, dr.rcp(sin_th), 0.0)
    cos_ph = dr.select(has_azimuth, hx * si, 1.0)
    sin_ph = hy * si
    tx = dr.fma(cos_ph, lx, sin_ph * ly)
    ty = dr.fma(-sin_ph, lx, cos_ph * ly)
    dx = dr.fma(hz, tx, -sin_th * lz)
    dz = dr.fma(sin_th, tx, hz * lz)
    if anisotropic:
        return [sin_th * cos_ph, sin_th * sin_ph, hz, dx, ty, dz]
    return [sin_th, None, hz, dx, ty, dz]  # None: the constant-zero input, skipped in layer 1


#: ``jit_weights = "auto"`` traces literal kernels while at most this many traced networks are
#: alive in the variant, and the shared kernel (kernel parameters) beyond. Each literal network
#: is its own callable in Mitsuba's symbolic call, compiled on the first render; kernel-parameter
#: networks of one shape trace to the same code, which Dr.Jit compiles once. Measured:
#: docs/results/performance.md, "Many materials".
AUTO_LITERAL_MAX = 4
WEIGHT_MODES = ("auto", "literal", "opaque")
_live: dict[str, weakref.WeakSet] = {}
_live_lock = threading.Lock()  # Mitsuba builds a scene's plugins on several threads


def live_networks() -> int:
    """How many traced networks of the current variant are alive: what Mitsuba's symbolic call
    traces (it traces every live BSDF instance, not only one scene's)."""
    with _live_lock:
        return len(_live.get(mi.variant(), ()))


class TracedNetwork:
    """An NBRDF as Dr.Jit arithmetic. ``layers`` are ``(W, b)`` NumPy pairs with ``y = x W + b``.

    ``flat`` (W1, b1, W2, b2, W3, b3 as one ``mi.Float``) is what ``traverse`` exposes; after an
    update call ``refresh()`` so the traced kernels see the new values.

    ``weights``: ``literal`` (constants of the kernel: one kernel per network), ``opaque``
    (kernel parameters gathered from ``flat``: gradients reach ``flat``) or ``auto`` (literal
    constants while :func:`live_networks` is at most :data:`AUTO_LITERAL_MAX`, else kernel
    parameters; no gradients, as ``literal``). Kernel-parameter networks of one shape trace to
    identical code: Mitsuba's symbolic call over hundreds of them compiles one callable and
    passes each instance's weights as call data (the shared kernel).

    ``active`` (per hidden layer, which units some pair of directions above the horizon can
    activate: the library's proof made when it loaded the network, ``_native.Material.network``)
    and ``active_units(flat)`` (the library's proof for new weights,
    ``_native.Material.active_units``), when given, name in literal kernels the units the kernel
    computes; it leaves the others out. They output exactly 0 wherever the BSDF is evaluated, so
    the values do not change and the kernel skips those units' multiply-adds
    (``network/pruning.rs``; tests/test_backends.py holds the pruned kernel to the full one).
    Kernel-parameter kernels keep every unit: their code must not depend on the weights.
    """

    def __init__(self, layers: list[tuple[np.ndarray, np.ndarray]], weights: str = "literal",
                 anisotropic: bool = False, active_units=None, active=None):
        if weights not in WEIGHT_MODES:
            raise ValueError(f"weights must be one of {', '.join(WEIGHT_MODES)}, got '{weights}'")
        self.mode = weights
        #: Whether the input carries phi_h (file format version 2, ``"anisotropic": true``).
        self.anisotropic = bool(anisotropic)
        self.shapes = [(int(W.shape[0]), int(W.shape[1])) for W, _ in layers]
        self.parameter_count = sum(i * o + o for i, o in self.shapes)
        self._active_units = active_units
        #: An :class:`adjoints.AdjointRecorder` while an estimate records this network's adjoints.
        self.recorder = None
        flat = np.concatenate([np.concatenate([W.ravel(), b.ravel()]) for W, b in layers])
        self.flat = mi.Float(flat.astype(np.float32))
        self.refresh(active)
        with _live_lock:
            _live.setdefault(mi.variant(), weakref.WeakSet()).add(self)

    def describe_index(self, k: int) -> str:
        """Where flat index ``k`` lives, e.g. ``layer 2 weight 17`` or ``layer 3 bias 0``."""
        offset = 0
        for layer, (n_in, n_out) in enumerate(self.shapes, start=1):
            if k < offset + n_in * n_out:
                return f"layer {layer} weight {k - offset}"
            offset += n_in * n_out
            if k < offset + n_out:
                return f"layer {layer} bias {k - offset}"
            offset += n_out
        return f"index {k}"

    def refresh(self, active=None) -> None:
        """Rebuilds the per-weight scalars from ``flat`` (the caller has validated it) and keeps
        a copy as ``good``, the state a rejected update returns to. ``active``: the proof for
        these weights when the caller has it (else ``active_units`` proves it)."""
        values = np.array(dr.detach(self.flat).numpy(), dtype=np.float32).reshape(-1)
        self.good = values
        self._active = active
        if self.mode == "literal" and active is None and self._active_units is not None:
            self._active = self._active_units(values)
        #: Each kind of kernel's :meth:`_vectorised` rows ("literal", "parameters"): only these hold
        #: the weights' variables, so that Dr.Jit's traversal (``freezing.JitState``) visits each once.
        self._rows = {}
        if self.mode == "literal":
            self._rows["literal"] = self._make_rows("literal", [mi.Float(float(v)) for v in values])
        if self.mode == "opaque":
            # Gathers at literal indices give one size-1 variable per weight; make_opaque
            # evaluates them in one small kernel so they become kernel parameters, not constants,
            # and keeps their AD edges to ``flat``.
            scalars = [dr.gather(mi.Float, self.flat, k) for k in range(dr.width(self.flat))]
            dr.make_opaque(*scalars)
            self._rows["parameters"] = self._make_rows("parameters", scalars)
        elif self.mode == "auto":
            # No AD edges needed: each value becomes its own one-element buffer, no kernel runs.
            scalars = [mi.Float(float(v)) for v in values]
            dr.make_opaque(*scalars)
            self._rows["parameters"] = self._make_rows("parameters", scalars)

    @property
    def active(self):
        """Per hidden layer, which units literal kernels compute (None: all of them). ``auto``
        proves it when a literal kernel first needs it: a network that only ever runs in the
        shared kernel never pays for the proof (most of a load's time)."""
        if self.mode == "opaque":
            return None
        if self._active is None and self._active_units is not None:
            self._active = self._active_units(self.good)
        return self._active

    def _split(self, scalars: list) -> list:
        layers, offset = [], 0
        for n_in, n_out in self.shapes:
            W = [scalars[offset + i * n_out : offset + (i + 1) * n_out] for i in range(n_in)]
            offset += n_in * n_out
            b = scalars[offset : offset + n_out]
            offset += n_out
            layers.append((W, b))
        return layers

    def kernel(self) -> str:
        """Which kernel the next trace uses: ``literal`` or ``parameters`` (see the class). ``auto``
        takes the parameters while a frozen function records: literals made in the trace would be
        replayed after an update as they were."""
        if self.mode == "auto":
            few = live_networks() <= AUTO_LITERAL_MAX and not dr.flag(dr.JitFlag.FreezingScope)
            return "literal" if few else "parameters"
        return "literal" if self.mode == "literal" else "parameters"

    def _vectorised(self, kernel: str) -> list:
        """The rows of ``kernel`` (:meth:`_make_rows`), built in :meth:`refresh`, outside any symbolic
        call: built while Dr.Jit traced one, they lost their AD edges to ``flat`` (and belonged to
        that trace). "auto" makes its literal rows when a trace first needs them, kept only when
        made outside one."""
        rows = self._rows.get(kernel)
        if rows is None:
            rows = self._make_rows(kernel, [mi.Float(float(v)) for v in self.good])
            if not dr.flag(dr.JitFlag.SymbolicScope):
                self._rows[kernel] = rows
        return rows

    def _make_rows(self, kernel: str, scalars: list) -> list:
        """Per layer: the outputs the kernel computes, and per input its weights to them and their
        biases as ``mi.ArrayXf`` (one Dr.Jit call per input while tracing, not one per weight: the
        same multiply-adds in the same order); ``scalars``: the flat weights, one variable each."""
        active = self.active if kernel == "literal" else None
        layers = self._split(scalars)
        last = len(layers) - 1
        rows = []
        for k, (W, b) in enumerate(layers):
            # A unit that never fires above the horizon outputs exactly 0: left out.
            kept = [o for o in range(len(b)) if k == last or active is None or active[k][o]]
            rows.append((kept, [mi.ArrayXf(*[W_i[o] for o in kept]) for W_i in W], mi.ArrayXf(*[b[o] for o in kept])))
        return rows

    def eval_input(self, x: list):
        """The network on an input list (``None`` entries are zeros): ``f_r``, clamped at 0 (RGB,
        or a spectral network's ``count`` coefficients as a list)."""
        h = x
        layers = self._vectorised(self.kernel())
        last = len(layers) - 1
        for k, (kept, W, b) in enumerate(layers):
            if not kept:  # every unit of the layer proved dead: its outputs are exactly 0
                h = [None] * self.shapes[k][1]
                continue
            acc = b
            for h_i, W_i in zip(h, W):
                if h_i is not None:
                    acc = dr.fma(h_i, W_i, acc)
            if k < last:
                acc = relu(acc)
            h = [None] * self.shapes[k][1]
            for j, o in enumerate(kept):
                h[o] = acc[j]
        out = [relu(expm1(clamp_exp_argument(v))) for v in h]
        # A spectral network's outputs are its B-spline coefficients (spectral_value reads them).
        return out if len(out) != 3 else mi.Color3f(out[0], out[1], out[2])

    def eval(self, view: mi.Vector3f, light: mi.Vector3f):
        """``f_r(light, view)``, zero at or below the horizon and for zero or non-finite
        directions (``network/kernel.rs`` ``eval_chunks``): a ``mi.Color3f``, or a spectral
        network's list of coefficients."""
        x = network_input(view, light, self.anisotropic)
        ok = both_valid_above(view, light)
        if self.recorder is not None and self.recorder.recording():
            with dr.suspend_grad():
                f = self.eval_input(x)
            return dr.select(ok, mi.Color3f(*self.recorder.probe(f, x, ok)), 0.0)
        f = self.eval_input(x)
        return [dr.select(ok, c, 0.0) for c in f] if isinstance(f, list) else dr.select(ok, f, 0.0)

