"""The NBRDF evaluation and the Blinn-Phong mixture written as Dr.Jit arithmetic.

Traced into Mitsuba's own kernels, so a scene with NBRDFs keeps Dr.Jit's symbolic (megakernel)
mode and runs on CUDA as well as LLVM. The Rust library stays the reference: every formula here
mirrors `nbrdf-core` (`coords::network_input_components`, `network`, `sampling`) and the parity
tests hold the two together.

Weights enter the kernel either as literals (``literal``: constant-folded, fastest, but one kernel
per material) or as opaque scalar variables (``opaque``: one kernel per network width shared by
every material, the weights loaded once per kernel launch). See ``TracedNetwork``.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

EXP_ARGUMENT_MAX = 80.0  # keeps exp() finite in float32, as the Rust evaluator does
SIN_THETA_H_EPS = 1e-7


def _unit_or_normal(x, y, z):
    """Unit vector, or the normal +z for zero, infinite or NaN input (as the Rust core)."""
    length2 = dr.fma(x, x, dr.fma(y, y, z * z))
    usable = (length2 > 0) & (length2 < float("inf"))
    inv = dr.rsqrt(length2)
    return dr.select(usable, x * inv, 0.0), dr.select(usable, y * inv, 0.0), dr.select(usable, z * inv, 1.0)


def network_input(view: mi.Vector3f, light: mi.Vector3f) -> list:
    """``[sin th, 0, cos th, d.x, d.y, d.z]`` (DESIGN.md section 2), branch-free like the Rust code."""
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
    return [sin_th, None, hz, dx, ty, dz]  # None: the constant-zero input, skipped in layer 1


class TracedNetwork:
    """An NBRDF as Dr.Jit arithmetic. ``layers`` are ``(W, b)`` NumPy pairs with ``y = x W + b``.

    ``flat`` (W1, b1, W2, b2, W3, b3 as one ``mi.Float``) is what ``traverse`` exposes; after an
    update call ``refresh()`` so the traced kernels see the new values.
    """

    def __init__(self, layers: list[tuple[np.ndarray, np.ndarray]], weights: str = "opaque"):
        if weights not in ("opaque", "literal"):
            raise ValueError(f"weights must be 'opaque' or 'literal', got '{weights}'")
        self.mode = weights
        self.shapes = [(int(W.shape[0]), int(W.shape[1])) for W, _ in layers]
        flat = np.concatenate([np.concatenate([W.ravel(), b.ravel()]) for W, b in layers])
        self.flat = mi.Float(flat.astype(np.float32))
        self.refresh()

    def refresh(self) -> None:
        """Rebuilds the per-weight scalars from ``flat``."""
        if self.mode == "literal":
            values = np.array(self.flat, dtype=np.float32)
            scalars = [mi.Float(float(v)) for v in values]
        else:
            # Gathers at literal indices give 675 size-1 variables; make_opaque evaluates them in
            # one small kernel so they become kernel parameters, not constants.
            scalars = [dr.gather(mi.Float, self.flat, k) for k in range(dr.width(self.flat))]
            dr.make_opaque(*scalars)
        self._layers = []
        offset = 0
        for n_in, n_out in self.shapes:
            W = [scalars[offset + i * n_out : offset + (i + 1) * n_out] for i in range(n_in)]
            offset += n_in * n_out
            b = scalars[offset : offset + n_out]
            offset += n_out
            self._layers.append((W, b))

    def eval_input(self, x: list) -> mi.Color3f:
        """The network on an input list (``None`` entries are zeros): ``f_r``, clamped at 0."""
        h = x
        for k, (W, b) in enumerate(self._layers):
            out = []
            for o in range(len(b)):
                acc = b[o]
                for i, h_i in enumerate(h):
                    if h_i is not None:
                        acc = dr.fma(h_i, W[i][o], acc)
                out.append(acc)
            h = [dr.maximum(v, 0.0) for v in out] if k < len(self._layers) - 1 else out
        rgb = [dr.maximum(dr.exp(dr.minimum(v, EXP_ARGUMENT_MAX)) - 1.0, 0.0) for v in h]
        return mi.Color3f(rgb[0], rgb[1], rgb[2])

    def eval(self, view: mi.Vector3f, light: mi.Vector3f) -> mi.Color3f:
        """``f_r(light, view)``, zero at or below the horizon."""
        f = self.eval_input(network_input(view, light))
        above = (view.z > 0) & (light.z > 0)
        return dr.select(above, f, 0.0)


def _expm1_nonpositive(x):
    """exp(x) - 1 for x <= 0 without the cancellation of exp near 0."""
    small = dr.abs(x) < 1e-3
    series = x * dr.fma(x, dr.fma(x, 1.0 / 6.0, 0.5), 1.0)
    return dr.select(small, series, dr.exp(x) - 1.0)


def _cos_power(cos_theta, exponent):
    """cos^n as exp(n ln cos), with n = 0 -> 1 and cos <= 0 -> 0 (never NaN)."""
    positive = cos_theta > 0
    value = dr.exp(exponent * dr.log(dr.select(positive, dr.minimum(cos_theta, 1.0), 1.0)))
    value = dr.select(positive, value, 0.0)
    return dr.select(exponent == 0, 1.0, value)


def _spherical(cos_theta, sin_theta, u):
    sin_phi, cos_phi = dr.sincos(2.0 * math.pi * u)
    return mi.Vector3f(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta)


def uniform_hemisphere(u1, u2) -> mi.Vector3f:
    """Same warp as ``sampling::uniform_hemisphere``: ``cos theta = u1``."""
    z = dr.clip(u1, 0.0, 1.0)
    return _spherical(z, dr.safe_sqrt((1.0 - z) * (1.0 + z)), u2)


def cosine_hemisphere(u1, u2) -> mi.Vector3f:
    """Same warp as ``sampling::cosine_hemisphere``: ``sin theta = sqrt(u1)``."""
    u1 = dr.clip(u1, 0.0, 1.0)
    return _spherical(dr.safe_sqrt(1.0 - u1), dr.safe_sqrt(u1), u2)


def blinn_phong_half_vector(exponent, u1, u2) -> mi.Vector3f:
    """``cos theta_h = u1^(1/(n+1))``; ``1 - cos`` from expm1 keeps sharp lobes' spread."""
    u1 = dr.clip(u1, 0.0, 1.0)
    positive = u1 > 0
    log_u1 = dr.log(dr.select(positive, u1, 1.0))
    one_minus_cos = dr.select(positive, -_expm1_nonpositive(log_u1 / (exponent + 1.0)), 1.0)
    one_minus_cos = dr.clip(one_minus_cos, 0.0, 1.0)
    cos_theta = 1.0 - one_minus_cos
    return _spherical(cos_theta, dr.safe_sqrt(one_minus_cos * (1.0 + cos_theta)), u2)


def _unit(v: mi.Vector3f):
    """Unit vector and whether ``v`` had one (zero, infinite and NaN vectors give zero)."""
    length2 = dr.squared_norm(v)
    usable = (length2 > 0) & (length2 < float("inf"))
    return dr.select(usable, v * dr.rsqrt(length2), 0.0), usable


def mixture_pdf(view: mi.Vector3f, light: mi.Vector3f, exponent, specular_weight):
    """The Blinn-Phong mixture pdf per unit solid angle of ``light`` (DESIGN.md section 6),
    zero unless both directions are above the horizon."""
    v, v_ok = _unit(view)
    l, l_ok = _unit(light)
    h, h_ok = _unit(v + l)
    v_dot_h = dr.abs(dr.dot(v, h))
    lobe = (exponent + 1.0) * (0.5 / math.pi) * _cos_power(dr.abs(h.z), exponent)
    specular = dr.select(h_ok & (v_dot_h > 0), lobe / (4.0 * v_dot_h), 0.0)
    specular = dr.select(specular_weight > 0, specular_weight * specular, 0.0)
    pdf = specular + (1.0 - specular_weight) * dr.maximum(l.z, 0.0) / math.pi
    return dr.select(v_ok & l_ok & (v.z > 0) & (l.z > 0), pdf, 0.0)


STRATEGIES = ("uniform", "cosine", "phong")


def pdf(strategy: str, view, light, exponent=0.0, specular_weight=0.0):
    """Density of ``light`` given ``view`` for a strategy of ``STRATEGIES``."""
    if strategy == "phong":
        return mixture_pdf(view, light, exponent, specular_weight)
    v, v_ok = _unit(view)
    l, l_ok = _unit(light)
    density = 0.5 / math.pi if strategy == "uniform" else l.z / math.pi
    return dr.select(v_ok & l_ok & (v.z > 0) & (l.z > 0), density, 0.0)


def sample(strategy: str, view, u0, u1, u2, exponent=0.0, specular_weight=0.0):
    """Draws a light direction like ``SamplingStrategy::sample``: ``(light, pdf)`` with pdf 0
    for invalid samples (a specular reflection below the horizon, a view below it)."""
    if strategy == "uniform":
        light = uniform_hemisphere(u1, u2)
    elif strategy == "cosine":
        light = cosine_hemisphere(u1, u2)
    elif strategy == "phong":
        v, _ = _unit(view)
        h = blinn_phong_half_vector(exponent, u1, u2)
        reflected = 2.0 * dr.dot(v, h) * h - v
        specular = (u0 < specular_weight) | (specular_weight >= 1.0)
        light = dr.select(specular, reflected, cosine_hemisphere(u1, u2))
    else:
        raise ValueError(f"unknown sampling strategy '{strategy}' (one of {', '.join(STRATEGIES)})")
    light, _ = _unit(light)
    return light, pdf(strategy, view, light, exponent, specular_weight)
