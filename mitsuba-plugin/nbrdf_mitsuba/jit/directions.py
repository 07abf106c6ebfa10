"""Unit directions as the Rust core makes them: total functions, zero and non-finite vectors
handled without NaN (``network/kernel.rs`` ``rescale_out_of_range``, ``coords.rs``)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi


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


def unit(v: mi.Vector3f):
    """Unit vector and whether ``v`` had one (zero, infinite and NaN vectors give zero)."""
    x, y, z, ok = unit_vector(v.x, v.y, v.z)
    return mi.Vector3f(x, y, z), ok


def unit_or_normal(x, y, z):
    """Unit vector, or the normal +z for zero, infinite or NaN input (as the Rust core)."""
    x, y, z, usable = unit_vector(x, y, z)
    return dr.select(usable, x, 0.0), dr.select(usable, y, 0.0), dr.select(usable, z, 1.0)


def cos_theta(v: mi.Vector3f):
    """``brdf.rs`` ``cos_theta_light``: ``z / |v|``, 0 for zero and non-finite vectors."""
    _, _, z, ok = unit_vector(v.x, v.y, v.z)
    return dr.select(ok, dr.maximum(z, 0.0), 0.0)


def both_valid_above(view, light):
    """Whether both directions exist and lie above the horizon."""
    *_, vz, v_ok = unit_vector(view.x, view.y, view.z)
    *_, lz, l_ok = unit_vector(light.x, light.y, light.z)
    return v_ok & l_ok & (vz > 0) & (lz > 0)
