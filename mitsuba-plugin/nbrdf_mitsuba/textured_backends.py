"""The two backends of a spatially varying ``nbrdf`` BSDF (docs/textured.md), with Mitsuba's
``eval``, ``pdf``, ``eval_pdf`` and ``sample``, each at the hit's texture coordinates
``si.uv``; they follow :mod:`nbrdf_mitsuba.backends` (which see for wavefronts, symbolic scopes
and the variants' spectra):

* :class:`TexturedJitBackend` (``jit``): the traced twin
  (:class:`nbrdf_mitsuba.jit.textured.TracedTexturedMaterial`) in Mitsuba's own kernels;
* :class:`TexturedRustBackend` (``rust``, the reference): the library at texture coordinates
  (``nbrdf_material_eval_uv``, ``nbrdf_material_sample_uv``). Its pdf comes with an evaluation
  (the C ABI has no pdf-only call at texture coordinates).

An RGB decoder's value goes to the variant as ``backends._to_spectrum`` says (monochrome variants
take its luminance, spectral ones uplift it, polarized ones get the depolarizer). A spectral
decoder (a file with a ``spectral`` object) gives B-spline coefficients, evaluated at the lane's
wavelengths in spectral and polarized variants and projected to linear sRGB (``M c``) in RGB
variants, its luminance in monochrome ones, as for spectral networks
(``JitBackend._spectral_spectrum``, ``RustBackend._spectral_value``).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from . import jit
from .backends import JitBackend, RustBackend, _both_above, _glossy, _to_spectrum, _width


def _glossy_sample(bs):
    """``bs`` marked as a sample of the one glossy reflection component."""
    bs.eta = 1.0
    bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
    bs.sampled_component = mi.UInt32(0)
    return bs


class TexturedJitBackend(JitBackend):
    """The traced material ``traced`` (a ``TracedTexturedMaterial``) in Mitsuba's kernels;
    ``spectral``: a spectral material's ``(count, min_nm, max_nm, M)``, else None."""

    def __init__(self, traced, spectral=None):
        JitBackend.__init__(self, traced, spectral, None)

    def use(self, sampler, lobes) -> None:
        """Nothing to take: the lobes come from the texture."""

    def sample(self, ctx, si, sample1, sample2, active=True):
        if _width(si.wi, sample1, sample2) == 0:
            return dr.zeros(mi.BSDFSample3f, 0), dr.zeros(mi.Spectrum, 0)
        bs = _glossy_sample(dr.zeros(mi.BSDFSample3f))
        light, pdf = self.traced.sample(si.uv, si.wi, sample1, sample2.x, sample2.y)
        active = active & _glossy(ctx) & (mi.Frame3f.cos_theta(si.wi) > 0) & (pdf > 0)
        bs.wo = light
        bs.pdf = dr.select(active, pdf, 0.0)
        f = self.traced.eval(si.uv, si.wi, light)
        scale = jit.cos_theta(light) / dr.select(active, pdf, 1.0)
        if self.spectral is not None:
            return bs, self._spectral_spectrum(f, scale, active, si)
        weight = f * scale
        # As sampling/mod.rs sample_weight: 0 where a tiny pdf would overflow the quotient.
        weight = dr.select(active & dr.all(dr.isfinite(weight)), weight, 0.0)
        return bs, _to_spectrum(weight, si)

    def _eval(self, si, wo, active):
        f = self.traced.eval(si.uv, si.wi, wo)
        if self.spectral is not None:
            return self._spectral_spectrum(f, jit.cos_theta(wo), _both_above(active, si.wi, wo), si)
        return _to_spectrum(dr.select(_both_above(active, si.wi, wo), f * jit.cos_theta(wo), 0.0), si)

    def _pdf(self, si, wo, active):
        return dr.select(_both_above(active, si.wi, wo), self.traced.pdf(si.uv, si.wi, wo), 0.0)


class TexturedRustBackend(RustBackend):
    """The library's textured material ``native`` (a ``_native.Material`` of kind ``textured``,
    with ``spectral`` as :class:`TexturedJitBackend`'s) on planar arrays made by ``arrays``;
    inside symbolic scopes its ``twin`` (a :class:`TexturedJitBackend`), as
    :class:`nbrdf_mitsuba.backends.RustBackend`."""

    def use(self, sampler, lobes) -> None:
        """Nothing to take: the library samples the lobes its texture stores."""

    def eval(self, ctx, si, wo, active=True):
        if self._in_symbolic_scope(si.wi, wo):
            return self.twin.eval(ctx, si, wo, active)
        if not self._enabled(ctx, si.wi, wo):
            return self.arrays.zero_spectrum(self.arrays.width(si.wi, wo))
        hits = self._hits(si, wo)
        active = _both_above(active, si.wi, wo)
        if self._per_wavelength():
            return self._spectral_value(hits[1], hits[2], active, si, uv=hits[0])
        value, _ = self.native.eval_uv(*hits, pdf=False)
        return self._value(value, active, si)

    def pdf(self, ctx, si, wo, active=True):
        if self._in_symbolic_scope(si.wi, wo):
            return self.twin.pdf(ctx, si, wo, active)
        if not self._enabled(ctx, si.wi, wo):
            return dr.zeros(mi.Float, self.arrays.width(si.wi, wo))
        _, pdf = self.native.eval_uv(*self._hits(si, wo))
        return dr.select(_both_above(active, si.wi, wo), self.arrays.float_(pdf), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        if self._in_symbolic_scope(si.wi, wo):
            return self.twin.eval_pdf(ctx, si, wo, active)
        if not self._enabled(ctx, si.wi, wo):
            n = self.arrays.width(si.wi, wo)
            return self.arrays.zero_spectrum(n), dr.zeros(mi.Float, n)
        hits = self._hits(si, wo)
        value, pdf = self.native.eval_uv(*hits)
        active = _both_above(active, si.wi, wo)
        if self._per_wavelength():
            value = self._spectral_value(hits[1], hits[2], active, si, uv=hits[0])
        else:
            value = self._value(value, active, si)
        return value, dr.select(active, self.arrays.float_(pdf), 0.0)

    def sample(self, ctx, si, sample1, sample2, active=True):
        if self._in_symbolic_scope(si.wi, sample1, sample2):
            return self.twin.sample(ctx, si, sample1, sample2, active)
        arrays = self.arrays
        n = arrays.width(si.wi, sample1, sample2)
        if not self._enabled(ctx, si.wi, sample1, sample2):
            return arrays.empty_sample(n), arrays.zero_spectrum(n)
        bs = _glossy_sample(arrays.empty_sample(n))
        arrays.evaluate(si.uv, si.wi, sample1, sample2)
        uv = arrays.planar([si.uv.x, si.uv.y], n)
        view = arrays.planar([si.wi.x, si.wi.y, si.wi.z], n)
        u = arrays.planar([sample1, sample2.x, sample2.y], n)
        light, weight, pdf = self.native.sample_uv(uv, view, u)
        bs.wo = arrays.vector(light)
        bs.pdf = arrays.float_(pdf)
        active = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (bs.pdf > 0)
        bs.pdf = dr.select(active, bs.pdf, 0.0)
        if self._per_wavelength():
            # The library's weight is RGB: the spectrum is evaluated again at the sampled
            # direction and the lane's wavelengths.
            return bs, self._spectral_value(view, light, active, si, pdf, uv)
        return bs, self._value(weight, active, si)

    def _per_wavelength(self) -> bool:
        """Whether values are evaluated per wavelength: a spectral material in a spectral variant."""
        return self.spectral is not None and mi.is_spectral

    def _hits(self, si, wo):
        """Planar float32 copies of the UVs (2, n), views and lights (3, n)."""
        n = self.arrays.width(si.wi, wo)
        self.arrays.evaluate(si.uv, si.wi, wo)  # one kernel for all
        planar = self.arrays.planar
        return (planar([si.uv.x, si.uv.y], n), planar([si.wi.x, si.wi.y, si.wi.z], n),
                planar([wo.x, wo.y, wo.z], n))

    def _value(self, rgb, active, si):
        """The library's planar RGB as the variant's spectrum, 0 where not ``active``."""
        return _to_spectrum(dr.select(active, self.arrays.color(rgb), 0.0), si)
