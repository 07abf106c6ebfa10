"""Twins of ``nbrdf-core/src/fastmath.rs``: ReLU, the exp argument clamp and ``exp(x) - 1``."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: The exp argument range of ``fastmath.rs`` (same names; tests/test_shared_constants.py): e^80
#: ~ 5.5e34 stays far below float32's maximum, and below -87 the result is -1 to float32 precision.
EXP_ARG_MAX = 80.0
EXP_ARG_MIN = -87.0
#: Cody-Waite split of ln 2 and log2(e) of ``fastmath.rs``.
LN2_HI = 355.0 / 512.0
LN2_LO = -2.1219444e-4
LOG2_E = 1.4426950408889634


def relu(v):
    """``max(v, 0)`` with NaN -> 0 (``fastmath.rs`` ``relu``: ``if v > 0 { v } else { 0 }``)."""
    return dr.select(v > 0, v, 0.0)


def clamp_exp_argument(z):
    """``fastmath.rs`` ``clamp_exp_arg``: into ``[EXP_ARG_MIN, EXP_ARG_MAX]``, NaN to the lower
    end (compare-selects, not min/max, whose NaN handling is backend-specific)."""
    z = dr.select(z > EXP_ARG_MIN, z, EXP_ARG_MIN)
    return dr.select(z < EXP_ARG_MAX, z, EXP_ARG_MAX)


def expm1(x):
    """exp(x) - 1 with full relative precision near 0 (most of a BRDF's domain holds small
    reflectances, where exp(x) - 1 cancels), for x in [EXP_ARG_MIN, EXP_ARG_MAX].

    Twin of ``fastmath.rs`` ``expm1_with`` (held together by tests/test_backends.py): ``x = k ln 2
    + r``, ``|r| <= ln 2 / 2``, ``expm1(x) = 2^k expm1(r) + (2^k - 1)`` with the degree-7 Taylor
    series of ``expm1(r)``; about 1e-7 relative error, and no exp or log, which as Dr.Jit's
    polynomials would cost about as much as the network's multiply-adds."""
    k = dr.round(x * LOG2_E)
    r = dr.fma(-k, LN2_LO, dr.fma(-k, LN2_HI, x))
    scale = dr.reinterpret_array(mi.Float, (mi.Int32(k) + 127) << 23)
    p = mi.Float(1.0 / 5040.0)
    for c in (1.0 / 720.0, 1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 0.5):
        p = dr.fma(p, r, c)
    return dr.fma(scale, dr.fma(p * r, r, r), scale - 1.0)
