"""The sampling strategies as Dr.Jit arithmetic: each strategy's sampler next to its pdf, then
:func:`sample` and :func:`pdf`, which pick one by name (``SamplingStrategy::sample`` and
``density`` of ``nbrdf-core/src/sampling``).

Sharp lobes: ``1 - cos(theta_h)`` is computed from ``|h_xy|^2`` (never as ``1 - h.z``, which
cancels in float32), so the pdf keeps its accuracy up to :data:`MAX_EXPONENT`.
"""

from __future__ import annotations

import math
from typing import NamedTuple
from collections.abc import Callable

import drjit as dr
import mitsuba as mi
import numpy as np

from .._native import KIND, SAMPLING_KINDS
from .directions import unit
from .fastmath import clamp_exp_argument, expm1

#: The largest Blinn-Phong exponent the plugins accept (``sampling/mod.rs``, same name;
#: docs/design.md promises stable sampling up to there; beyond it float32 directions cannot
#: resolve the lobe and the backends would disagree).
MAX_EXPONENT = 1e6

# --------------------------------------------------------------------------------------------
# Shared by the strategies


def unit_interval(u):
    """``sampling/mod.rs`` ``unit_interval``: clamped into [0, 1], NaN -> 0."""
    return dr.select(u >= 0, dr.minimum(u, 1.0), 0.0)


def _spherical(cos_theta, sin_theta, u):
    sin_phi, cos_phi = dr.sincos(2.0 * math.pi * u)
    return mi.Vector3f(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta)


def _reflected(view, h):
    v, _ = unit(view)
    return 2.0 * dr.dot(v, h) * h - v


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


def _phong_elevation(exponent, u):
    """``(cos theta, sin theta)`` with ``cos theta = u^(1/(n+1))``; ``1 - cos`` from expm1 keeps
    sharp lobes' spread."""
    u = dr.clip(u, 0.0, 1.0)
    positive = u > 0
    log_u = dr.log(dr.select(positive, u, 1.0))
    # The network's expm1 (exact near 0); below EXP_ARG_MIN, 1 - cos rounds to 1 anyway.
    one_minus_cos = dr.select(positive, -expm1(clamp_exp_argument(log_u / (exponent + 1.0))), 1.0)
    one_minus_cos = dr.clip(one_minus_cos, 0.0, 1.0)
    cos_theta = 1.0 - one_minus_cos
    return cos_theta, dr.safe_sqrt(one_minus_cos * (1.0 + cos_theta))



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


def _isotropic_pdf(density):
    """The pdf of a view-independent density of ``l`` (0 off the upper hemisphere)."""
    def pdf_(view, light, params, table):
        v, v_ok = unit(view)
        l, l_ok = unit(light)
        return dr.select(v_ok & l_ok & (v.z > 0) & (l.z > 0), density(l), 0.0)
    return pdf_


# --------------------------------------------------------------------------------------------
# uniform


def uniform_hemisphere(u1, u2) -> mi.Vector3f:
    """Same warp as ``sampling::uniform_hemisphere``: ``cos theta = u1``."""
    z = dr.clip(u1, 0.0, 1.0)
    return _spherical(z, dr.safe_sqrt((1.0 - z) * (1.0 + z)), u2)


def _sample_uniform(view, u0, u1, u2, p, table):
    return uniform_hemisphere(u1, u2)


_pdf_uniform = _isotropic_pdf(lambda l: 0.5 / math.pi)

# --------------------------------------------------------------------------------------------
# cosine


def cosine_hemisphere(u1, u2) -> mi.Vector3f:
    """Same warp as ``sampling::cosine_hemisphere``: ``sin theta = sqrt(u1)``."""
    u1 = dr.clip(u1, 0.0, 1.0)
    return _spherical(dr.safe_sqrt(1.0 - u1), dr.safe_sqrt(u1), u2)


def _sample_cosine(view, u0, u1, u2, p, table):
    return cosine_hemisphere(u1, u2)


_pdf_cosine = _isotropic_pdf(lambda l: l.z / math.pi)

# --------------------------------------------------------------------------------------------
# phong: one Blinn-Phong lobe mixed with cosine


def phong_half_vector(exponent, u1, u2) -> mi.Vector3f:
    """``cos theta_h = u1^(1/(n+1))``, the azimuth ``2 pi u2``."""
    return _spherical(*_phong_elevation(exponent, u1), u2)


def _sample_phong(view, u0, u1, u2, p, table):
    specular = (u0 < p[1]) | (p[1] >= 1.0)
    return dr.select(specular, _reflected(view, phong_half_vector(p[0], u1, u2)), cosine_hemisphere(u1, u2))


def mixture_pdf(view: mi.Vector3f, light: mi.Vector3f, exponent, specular_weight):
    """The Blinn-Phong mixture pdf per unit solid angle of ``light`` (docs/design.md section 6),
    zero unless both directions are above the horizon."""
    v, v_ok = unit(view)
    l, l_ok = unit(light)
    one_minus_cos, v_dot_h, h_ok = _half_vector_terms(view, light)
    lobe = (exponent + 1.0) * (0.5 / math.pi) * _cos_power_from_one_minus(one_minus_cos, exponent)
    specular = dr.select(h_ok & (v_dot_h > 0), lobe / (4.0 * v_dot_h), 0.0)
    specular = dr.select(specular_weight > 0, specular_weight * specular, 0.0)
    pdf = specular + (1.0 - specular_weight) * dr.maximum(l.z, 0.0) / math.pi
    return dr.select(v_ok & l_ok & (v.z > 0) & (l.z > 0), pdf, 0.0)


def _pdf_phong(view, light, p, table):
    return mixture_pdf(view, light, p[0], p[1])


# --------------------------------------------------------------------------------------------
# two_lobe: two Blinn-Phong lobes mixed with cosine


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


def two_lobe_pdf(view: mi.Vector3f, light: mi.Vector3f, exponent, specular_weight, exponent2,
                 specular_weight2):
    """``w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine`` per unit solid angle of ``light``
    (``sampling/two_lobe.rs`` ``density``; the cosine weight clamped at 0), zero unless
    both directions are above the horizon."""
    v, v_ok = unit(view)
    l, l_ok = unit(light)
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


def _pdf_two_lobe(view, light, p, table):
    return two_lobe_pdf(view, light, *p)


# --------------------------------------------------------------------------------------------
# anisotropic_phong: an Ashikhmin-Shirley lobe (n_u along the tangent x, n_v across) mixed with
# cosine


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


def _sample_anisotropic(view, u0, u1, u2, p, table):
    specular = (u0 < p[1]) | (p[1] >= 1.0)
    h = anisotropic_half_vector(p[0], p[2], u1, u2)
    return dr.select(specular, _reflected(view, h), cosine_hemisphere(u1, u2))


def anisotropic_pdf(view: mi.Vector3f, light: mi.Vector3f, exponent_u, specular_weight, exponent_v):
    """The anisotropic Blinn-Phong mixture (Ashikhmin-Shirley half-vector density, ``n_u`` along
    the tangent x, ``n_v`` across) per unit solid angle of ``light``, zero unless both directions
    are above the horizon (``sampling/anisotropic.rs`` ``density``)."""
    v, v_ok = unit(view)
    l, l_ok = unit(light)
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


def _pdf_anisotropic(view, light, p, table):
    return anisotropic_pdf(view, light, p[0], p[1], p[2])


# --------------------------------------------------------------------------------------------
# tabulated: a half-vector table built from the material, mixed with cosine


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
        v, v_ok = unit(view)
        l, l_ok = unit(light)
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


def _sample_tabulated(view, u0, u1, u2, p, table):
    return table.sample_direction(unit(view)[0], u0, u1, u2)


def _pdf_tabulated(view, light, p, table):
    return table.pdf(view, light)


# --------------------------------------------------------------------------------------------
# Every strategy by name


class Strategy(NamedTuple):
    """A strategy's traced sampler ``sample(view, u0, u1, u2, params, table)`` (a direction) and
    density ``pdf(view, light, params, table)``; ``params`` are (exponent, specular_weight,
    exponent2, specular_weight2)."""

    sample: Callable
    pdf: Callable


_STRATEGIES = {
    KIND.uniform: Strategy(_sample_uniform, _pdf_uniform),
    KIND.cosine: Strategy(_sample_cosine, _pdf_cosine),
    KIND.phong: Strategy(_sample_phong, _pdf_phong),
    KIND.two_lobe: Strategy(_sample_two_lobe, _pdf_two_lobe),
    KIND.anisotropic_phong: Strategy(_sample_anisotropic, _pdf_anisotropic),
    KIND.tabulated: Strategy(_sample_tabulated, _pdf_tabulated),
}
#: Every strategy of the library, each with a traced pdf and sampler.
STRATEGIES = tuple(SAMPLING_KINDS)
if set(_STRATEGIES) != set(STRATEGIES):
    raise ImportError(f"nbrdf_mitsuba.jit: the traced strategies {sorted(_STRATEGIES)} are not the library's "
                      f"{sorted(STRATEGIES)}")


def _strategy(strategy: str) -> Strategy:
    try:
        return _STRATEGIES[strategy]
    except KeyError:
        raise ValueError(f"unknown sampling strategy '{strategy}' (one of {', '.join(STRATEGIES)})") from None


def pdf(strategy: str, view, light, exponent=0.0, specular_weight=0.0, exponent2=0.0,
        specular_weight2=0.0, table: TracedTable | None = None):
    """Density of ``light`` given ``view`` for a strategy of ``STRATEGIES`` (``tabulated``
    needs ``table``; ``exponent2`` is ``n_v`` for ``anisotropic_phong``)."""
    params = (exponent, specular_weight, exponent2, specular_weight2)
    return _strategy(strategy).pdf(view, light, params, table)


def sample(strategy: str, view, u0, u1, u2, exponent=0.0, specular_weight=0.0, exponent2=0.0,
           specular_weight2=0.0, table: TracedTable | None = None):
    """Draws a light direction like ``SamplingStrategy::sample``: ``(light, pdf)`` with pdf 0
    for invalid samples (a specular reflection below the horizon, a view below it)."""
    draw = _strategy(strategy).sample
    u0, u1, u2 = unit_interval(u0), unit_interval(u1), unit_interval(u2)
    params = (exponent, specular_weight, exponent2, specular_weight2)
    light = draw(view, u0, u1, u2, params, table)
    _, view_ok = unit(view)
    light, light_ok = unit(light)
    # As SamplingStrategy::sample: +z (with pdf 0) when there is no direction to return.
    light = dr.select(view_ok & light_ok, light, mi.Vector3f(0.0, 0.0, 1.0))
    return light, pdf(strategy, view, light, exponent, specular_weight, exponent2, specular_weight2, table)
