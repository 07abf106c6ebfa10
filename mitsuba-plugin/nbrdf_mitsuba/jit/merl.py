"""The MERL table lookup as Dr.Jit arithmetic (:class:`TracedMerl`), the twin of
``nbrdf-core/src/merl``."""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .directions import both_valid_above
from .network import network_input

# The MERL grid (docs/design.md section 3): merl/grid.rs, same names (tests/test_shared_constants.py).
N_THETA_H, N_THETA_D, N_PHI_D = 90, 90, 180
#: Stored value times scale = reflectance, per channel (``merl/grid.rs``, same name).
SCALE = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)


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
        reflectance = stored * np.asarray(SCALE)[:, None]
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
        return dr.select(both_valid_above(view, light), f, 0.0)
