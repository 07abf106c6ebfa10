"""Spatially varying materials as Dr.Jit arithmetic (:class:`TracedTexturedMaterial`), the twin
of ``nbrdf-core/src/textured`` (docs/textured.md): the latent texture's lookup as Mitsuba's
``bitmap`` reads an image (:class:`TracedUvMapping`), the decoder (a :class:`TracedNetwork` on
the six direction features followed by the code) and the lobe channels' sampling strategy
(:func:`lobe_parameters`).

The texture is looked up with gathers rather than ``dr.Texture``: texel indices are wrapped
exactly for any finite UV (``dr.Texture`` converts positions to 32-bit integers, which overflow
far outside [0, 1]), and a non-finite texel must poison its footprint (``0 * NaN``), as in the
Rust code, so that the hit reads as a bad texel. Gathers are differentiable: gradients reach the
texture's values.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .._native import KIND
from .directions import both_valid_above
from .network import TracedNetwork, network_input
from .sampling import MAX_EXPONENT, pdf, sample

#: How far filtered lobe values may pass their range and still be clamped into it
#: (``textured/lobes.rs``, same name).
FILTER_SLACK = 1e-5
#: Wrap modes and filters (``textured/texture.rs`` ``WrapMode``, ``FilterMode``; Mitsuba's names).
WRAP_MODES = ("repeat", "mirror", "clamp")
FILTER_MODES = ("bilinear", "nearest")
# Steps of _rem_euclid: each divides the magnitude by 2^23 at least, from float32's 2^128.
_REDUCTION_STEPS = 5
# Below this a float64 holds base + 1 exactly; above, texture.rs's f64 sum rounds back to base.
_F64_EXACT = 2.0**53
# From here on texture.rs's float64 sum coord * size - 1/2 rounds back to the product.
_F64_HALF_LOST = 2.0**52


def _rem_euclid(x, m: int):
    """``x mod m`` in ``[0, m)`` (an Int32) of a float32 integer ``x`` of any finite size and an
    integer ``0 < m <= 2^15``, exactly, as ``f64::rem_euclid`` in ``texture.rs``.

    Each step ``r - floor(r / m) m`` is one fused multiply-add whose exact result is an integer
    at most ``2^16`` times the coarser of the two operands' spacings, so float32 holds it and
    the step is exact; five steps bring any float32 below ``2^24``, where an integer remainder
    finishes."""
    r = x
    for _ in range(_REDUCTION_STEPS):
        r = dr.fma(-dr.floor(r / m), m, r)
    i = mi.Int32(r) % m
    return dr.select(i < 0, i + m, i)


def _wrap_pair(base, size: int, mode: str):
    """Texel indices (UInt32) of ``base`` and ``base + 1`` (``base`` a finite float32 integer)
    wrapped into ``[0, size)`` (``WrapMode::wrap``): the second as ``texture.rs`` adds 1 in
    float64, where beyond 2^53 the sum rounds back to ``base``."""
    if mode == "clamp":
        return (mi.UInt32(dr.clip(base, 0.0, size - 1.0)), mi.UInt32(dr.clip(base + 1.0, 0.0, size - 1.0)))
    period = size if mode == "repeat" else 2 * size
    r0 = _rem_euclid(base, period)
    r1 = dr.select(dr.abs(base) < _F64_EXACT, r0 + 1, r0)
    r1 = dr.select(r1 >= period, r1 - period, r1)
    if mode == "mirror":
        r0 = dr.select(r0 < size, r0, 2 * size - 1 - r0)
        r1 = dr.select(r1 < size, r1, 2 * size - 1 - r1)
    return mi.UInt32(r0), mi.UInt32(r1)


class Footprint:
    """The texels a lookup reads (indices ``y width + x``, UInt32), their weights, and whether
    the mapped position was finite (``valid``; where it is not, the hit reads no texel)."""

    def __init__(self, texels: list, weights: list, valid):
        self.texels, self.weights, self.valid = texels, weights, valid


class TracedUvMapping:
    """``UvMapping`` of ``texture.rs``: ``to_uv`` (3 x 3 rows of float32), the wrap mode and the
    filter of a ``width x height`` texture, as Mitsuba's ``bitmap`` texture reads an image."""

    def __init__(self, width: int, height: int, wrap: str = "repeat", filter: str = "bilinear", to_uv=None):
        if wrap not in WRAP_MODES or filter not in FILTER_MODES:
            raise ValueError(f"wrap {wrap!r} or filter {filter!r} unknown (expected one of {WRAP_MODES}, {FILTER_MODES})")
        self.width, self.height, self.wrap, self.filter = int(width), int(height), wrap, filter
        rows = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] if to_uv is None else to_uv[:2]
        #: The first two rows, each entry rounded to float32 as the Rust reader does.
        self.to_uv = [[float(np.float32(x)) for x in row] for row in rows]

    def _axis(self, coord, size: int):
        """``UvMapping::axis``: the two texel indices along one axis, the upper one's weight, and
        whether the position is finite. The position ``coord size - 1/2`` (bilinear) is rounded
        to float32 once, as texture.rs sums it in float64, where from 2^52 on the half is lost
        and the position is the rounded product (nearest: the rounded product)."""
        position = coord * size
        if self.filter == "bilinear":
            half_lost = dr.abs(mi.Float64(coord) * size) >= _F64_HALF_LOST
            position = dr.select(half_lost, position, dr.fma(coord, size, -0.5))
        finite = dr.isfinite(position)
        position = dr.select(finite, position, 0.0)
        base = dr.floor(position)
        i0, i1 = _wrap_pair(base, size, self.wrap)
        return i0, i1, position - base, finite

    def footprint(self, uv) -> Footprint:
        """``UvMapping::footprint`` of the hit coordinates ``uv`` (``mi.Point2f``): one texel of
        weight 1 (nearest) or four, in Dr.Jit's corner order."""
        (a, b, c), (d, e, f) = self.to_uv
        u = a * uv.x + b * uv.y + c
        v = d * uv.x + e * uv.y + f
        x0, x1, wx1, fx = self._axis(u, self.width)
        y0, y1, wy1, fy = self._axis(v, self.height)
        # A non-finite coordinate makes both rows non-finite in float32 (0 * inf is NaN), which
        # Dr.Jit's folding of products with a literal 0 would hide.
        valid = fx & fy & dr.isfinite(uv.x) & dr.isfinite(uv.y)
        if self.filter == "nearest":
            return Footprint([y0 * self.width + x0], [mi.Float(1.0)], valid)
        wx0, wy0 = 1.0 - wx1, 1.0 - wy1
        texels = [y0 * self.width + x0, y0 * self.width + x1, y1 * self.width + x0, y1 * self.width + x1]
        return Footprint(texels, [wx0 * wy0, wx1 * wy0, wx0 * wy1, wx1 * wy1], valid)


def filter_channels(values, channels: int, footprint: Footprint, fused: bool) -> list:
    """``LatentTexture::filter_into``: each of the ``channels`` channels of the texel-major flat
    array ``values`` summed over the footprint in corner order, ``sum_t w_t c_t``; ``fused``
    rounds each term's product and sum once (the Rust kernel on FMA CPUs, as for the code),
    else twice (the portable arithmetic of the lobes). A non-finite texel in the footprint
    makes the channel non-finite."""
    out = [mi.Float(0.0) for _ in range(channels)]
    for texel, weight in zip(footprint.texels, footprint.weights):
        for k in range(channels):
            c = dr.gather(mi.Float, values, texel * channels + k, footprint.valid)
            out[k] = dr.fma(c, weight, out[k]) if fused else c * weight + out[k]
    return out


def _within(x, low: float, high: float):
    """``lobes.rs`` ``within``: whether ``x`` lies within :data:`FILTER_SLACK` of ``[low, high]``
    (false for NaN), and ``x`` clamped into it; in float64, as the Rust code."""
    x = mi.Float64(x)
    slack = FILTER_SLACK * (high - low)
    return (x >= low - slack) & (x <= high + slack), dr.clip(x, low, high)


def lobe_parameters(values: list, valid):
    """``lobes.rs`` ``strategy_of``: the Blinn-Phong mixture ``(n1, w1, n2, w2)`` of filtered lobe
    values in texture order (``[n, w]`` or ``[n1, w1, n2, w2]``, exponents as ``ln(1 + n)``),
    where ``valid``; the cosine lobe (zeros) without lobes, elsewhere, and where a value is out
    of range beyond :data:`FILTER_SLACK` or not finite. One lobe is the two-lobe mixture with a
    second of weight 0, which samples and weighs exactly as the one-lobe mixture."""
    zero = mi.Float(0.0)
    if not values:
        return zero, zero, zero, zero
    good = mi.Bool(valid)
    lobes = []
    for k in range(len(values) // 2):
        code_ok, code = _within(values[2 * k], 0.0, math.log1p(MAX_EXPONENT))
        weight_ok, weight = _within(values[2 * k + 1], 0.0, 1.0)
        good &= code_ok & weight_ok
        lobes.append([dr.minimum(dr.exp(code) - 1.0, MAX_EXPONENT), weight])
    if len(lobes) == 2:
        total = lobes[0][1] + lobes[1][1]
        sum_ok, clamped = _within(total, 0.0, 1.0)
        good &= sum_ok
        scale = dr.select(total > 1.0, clamped / dr.select(total > 0.0, total, 1.0), 1.0)
        for lobe in lobes:
            lobe[1] = lobe[1] * scale
    else:
        lobes.append([0.0, 0.0])
    (n1, w1), (n2, w2) = lobes
    return tuple(dr.select(good, mi.Float(p), 0.0) for p in (n1, w1, n2, w2))


class TracedTexturedMaterial:
    """A spatially varying material (``TexturedNbrdf``) as Dr.Jit arithmetic: the ``decoder``
    (a :class:`TracedNetwork` of ``6 + channels`` inputs), the ``mapping``, and the texture's
    values, read at trace time from ``latent()`` (a ``mi.TensorXf`` of ``height x width x
    channels``) and ``lobe_values()`` (``height x width x 2 lobes``, or None), so that updates
    and gradients reach them."""

    def __init__(self, decoder: TracedNetwork, mapping: TracedUvMapping, channels: int, lobes: int, latent,
                 lobe_values):
        self.decoder, self.mapping = decoder, mapping
        self.channels, self.lobes = int(channels), int(lobes)
        self.latent, self.lobe_values = latent, lobe_values

    def code(self, uv):
        """The latent code at the hits (a list of ``channels`` Floats, 0 at bad texels) and
        whether the hit is good (a finite position and code)."""
        footprint = self.mapping.footprint(uv)
        code = filter_channels(self.latent().array, self.channels, footprint, fused=True)
        good = footprint.valid
        for c in code:
            good &= dr.isfinite(c)
        return [dr.select(good, c, 0.0) for c in code], good

    def eval(self, uv, view, light):
        """``f_r`` at the hits, a ``mi.Color3f`` or a spectral decoder's list of coefficients: 0
        at bad texels, at or below the horizon and for zero or non-finite directions
        (``TexturedNbrdf::eval_cos`` without the cosine)."""
        code, good = self.code(uv)
        f = self.decoder.eval_input(network_input(view, light, self.decoder.anisotropic) + code)
        ok = good & both_valid_above(view, light)
        return [dr.select(ok, c, 0.0) for c in f] if isinstance(f, list) else dr.select(ok, f, 0.0)

    def strategy(self, uv):
        """``TexturedNbrdf::sampling_strategy``: the mixture ``(n1, w1, n2, w2)`` at the hits."""
        if not self.lobes:
            return lobe_parameters([], True)
        footprint = self.mapping.footprint(uv)
        values = filter_channels(self.lobe_values().array, 2 * self.lobes, footprint, fused=False)
        return lobe_parameters(values, footprint.valid)

    def sample(self, uv, view, u0, u1, u2):
        """``TexturedNbrdf::sample``: a light direction and its pdf (0 for invalid samples)."""
        return sample(KIND.two_lobe, view, u0, u1, u2, *self.strategy(uv))

    def pdf(self, uv, view, light):
        """``TexturedNbrdf::pdf``: the density of :meth:`sample` per unit solid angle of ``light``."""
        return pdf(KIND.two_lobe, view, light, *self.strategy(uv))
