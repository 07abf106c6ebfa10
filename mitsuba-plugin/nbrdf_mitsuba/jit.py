"""The rendering formulas of the Rust library written as Dr.Jit arithmetic: the network input and
forward pass, the MERL lookup, the hemisphere warps, the Phong, two-lobe and anisotropic lobes
and the tabulated sampler; and, for spectral variants, Mitsuba's RGB-to-spectrum lookup per lane
(:class:`SrgbModel`, :func:`spectrum_from_rgb`).

Why a second copy: traced into Mitsuba's own kernels, a scene with NBRDFs keeps Dr.Jit's symbolic
(megakernel) mode and runs on CUDA as well as LLVM. The Rust code stays the reference; each
function here is a deliberate twin of one there. Which twin, and the test holding the two
together: docs/design.md, "Twins" (the twin table, checked by tests/test_twin_map.py).

Sharp lobes: ``1 - cos(theta_h)`` is computed from ``|h_xy|^2`` (never as ``1 - h.z``, which
cancels in float32), so the pdf keeps its accuracy up to :data:`MAX_EXPONENT`.

Weights enter the kernel either as literals (``literal``: constant-folded, fastest, but one kernel
per material), as kernel parameters (``opaque``: one kernel per network shape shared by every
material, the weights passed per instance) or as whichever suits the scene (``auto``: literals for
a few networks, the shared kernel for more). See ``TracedNetwork``.
"""

from __future__ import annotations

import math
import threading
import weakref

import drjit as dr
import mitsuba as mi
import numpy as np

from ._native import KIND, SAMPLING_KINDS

# The exp argument range of nbrdf-core's fastmath.rs (EXP_ARG_MAX / EXP_ARG_MIN): e^80 ~ 5.5e34
# stays far below float32's maximum, and below -87 the result is -1 to float32 precision.
EXP_ARGUMENT_MAX = 80.0
EXP_ARGUMENT_MIN = -87.0
SIN_THETA_H_EPS = 1e-7
#: The largest Blinn-Phong exponent the plugins accept (docs/design.md promises stable sampling up to
#: 1e6; beyond it float32 directions cannot resolve the lobe and the backends would disagree).
MAX_EXPONENT = 1e6


def relu(v):
    """``max(v, 0)`` with NaN -> 0 (``fastmath.rs`` ``relu``: ``if v > 0 { v } else { 0 }``)."""
    return dr.select(v > 0, v, 0.0)


def clamp_exp_argument(z):
    """``fastmath.rs`` ``clamp_exp_arg``: into ``[EXP_ARGUMENT_MIN, EXP_ARGUMENT_MAX]``, NaN to the
    lower end (compare-selects, not min/max, whose NaN handling is backend-specific)."""
    z = dr.select(z > EXP_ARGUMENT_MIN, z, EXP_ARGUMENT_MIN)
    return dr.select(z < EXP_ARGUMENT_MAX, z, EXP_ARGUMENT_MAX)


def unit_vector(x, y, z):
    """``(x, y, z) / |(x, y, z)|`` and whether it exists (false for zero, infinite and NaN input).

    Divides by the largest component first, as ``network/kernel.rs`` ``rescale_out_of_range`` does, so
    that vectors far too short or long to square in float32 keep their direction."""
    m = dr.maximum(dr.maximum(dr.abs(x), dr.abs(y)), dr.abs(z))
    finite = dr.isfinite(x) & dr.isfinite(y) & dr.isfinite(z)
    ok = finite & (m > 0)
    inv_m = dr.select(ok, dr.rcp(m), 0.0)
    x, y, z = x * inv_m, y * inv_m, z * inv_m
    length2 = dr.fma(x, x, dr.fma(y, y, z * z))
    inv = dr.select(ok, dr.rsqrt(length2), 0.0)
    return x * inv, y * inv, z * inv, ok


def cos_theta(v: mi.Vector3f):
    """``brdf.rs`` ``cos_theta_light``: ``z / |v|``, 0 for zero and non-finite vectors."""
    _, _, z, ok = unit_vector(v.x, v.y, v.z)
    return dr.select(ok, dr.maximum(z, 0.0), 0.0)


def _unit_or_normal(x, y, z):
    """Unit vector, or the normal +z for zero, infinite or NaN input (as the Rust core)."""
    x, y, z, usable = unit_vector(x, y, z)
    return dr.select(usable, x, 0.0), dr.select(usable, y, 0.0), dr.select(usable, z, 1.0)


def network_input(view: mi.Vector3f, light: mi.Vector3f, anisotropic: bool = False) -> list:
    """``[sin th, 0, cos th, d.x, d.y, d.z]`` (docs/design.md section 2), branch-free like the Rust code;
    for an anisotropic network ``[sin th cos ph, sin th sin ph, cos th, d.x, d.y, d.z]``, the half
    vector in the local frame (x: the shading frame's tangent)."""
    lx, ly, lz = _unit_or_normal(light.x, light.y, light.z)
    vx, vy, vz = _unit_or_normal(view.x, view.y, view.z)
    hx, hy, hz = lx + vx, ly + vy, lz + vz
    h_len2 = dr.fma(hx, hx, dr.fma(hy, hy, hz * hz))
    degenerate = h_len2 <= 0
    hi = dr.select(degenerate, 0.0, dr.rsqrt(h_len2))
    hx, hy = hx * hi, hy * hi
    hz = dr.select(degenerate, 1.0, hz * hi)
    sin_th = dr.sqrt(dr.fma(hx, hx, hy * hy))
    has_azimuth = sin_th > SIN_THETA_H_EPS
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


#: Cody-Waite split of ln 2 and log2(e) of ``fastmath.rs``.
LN2_HI = 355.0 / 512.0
LN2_LO = -2.1219444e-4
LOG2_E = 1.4426950408889634


def expm1(x):
    """exp(x) - 1 with full relative precision near 0 (most of a BRDF's domain holds small
    reflectances, where exp(x) - 1 cancels), for x in [EXP_ARGUMENT_MIN, EXP_ARGUMENT_MAX].

    Twin of ``fastmath.rs`` ``expm1_with`` (held together by tests/test_backends.py): ``x = k ln 2
    + r``, ``|r| <= ln 2 / 2``, ``expm1(x) = 2^k expm1(r) + (2^k - 1)`` with the degree-7 Taylor
    series of ``expm1(r)``; about 1e-7 relative error, and no exp or log, which as Dr.Jit's
    polynomials cost as much as the network's 630 multiply-adds (an exp and a log per channel
    made the traced network 1.2x slower)."""
    k = dr.round(x * LOG2_E)
    r = dr.fma(-k, LN2_LO, dr.fma(-k, LN2_HI, x))
    scale = dr.reinterpret_array(mi.Float, (mi.Int32(k) + 127) << 23)
    p = mi.Float(1.0 / 5040.0)
    for c in (1.0 / 720.0, 1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 0.5):
        p = dr.fma(p, r, c)
    return dr.fma(scale, dr.fma(p * r, r, r), scale - 1.0)


#: ``jit_weights = "auto"`` traces literal kernels while at most this many traced networks are
#: alive in the variant, and the shared kernel (kernel parameters) beyond. Each literal network
#: is its own callable in Mitsuba's symbolic call, compiled on the first render (about 0.3 s on
#: two cores); kernel-parameter networks of one shape trace to the same code, which Dr.Jit
#: compiles once. Measured: docs/results/performance.md, "Many materials".
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
    the values do not change and a trained network loses up to two thirds of its multiply-adds
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
        #: The weights of each kind of kernel this network traces: "literal", "parameters".
        self._kernels = {}
        if self.mode == "literal":
            self._kernels["literal"] = self._split([mi.Float(float(v)) for v in values])
        if self.mode == "opaque":
            # Gathers at literal indices give 675 size-1 variables; make_opaque evaluates them in
            # one small kernel so they become kernel parameters, not constants, and keeps their
            # AD edges to ``flat``.
            scalars = [dr.gather(mi.Float, self.flat, k) for k in range(dr.width(self.flat))]
            dr.make_opaque(*scalars)
            self._kernels["parameters"] = self._split(scalars)
        elif self.mode == "auto":
            # No AD edges needed: each value becomes its own one-element buffer, no kernel runs.
            scalars = [mi.Float(float(v)) for v in values]
            dr.make_opaque(*scalars)
            self._kernels["parameters"] = self._split(scalars)

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
        """Which kernel the next trace uses: ``literal`` or ``parameters`` (see the class)."""
        if self.mode == "auto":
            return "literal" if live_networks() <= AUTO_LITERAL_MAX else "parameters"
        return "literal" if self.mode == "literal" else "parameters"

    def eval_input(self, x: list):
        """The network on an input list (``None`` entries are zeros): ``f_r``, clamped at 0 (RGB,
        or a spectral network's ``count`` coefficients as a list)."""
        h = x
        kernel = self.kernel()
        if kernel not in self._kernels:  # "auto" makes its literals when it first needs them
            self._kernels[kernel] = self._split([mi.Float(float(v)) for v in self.good])
        layers = self._kernels[kernel]
        active = self.active if kernel == "literal" else None
        last = len(layers) - 1
        for k, (W, b) in enumerate(layers):
            out = []
            for o in range(len(b)):
                if k < last and active is not None and not active[k][o]:
                    out.append(None)  # never fires above the horizon: exactly 0
                    continue
                acc = b[o]
                for i, h_i in enumerate(h):
                    if h_i is not None:
                        acc = dr.fma(h_i, W[i][o], acc)
                out.append(acc)
            h = [None if v is None else relu(v) for v in out] if k < last else out
        out = [relu(expm1(clamp_exp_argument(v))) for v in h]
        # A spectral network's outputs are its B-spline coefficients (spectral_value reads them).
        return out if len(out) != 3 else mi.Color3f(out[0], out[1], out[2])

    def eval(self, view: mi.Vector3f, light: mi.Vector3f):
        """``f_r(light, view)``, zero at or below the horizon and for zero or non-finite
        directions (``network/kernel.rs`` ``eval_chunks``): a ``mi.Color3f``, or a spectral
        network's list of coefficients."""
        f = self.eval_input(network_input(view, light, self.anisotropic))
        ok = _both_valid_above(view, light)
        return [dr.select(ok, c, 0.0) for c in f] if isinstance(f, list) else dr.select(ok, f, 0.0)


def _both_valid_above(view, light):
    *_, vz, v_ok = unit_vector(view.x, view.y, view.z)
    *_, lz, l_ok = unit_vector(light.x, light.y, light.z)
    return v_ok & l_ok & (vz > 0) & (lz > 0)


def _log1m(x):
    """ln(1 - x) for x in [0, 1) with full relative accuracy for small x: Rust's ``ln_1p(-x)``
    (``sampling/phong.rs``; parity: tests/test_hardening_plugin.py's zoomed chi2 at n = 1e6).
    Below 1/16 it is the series ``-2 atanh(t)``, t = x / (2 - x) <= 0.033, to t^7 (relative error
    < 1e-10), because CUDA's ``dr.log`` (``lg2.approx``) is only accurate to ~1e-7 absolute near 1,
    which is 10 % of ln(1 - 1e-6): a sharp lobe's pdf would lose its shape there."""
    t = x / (2.0 - x)
    t2 = t * t
    series = -2.0 * t * dr.fma(t2, dr.fma(t2, dr.fma(t2, 1.0 / 7.0, 1.0 / 5.0), 1.0 / 3.0), 1.0)
    small = x < 0.0625
    return dr.select(small, series, dr.log(dr.select(small, 0.5, 1.0 - x)))


def _cos_power_from_one_minus(one_minus_cos, exponent):
    """cos^n = exp(n ln(1 - (1 - cos))) from ``1 - cos`` (``sampling/phong.rs`` ``cos_power_from_one_minus``), with
    n = 0 -> 1 and cos <= 0 -> 0 (never NaN)."""
    positive = one_minus_cos < 1.0
    value = dr.exp(exponent * _log1m(dr.select(positive, dr.maximum(one_minus_cos, 0.0), 0.0)))
    value = dr.select(positive, value, 0.0)
    return dr.select(exponent == 0, 1.0, value)


def _spherical(cos_theta, sin_theta, u):
    sin_phi, cos_phi = dr.sincos(2.0 * math.pi * u)
    return mi.Vector3f(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta)


def unit_interval(u):
    """``sampling/mod.rs`` ``unit_interval``: clamped into [0, 1], NaN -> 0."""
    return dr.select(u >= 0, dr.minimum(u, 1.0), 0.0)


def uniform_hemisphere(u1, u2) -> mi.Vector3f:
    """Same warp as ``sampling::uniform_hemisphere``: ``cos theta = u1``."""
    z = dr.clip(u1, 0.0, 1.0)
    return _spherical(z, dr.safe_sqrt((1.0 - z) * (1.0 + z)), u2)


def cosine_hemisphere(u1, u2) -> mi.Vector3f:
    """Same warp as ``sampling::cosine_hemisphere``: ``sin theta = sqrt(u1)``."""
    u1 = dr.clip(u1, 0.0, 1.0)
    return _spherical(dr.safe_sqrt(1.0 - u1), dr.safe_sqrt(u1), u2)


def _phong_elevation(exponent, u):
    """``(cos theta, sin theta)`` with ``cos theta = u^(1/(n+1))``; ``1 - cos`` from expm1 keeps
    sharp lobes' spread."""
    u = dr.clip(u, 0.0, 1.0)
    positive = u > 0
    log_u = dr.log(dr.select(positive, u, 1.0))
    # The network's expm1 (exact near 0); below EXP_ARGUMENT_MIN, 1 - cos rounds to 1 anyway.
    one_minus_cos = dr.select(positive, -expm1(clamp_exp_argument(log_u / (exponent + 1.0))), 1.0)
    one_minus_cos = dr.clip(one_minus_cos, 0.0, 1.0)
    cos_theta = 1.0 - one_minus_cos
    return cos_theta, dr.safe_sqrt(one_minus_cos * (1.0 + cos_theta))


def phong_half_vector(exponent, u1, u2) -> mi.Vector3f:
    """``cos theta_h = u1^(1/(n+1))``, the azimuth ``2 pi u2``."""
    return _spherical(*_phong_elevation(exponent, u1), u2)


def _unit(v: mi.Vector3f):
    """Unit vector and whether ``v`` had one (zero, infinite and NaN vectors give zero)."""
    x, y, z, ok = unit_vector(v.x, v.y, v.z)
    return mi.Vector3f(x, y, z), ok


def _in_range(x, y, z):
    """``x, y, z`` divided by the largest component unless the length is within a factor 2 of 1
    (unit inputs stay bit-exact; products of two such vectors cannot overflow)."""
    length2 = dr.fma(x, x, dr.fma(y, y, z * z))
    fine = (length2 > 0.25) & (length2 < 4.0)
    m = dr.maximum(dr.maximum(dr.abs(x), dr.abs(y)), dr.abs(z))
    scale = dr.select(fine | ~(m > 0) | ~dr.isfinite(m), 1.0, dr.rcp(m))
    return mi.Vector3f(x * scale, y * scale, z * scale)


def _half_vector_terms(view: mi.Vector3f, light: mi.Vector3f):
    """``1 - |cos(theta_h)|`` and ``|v . h|`` of the half vector of the (possibly non-unit) view
    and light, without cancellation, and whether the half vector exists (``l != -v``).

    With ``s = v |l| + l |v|`` (parallel to ``v/|v| + l/|l|``; for unit float32 inputs the norms
    are exactly 1 and ``s`` is exact where ``l`` mirrors ``v``):
    ``1 - |s_z|/|s| = |s_xy|^2 / (|s|^2 + |s_z| |s|)`` and ``v . h = |s| / (2 |v| |l|)``.
    ``1 - h.z`` in float32 would lose the whole lobe of ``n = 1e6`` (width ~1e-6) to rounding."""
    v, l = _in_range(view.x, view.y, view.z), _in_range(light.x, light.y, light.z)
    v_norm, l_norm = dr.norm(v), dr.norm(l)
    s = v * l_norm + l * v_norm
    xy2 = dr.fma(s.x, s.x, s.y * s.y)
    s2 = dr.fma(s.z, s.z, xy2)
    ok = (s2 > 0) & dr.isfinite(s2)
    norm = dr.sqrt(s2)
    denominator = dr.select(ok, dr.fma(dr.abs(s.z), norm, s2), 1.0)
    one_minus_cos = dr.select(ok, xy2 / denominator, 1.0)
    v_dot_h = dr.select(ok, norm / (2.0 * v_norm * l_norm), 0.0)
    return one_minus_cos, v_dot_h, ok


def mixture_pdf(view: mi.Vector3f, light: mi.Vector3f, exponent, specular_weight):
    """The Blinn-Phong mixture pdf per unit solid angle of ``light`` (docs/design.md section 6),
    zero unless both directions are above the horizon."""
    v, v_ok = _unit(view)
    l, l_ok = _unit(light)
    one_minus_cos, v_dot_h, h_ok = _half_vector_terms(view, light)
    lobe = (exponent + 1.0) * (0.5 / math.pi) * _cos_power_from_one_minus(one_minus_cos, exponent)
    specular = dr.select(h_ok & (v_dot_h > 0), lobe / (4.0 * v_dot_h), 0.0)
    specular = dr.select(specular_weight > 0, specular_weight * specular, 0.0)
    pdf = specular + (1.0 - specular_weight) * dr.maximum(l.z, 0.0) / math.pi
    return dr.select(v_ok & l_ok & (v.z > 0) & (l.z > 0), pdf, 0.0)


def two_lobe_pdf(view: mi.Vector3f, light: mi.Vector3f, exponent, specular_weight, exponent2,
                 specular_weight2):
    """``w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine`` per unit solid angle of ``light``
    (``sampling/two_lobe.rs`` ``density``; the cosine weight clamped at 0), zero unless
    both directions are above the horizon."""
    v, v_ok = _unit(view)
    l, l_ok = _unit(light)
    one_minus_cos, v_dot_h, h_ok = _half_vector_terms(view, light)
    h_ok = h_ok & (v_dot_h > 0)
    pdf = mi.Float(0.0)
    for n, w in ((exponent, specular_weight), (exponent2, specular_weight2)):
        lobe = (n + 1.0) * (0.5 / math.pi) * _cos_power_from_one_minus(one_minus_cos, n)
        specular = dr.select(h_ok, lobe / (4.0 * v_dot_h), 0.0)
        pdf += dr.select(w > 0, w * specular, 0.0)
    cosine_weight = dr.maximum(1.0 - specular_weight - specular_weight2, 0.0)
    pdf += cosine_weight * dr.maximum(l.z, 0.0) / math.pi
    return dr.select(v_ok & l_ok & (v.z > 0) & (l.z > 0), pdf, 0.0)


def anisotropic_pdf(view: mi.Vector3f, light: mi.Vector3f, exponent_u, specular_weight, exponent_v):
    """The anisotropic Blinn-Phong mixture (Ashikhmin-Shirley half-vector density, ``n_u`` along
    the tangent x, ``n_v`` across) per unit solid angle of ``light``, zero unless both directions
    are above the horizon (``sampling/anisotropic.rs`` ``density``)."""
    v, v_ok = _unit(view)
    l, l_ok = _unit(light)
    one_minus_cos, v_dot_h, h_ok = _half_vector_terms(view, light)
    # The half vector's azimuth from s = v |l| + l |v| as in _half_vector_terms.
    vr, lr = _in_range(view.x, view.y, view.z), _in_range(light.x, light.y, light.z)
    s = vr * dr.norm(lr) + lr * dr.norm(vr)
    xy2 = dr.fma(s.x, s.x, s.y * s.y)
    cos2_phi = dr.select(xy2 > 0, s.x * s.x / dr.select(xy2 > 0, xy2, 1.0), 1.0)
    exponent = exponent_u * cos2_phi + exponent_v * (1.0 - cos2_phi)
    lobe = (dr.sqrt((exponent_u + 1.0) * (exponent_v + 1.0)) * (0.5 / math.pi)
            * _cos_power_from_one_minus(one_minus_cos, exponent))
    specular = dr.select(h_ok & (v_dot_h > 0), lobe / (4.0 * v_dot_h), 0.0)
    specular = dr.select(specular_weight > 0, specular_weight * specular, 0.0)
    pdf = specular + (1.0 - specular_weight) * dr.maximum(l.z, 0.0) / math.pi
    return dr.select(v_ok & l_ok & (v.z > 0) & (l.z > 0), pdf, 0.0)


def anisotropic_half_vector(exponent_u, exponent_v, u1, u2) -> mi.Vector3f:
    """``phi = atan(sqrt((n_u + 1)/(n_v + 1)) tan(pi xi / 2))`` per quadrant (``u1`` picks the
    quadrant and ``xi``), then ``cos theta_h = u2^(1/(n(phi) + 1))``."""
    scaled = 4.0 * dr.clip(u1, 0.0, 1.0)
    quadrant = dr.minimum(dr.floor(scaled), 3.0)
    xi = scaled - quadrant
    ratio = dr.sqrt((exponent_u + 1.0) / (exponent_v + 1.0))
    phi0 = dr.atan(ratio * dr.tan(0.5 * math.pi * xi))
    phi = dr.select(quadrant == 0, phi0,
                    dr.select(quadrant == 1, math.pi - phi0,
                              dr.select(quadrant == 2, math.pi + phi0, 2.0 * math.pi - phi0)))
    sin_phi, cos_phi = dr.sincos(phi)
    exponent = exponent_u * cos_phi * cos_phi + exponent_v * sin_phi * sin_phi
    cos_theta, sin_theta = _phong_elevation(exponent, u2)
    return mi.Vector3f(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta)


class TracedTable:
    """The tabulated half-vector sampler (``sampling/tabulated.rs``) from the library's arrays
    (``_native.Sampler.arrays``): the view's elevation picks a row, the row's alias table a bin in
    ``t = (1 - cos theta_h)^(1/4)`` and ``|phi_h - phi_v|`` over ``[0, pi]``, ``u2`` the side of
    the plane of incidence, the half vector uniform in solid angle within the bin or its mirror
    image; mixed with cosine. The pdf is the bin's mass over the solid angle of the bin and its
    mirror image through the half-vector Jacobian (``density_f64``)."""

    def __init__(self, rows: int, theta_bins: int, phi_bins: int, cosine_weight: float,
                 mass: np.ndarray, alias_probability: np.ndarray, alias: np.ndarray):
        self.rows, self.theta_bins, self.phi_bins = int(rows), int(theta_bins), int(phi_bins)
        self.cosine_weight = float(cosine_weight)
        # Kernel parameters rather than literals, so that tables of different cosine weights trace
        # to the same code (one callable for hundreds of materials); each is the float32 of the
        # float64 value a literal would hold, so the values do not change.
        self._cosine = mi.Float(self.cosine_weight)
        self._rest = mi.Float(1.0 - self.cosine_weight)
        # (A table of cosine weight 1 never picks a bin: u0 < 1 selects the cosine lobe.)
        self._inv_rest = mi.Float(1.0 / (1.0 - self.cosine_weight) if self.cosine_weight < 1.0 else 0.0)
        dr.make_opaque(self._cosine, self._rest, self._inv_rest)
        self.mass = mi.Float(np.asarray(mass, dtype=np.float32))
        self.alias_probability = mi.Float(np.asarray(alias_probability, dtype=np.float32))
        self.alias = mi.UInt32(np.asarray(alias, dtype=np.uint32))

    def _row(self, v: mi.Vector3f):
        theta_v = dr.atan2(dr.sqrt(dr.fma(v.x, v.x, v.y * v.y)), v.z)
        return dr.minimum(mi.UInt32(dr.maximum(theta_v * (2.0 / math.pi) * self.rows, 0.0)), self.rows - 1)

    def _edge(self, i):
        """``1 - cos theta_h`` at the ``t``-bin edge ``i`` (``sampling/tabulated.rs`` ``bin_one_minus_cos``)."""
        t = mi.Float(i) * (1.0 / self.theta_bins)
        t2 = t * t
        return t2 * t2

    @staticmethod
    def _view_azimuth(v: mi.Vector3f):
        """``(cos phi_v, sin phi_v)``, +x at the normal (``sampling/tabulated.rs`` ``view_azimuth``)."""
        length = dr.sqrt(dr.fma(v.x, v.x, v.y * v.y))
        inside = length > 0
        inv = dr.rcp(dr.select(inside, length, 1.0))
        return dr.select(inside, v.x * inv, 1.0), dr.select(inside, v.y * inv, 0.0)

    def pick(self, row, u):
        """``sampling/tabulated.rs`` ``pick``: the bin (within the row) of the rescaled uniform ``u``
        through the row's alias table."""
        n = self.theta_bins * self.phi_bins
        scaled = u * n
        k = dr.minimum(mi.UInt32(scaled), n - 1)
        index = row * n + k
        keep = scaled - mi.Float(k) < dr.gather(mi.Float, self.alias_probability, index)
        return dr.select(keep, k, dr.gather(mi.UInt32, self.alias, index, ~keep))

    def sample_direction(self, v: mi.Vector3f, u0, u1, u2) -> mi.Vector3f:
        c = self._cosine
        bin_ = self.pick(self._row(v), (u0 - c) * self._inv_rest)
        i, j = bin_ // self.phi_bins, bin_ % self.phi_bins
        o0, o1 = self._edge(i), self._edge(i + 1)
        one_minus_cos = dr.fma(u1, o1 - o0, o0)
        cos_h = 1.0 - one_minus_cos
        sin_h = dr.safe_sqrt(one_minus_cos * (1.0 + cos_h))
        mirrored = u2 >= 0.5
        fp = dr.select(mirrored, 2.0 * u2 - 1.0, 2.0 * u2)
        sin_p, cos_p = dr.sincos((mi.Float(j) + fp) * (math.pi / self.phi_bins))
        sin_p = dr.select(mirrored, -sin_p, sin_p)
        cx, cy = self._view_azimuth(v)
        h = mi.Vector3f(sin_h * (cos_p * cx - sin_p * cy), sin_h * (cos_p * cy + sin_p * cx), cos_h)
        reflected = 2.0 * dr.dot(v, h) * h - v
        return dr.select(u0 < c, cosine_hemisphere(u1, u2), reflected)

    def pdf(self, view: mi.Vector3f, light: mi.Vector3f):
        v, v_ok = _unit(view)
        l, l_ok = _unit(light)
        cosine = self._cosine * dr.maximum(l.z, 0.0) / math.pi
        s = v + l
        h = dr.normalize(s)
        v_dot_h = dr.dot(v, h)
        valid = (dr.squared_norm(s) > 0) & (v_dot_h > 0) & (h.z > 0)
        t = dr.sqrt(dr.sqrt(dr.fma(h.x, h.x, h.y * h.y) / (1.0 + h.z)))
        cx, cy = self._view_azimuth(v)
        phi = dr.abs(dr.atan2(cx * h.y - cy * h.x, cx * h.x + cy * h.y))
        nt, np_ = self.theta_bins, self.phi_bins
        i = dr.minimum(mi.UInt32(t * nt), nt - 1)
        j = dr.minimum(mi.UInt32(phi * (np_ / math.pi)), np_ - 1)
        p = dr.gather(mi.Float, self.mass, (self._row(v) * nt + i) * np_ + j, valid)
        solid_angle = (self._edge(i + 1) - self._edge(i)) * (2.0 * math.pi / np_)  # with the mirror
        table = p / solid_angle / (4.0 * v_dot_h)
        pdf = cosine + self._rest * dr.select(valid, table, 0.0)
        return dr.select(v_ok & l_ok & (v.z > 0) & (l.z > 0), pdf, 0.0)




def _isotropic_pdf(density):
    """The pdf of a view-independent density of ``l`` (0 off the upper hemisphere)."""
    def pdf_(view, light, params, table):
        v, v_ok = _unit(view)
        l, l_ok = _unit(light)
        return dr.select(v_ok & l_ok & (v.z > 0) & (l.z > 0), density(l), 0.0)
    return pdf_


_PDF = {
    KIND.uniform: _isotropic_pdf(lambda l: 0.5 / math.pi),
    KIND.cosine: _isotropic_pdf(lambda l: l.z / math.pi),
    KIND.phong: lambda view, light, p, table: mixture_pdf(view, light, p[0], p[1]),
    KIND.two_lobe: lambda view, light, p, table: two_lobe_pdf(view, light, *p),
    KIND.anisotropic_phong: lambda view, light, p, table: anisotropic_pdf(view, light, p[0], p[1], p[2]),
    KIND.tabulated: lambda view, light, p, table: table.pdf(view, light),
}


def _reflected(view, h):
    v, _ = _unit(view)
    return 2.0 * dr.dot(v, h) * h - v


def _sample_phong(view, u0, u1, u2, p, table):
    specular = (u0 < p[1]) | (p[1] >= 1.0)
    return dr.select(specular, _reflected(view, phong_half_vector(p[0], u1, u2)), cosine_hemisphere(u1, u2))


def _sample_two_lobe(view, u0, u1, u2, p, table):
    # The component choice of sampling/two_lobe.rs two_lobe_component.
    exponent, specular_weight, exponent2, specular_weight2 = p
    total = specular_weight + specular_weight2
    first = u0 < specular_weight
    second = ~first & (u0 < total)
    rest = ~first & ~second & (total >= 1.0)
    first |= rest & ~(specular_weight2 > 0)
    second |= rest & (specular_weight2 > 0)
    h = phong_half_vector(dr.select(first, exponent, exponent2), u1, u2)
    return dr.select(first | second, _reflected(view, h), cosine_hemisphere(u1, u2))


def _sample_anisotropic(view, u0, u1, u2, p, table):
    specular = (u0 < p[1]) | (p[1] >= 1.0)
    h = anisotropic_half_vector(p[0], p[2], u1, u2)
    return dr.select(specular, _reflected(view, h), cosine_hemisphere(u1, u2))


_SAMPLE = {
    KIND.uniform: lambda view, u0, u1, u2, p, table: uniform_hemisphere(u1, u2),
    KIND.cosine: lambda view, u0, u1, u2, p, table: cosine_hemisphere(u1, u2),
    KIND.phong: _sample_phong,
    KIND.two_lobe: _sample_two_lobe,
    KIND.anisotropic_phong: _sample_anisotropic,
    KIND.tabulated: lambda view, u0, u1, u2, p, table: table.sample_direction(_unit(view)[0], u0, u1, u2),
}
#: Every strategy of the library, each with a traced pdf and sampler.
STRATEGIES = tuple(SAMPLING_KINDS)
if set(_PDF) != set(STRATEGIES) or set(_SAMPLE) != set(STRATEGIES):
    raise ImportError(f"nbrdf_mitsuba.jit: the traced strategies {sorted(_SAMPLE)} are not the library's "
                      f"{sorted(STRATEGIES)}")


def _strategy(table: dict, strategy: str):
    try:
        return table[strategy]
    except KeyError:
        raise ValueError(f"unknown sampling strategy '{strategy}' (one of {', '.join(STRATEGIES)})") from None


def pdf(strategy: str, view, light, exponent=0.0, specular_weight=0.0, exponent2=0.0,
        specular_weight2=0.0, table: TracedTable | None = None):
    """Density of ``light`` given ``view`` for a strategy of ``STRATEGIES`` (``tabulated``
    needs ``table``; ``exponent2`` is ``n_v`` for ``anisotropic_phong``)."""
    params = (exponent, specular_weight, exponent2, specular_weight2)
    return _strategy(_PDF, strategy)(view, light, params, table)


def sample(strategy: str, view, u0, u1, u2, exponent=0.0, specular_weight=0.0, exponent2=0.0,
           specular_weight2=0.0, table: TracedTable | None = None):
    """Draws a light direction like ``SamplingStrategy::sample``: ``(light, pdf)`` with pdf 0
    for invalid samples (a specular reflection below the horizon, a view below it)."""
    draw = _strategy(_SAMPLE, strategy)
    u0, u1, u2 = unit_interval(u0), unit_interval(u1), unit_interval(u2)
    params = (exponent, specular_weight, exponent2, specular_weight2)
    light = draw(view, u0, u1, u2, params, table)
    _, view_ok = _unit(view)
    light, light_ok = _unit(light)
    # As SamplingStrategy::sample: +z (with pdf 0) when there is no direction to return.
    light = dr.select(view_ok & light_ok, light, mi.Vector3f(0.0, 0.0, 1.0))
    return light, pdf(strategy, view, light, exponent, specular_weight, exponent2, specular_weight2, table)


# MERL grid (docs/design.md section 3), as in nbrdf-core's merl/grid.rs.
N_THETA_H, N_THETA_D, N_PHI_D = 90, 90, 180
MERL_SCALE = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)


def _lerp_clamped(t, n: int):
    """Lower cell, upper cell and upper weight between centres, clamped (``lerp_clamped``)."""
    t = dr.clip(t, 0.0, float(n - 1))
    i0 = dr.minimum(mi.UInt32(dr.floor(t)), n - 2)
    return i0, i0 + 1, t - mi.Float(i0)


def _lerp_wrapped(t, n: int):
    """As ``_lerp_clamped`` on the periodic phi_d axis (``lerp_wrapped``)."""
    floor = dr.floor(t)
    i0 = mi.Int32(floor)
    i0 = mi.UInt32(dr.select(i0 < 0, i0 + n, dr.select(i0 >= n, i0 - n, i0)))
    i1 = dr.select(i0 + 1 >= n, 0, i0 + 1)
    return i0, i1, t - floor


class TracedMerl:
    """A MERL-format table as a Dr.Jit array with gathers and trilinear interpolation, the
    same rule as ``MerlTable::trilinear``: cell values at cell centres, clamped in theta,
    wrapping in phi_d, unmeasured neighbours left out and the weights renormalised."""

    def __init__(self, stored: np.ndarray):
        """``stored``: the file's values, channel-major ``(3, 90*90*180)``, unscaled."""
        stored = np.asarray(stored, dtype=np.float64).reshape(3, -1)
        invalid = np.any(stored < 0, axis=0)
        reflectance = stored * np.asarray(MERL_SCALE)[:, None]
        reflectance[:, invalid] = -1.0  # one sentinel for the whole cell
        self.table = mi.Float(np.ascontiguousarray(reflectance.T).ravel().astype(np.float32))

    def eval(self, view: mi.Vector3f, light: mi.Vector3f) -> mi.Color3f:
        """``f_r(light, view)``, zero at or below the horizon."""
        sin_th, _, cos_th, dx, dy, dz = network_input(view, light)
        theta_h = dr.atan2(sin_th, cos_th)
        theta_d = dr.acos(dr.clip(dz, -1.0, 1.0))
        phi_d = dr.atan2(dy, dx)
        phi_d = dr.select(phi_d < 0, phi_d + math.pi, phi_d)
        phi_d = dr.select(phi_d >= math.pi, phi_d - math.pi, phi_d)
        index_h = N_THETA_H * dr.sqrt(dr.maximum(theta_h, 0.0) / (0.5 * math.pi))
        index_d = N_THETA_D * theta_d / (0.5 * math.pi)
        index_p = N_PHI_D * phi_d / math.pi
        h = _lerp_clamped(index_h - 0.5, N_THETA_H)
        d = _lerp_clamped(index_d - 0.5, N_THETA_D)
        p = _lerp_wrapped(index_p - 0.5, N_PHI_D)
        total = mi.Color3f(0.0)
        weight_sum = mi.Float(0.0)
        for ih, wh in ((h[0], 1.0 - h[2]), (h[1], h[2])):
            for id_, wd in ((d[0], 1.0 - d[2]), (d[1], d[2])):
                for ip, wp in ((p[0], 1.0 - p[2]), (p[1], p[2])):
                    w = wh * wd * wp
                    cell = ip + N_PHI_D * (id_ + N_THETA_D * ih)
                    rgb = dr.gather(mi.Color3f, self.table, cell, w > 0)
                    use = (w > 0) & (rgb[0] >= 0)
                    total += dr.select(use, w * rgb, 0.0)
                    weight_sum += dr.select(use, w, 0.0)
        f = dr.select(weight_sum > 0, total / weight_sum, 0.0)
        return dr.select(_both_valid_above(view, light), f, 0.0)


# --------------------------------------------------------------------------------------------
# Output stage: an RGB value as a spectrum (spectral variants)

_SRGB_COEFFS = 3  # RGB2SPEC_N_COEFFS: c0 lambda^2 + c1 lambda + c2 inside the sigmoid


class SrgbModel:
    """Mitsuba's RGB-to-spectrum model (Jakob and Hanika 2019, the file ``data/srgb.coeff``) with
    ``fetch`` traced: the twin of ``rgb2spec_fetch`` (ext/rgb2spec/rgb2spec.c), which Mitsuba's
    ``mi.srgb_model_fetch`` wraps for one scalar colour only. A BRDF's colour changes with every
    direction, so JIT variants look the coefficients up per lane, with gathers from the same
    table; tests/test_spectral.py holds this to ``mi.srgb_model_fetch``."""

    def __init__(self, path: str):
        with open(path, "rb") as file:
            if file.read(4) != b"SPEC":
                raise RuntimeError(f'"{path}" is not an RGB-to-spectrum model (no "SPEC" header)')
            res = int(np.frombuffer(file.read(4), dtype="<u4")[0])
            scale = np.frombuffer(file.read(4 * res), dtype="<f4")
            data = np.frombuffer(file.read(4 * res**3 * 3 * _SRGB_COEFFS), dtype="<f4")
        if res < 2 or scale.size != res or data.size != res**3 * 3 * _SRGB_COEFFS:
            raise RuntimeError(f'"{path}": truncated RGB-to-spectrum model')
        self.res = res
        self.scale = mi.Float(scale)
        self.data = mi.Float(data)
        self.black = [float(c) for c in data[:_SRGB_COEFFS]]

    def _interval(self, z):
        """rgb2spec_find_interval: the last ``k`` in [0, res - 2] with ``scale[k] <= z``, the same
        binary search unrolled (each lane halves its own range; finished lanes keep theirs)."""
        left, size = mi.UInt32(0), mi.UInt32(self.res - 2)
        for _ in range(self.res.bit_length()):
            half = size >> 1
            middle = left + half + 1
            go = (size > 0) & (dr.gather(mi.Float, self.scale, middle, size > 0) <= z)
            left = dr.select(go, middle, left)
            size = dr.select(size > 0, dr.select(go, size - half - 1, half), size)
        return dr.minimum(left, self.res - 2)

    def fetch(self, rgb) -> mi.Vector3f:
        """The sigmoid-polynomial coefficients of ``rgb``, clamped to [0, 1] as rgb2spec_fetch does."""
        r, g, b = (dr.clip(c, 0.0, 1.0) for c in (rgb[0], rgb[1], rgb[2]))
        res = self.res
        # Grey inputs: the closed form (+-8192 evaluate to 0 and 1 in float32).
        grey = (r == g) & (g == b)
        safe = dr.select((r > 0) & (r < 1), r, 0.5)
        c2 = dr.select(r <= 0, -8192.0, dr.select(r >= 1, 8192.0, (safe - 0.5) / dr.sqrt(safe * (1.0 - safe))))
        # The largest component (the later one on ties) indexes the table's block.
        i = dr.select(g >= r, mi.UInt32(1), mi.UInt32(0))
        z = dr.select(i == 1, g, r)
        i = dr.select(b >= z, mi.UInt32(2), i)
        z = dr.maximum(z, b)
        nz = dr.select(z > 0, z, 1.0)
        scale = (res - 1) / nz
        x = dr.select(i == 0, g, dr.select(i == 1, b, r)) * scale
        y = dr.select(i == 0, b, dr.select(i == 1, r, g)) * scale
        xi = dr.minimum(mi.UInt32(x), res - 2)
        yi = dr.minimum(mi.UInt32(y), res - 2)
        zi = self._interval(z)
        x1, y1 = x - mi.Float(xi), y - mi.Float(yi)
        s0 = dr.gather(mi.Float, self.scale, zi)
        z1 = (z - s0) / (dr.gather(mi.Float, self.scale, zi + 1) - s0)
        x0, y0, z0 = 1.0 - x1, 1.0 - y1, 1.0 - z1
        cell = ((i * res + zi) * res + yi) * res + xi

        def at(dx, dy, dz):
            return dr.gather(mi.Vector3f, self.data, cell + dx + res * (dy + res * dz))

        out = (((at(0, 0, 0) * x0 + at(1, 0, 0) * x1) * y0 + (at(0, 1, 0) * x0 + at(1, 1, 0) * x1) * y1) * z0
               + ((at(0, 0, 1) * x0 + at(1, 0, 1) * x1) * y0 + (at(0, 1, 1) * x0 + at(1, 1, 1) * x1) * y1) * z1)
        out = dr.select(z > 0, out, mi.Vector3f(*self.black))
        return dr.select(grey, mi.Vector3f(0.0, 0.0, c2), out)


_srgb_models: dict[str, SrgbModel] = {}


def srgb_model() -> SrgbModel:
    """The current variant's :class:`SrgbModel`, read once per variant from Mitsuba's own file."""
    variant = mi.variant()
    if variant not in _srgb_models:
        resolver = mi.file_resolver() if hasattr(mi, "file_resolver") else mi.Thread.thread().file_resolver()
        _srgb_models[variant] = SrgbModel(str(resolver.resolve("data/srgb.coeff")))
    return _srgb_models[variant]


def spectrum_from_rgb(rgb, wavelengths):
    """An RGB BRDF value as its spectrum at ``wavelengths``, the way Mitsuba uplifts unbounded RGB
    data (src/volumes/grid.cpp, src/emitters/envmap.cpp): the colour is scaled so that its largest
    component is 0.5 (``scale = 2 max(rgb)``), its coefficients fetched, and the spectrum is
    ``scale * srgb_model_eval``. One rule for every value, so the uplift is linear in the value
    (a sampled weight f cos / pdf uplifts to the uplifted f times cos / pdf) and continuous across
    directions. Wavelengths outside Mitsuba's [MI_CIE_MIN, MI_CIE_MAX] or not finite give 0."""
    scale = 2.0 * dr.maximum(dr.maximum(rgb[0], rgb[1]), rgb[2])
    normalised = rgb / dr.maximum(1e-8, scale)
    if dr.is_jit_v(mi.Float):
        coeff = srgb_model().fetch(normalised)
    else:  # one colour: Mitsuba's own function
        coeff = mi.srgb_model_fetch(mi.ScalarColor3f(normalised[0], normalised[1], normalised[2]))
    value = scale * mi.srgb_model_eval(coeff, wavelengths)
    valid = dr.isfinite(wavelengths) & (wavelengths >= mi.MI_CIE_MIN) & (wavelengths <= mi.MI_CIE_MAX)
    # dr.select returns a plain Array4f, which mi.depolarizer would misread: keep Mitsuba's type.
    return mi.UnpolarizedSpectrum(dr.select(valid, value, 0.0))


# --------------------------------------------------------------------------------------------
# Output stage of spectral networks (file format version 3): a clamped uniform cubic B-spline


def bspline_weights(wavelengths, count: int, min_nm: float, max_nm: float) -> list:
    """The ``count`` clamped uniform cubic B-spline basis functions over ``[min_nm, max_nm]``
    (``count - 3`` equal intervals) at ``wavelengths`` (any Dr.Jit or Mitsuba array type, e.g.
    the 4 wavelengths of a spectral lane): a list of ``count`` values of that type, at most 4 of
    them non-zero, summing to 1 inside the range; all 0 outside it and at non-finite
    wavelengths.

    Twin of the Rust basis of spectral networks (docs/design.md, "Twins"). De Boor's triangular
    scheme (Piegl and Tiller's BasisFuns) on the interval ``j`` of each lane, in units of the
    knot spacing; the knots are ``clip(k - 3, 0, count - 3)``, so the clamped ends need no
    special case and no denominator is ever 0."""
    intervals = count - 3
    x = (wavelengths - min_nm) * (intervals / (max_nm - min_nm))
    valid = dr.isfinite(wavelengths) & (wavelengths >= min_nm) & (wavelengths <= max_nm)
    x = dr.select(valid, x, 0.0)
    j = dr.minimum(dr.floor(x), intervals - 1.0)

    def knot(d):  # t[j + 3 + d] in units of the spacing
        return dr.clip(j + d, 0.0, float(intervals))

    n = [dr.select(valid, 1.0, 0.0)]
    for r in range(1, 4):
        left = [None] + [x - knot(1 - s) for s in range(1, r + 1)]
        right = [None] + [knot(s) - x for s in range(1, r + 1)]
        saved = 0.0
        for k in range(r):
            temp = n[k] / (right[k + 1] + left[r - k])
            n[k] = saved + right[k + 1] * temp
            saved = left[r - k] * temp
        n.append(saved)
    # n[r] belongs to coefficient j + r: spread the 4 values over the count slots.
    return [dr.select(j == k, n[0], 0.0) + dr.select(j == k - 1, n[1], 0.0)
            + dr.select(j == k - 2, n[2], 0.0) + dr.select(j == k - 3, n[3], 0.0) for k in range(count)]


def spectral_value(coefficients: list, wavelengths, min_nm: float, max_nm: float):
    """``sum_k c_k B_k(lambda)`` at ``wavelengths`` (:func:`bspline_weights`): a spectral
    network's value per wavelength, 0 outside ``[min_nm, max_nm]`` and at non-finite ones."""
    weights = bspline_weights(wavelengths, len(coefficients), min_nm, max_nm)
    value = weights[0] * coefficients[0]
    for w, c in zip(weights[1:], coefficients[1:]):
        value = dr.fma(w, c, value)
    return value


def srgb_projection(coefficients: list, matrix) -> mi.Color3f:
    """``M c``: linear sRGB of a spectral network's value, ``matrix`` the library's 3 x count
    projection (``nbrdf_material_spectral_srgb``; one formula, in Rust, folded into literals)."""
    rows = []
    for row in np.asarray(matrix, dtype=np.float64).reshape(3, len(coefficients)):
        acc = coefficients[0] * float(row[0])
        for m, c in zip(row[1:], coefficients[1:]):
            acc = dr.fma(c, float(m), acc)
        rows.append(acc)
    return mi.Color3f(rows[0], rows[1], rows[2])
