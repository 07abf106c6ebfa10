"""The output stage of spectral variants as Dr.Jit arithmetic: an RGB value as a spectrum
(Mitsuba's RGB-to-spectrum model, looked up per lane: :class:`SrgbModel`,
:func:`spectrum_from_rgb`), and a spectral network's B-spline coefficients as a value per
wavelength (:func:`spectral_value`) or as linear sRGB (:func:`srgb_projection`)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

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
