"""The Mitsuba BSDF plugins ``nbrdf`` (a neural BRDF, ``*.nbrdf.json``) and ``merl`` (a
MERL-format ``.binary`` table).

Mitsuba's ``BSDF`` base class differs per variant, so :func:`classes` builds the two plugin
classes for the current variant from the variant-independent mixins below. Every variant: RGB,
monochrome, spectral (the RGB value uplifted per wavelength as Mitsuba uplifts unbounded RGB data)
and polarized (see :func:`_to_spectrum`).

Two backends (parameter ``backend``):

* ``jit`` (default in JIT variants): the network, the table lookup and the Blinn-Phong mixture
  written as Dr.Jit arithmetic (:mod:`nbrdf_mitsuba.jit`), traced into Mitsuba's own kernels.
  Symbolic loops and calls stay on; it runs at Mitsuba's full speed, on LLVM and CUDA alike.
* ``rust`` (default in scalar variants, the reference): the native library evaluates whole
  wavefronts on the host. Directions are evaluated (``dr.eval``), copied to NumPy in Dr.Jit's
  planar (3, N) layout, handed to the library, and copied back. That cannot happen while Dr.Jit
  records a symbolic loop or call, so in JIT variants the library runs in wavefront mode on the
  thread that renders (see :func:`use_wavefront_mode`). Dr.Jit's flags are per thread, Mitsuba
  builds a scene's plugins on worker threads, and a symbolic call is traced through every live
  BSDF, so constructing a BSDF changes no flag; inside a symbolic scope a rust-backed BSDF
  evaluates its traced twin instead (logged once), on whichever thread. Outputs are not
  differentiable.

Parameter updates (``mi.traverse`` + ``params.update()``) are validated as a whole and applied
atomically: a rejected update raises, puts the previous values back into the traversed
parameters and leaves the BSDF in its last good state; later valid updates take effect.
Rejected: non-finite or negative exponents, exponents above ``MAX_EXPONENT`` (1e6), specular
weights outside [0, 1], two-lobe weights summing above 1, NaN or infinite network weights,
weights of the wrong count. The second lobe of ``sampling`` = ``two_lobe`` is ``exponent2`` and
``specular_weight2`` (the mixture ``w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine``).
With ``sampling`` = ``anisotropic_phong`` (Ashikhmin-Shirley lobe in the shading frame, mixed with
cosine), ``exponent`` is ``n_u`` (along the tangent), ``exponent_v`` is ``n_v`` (across it, the
file's ``sampling.exponent_v``; validated like ``exponent``) and ``specular_weight2`` is unused;
``exponent2`` is accepted there as a deprecated alias of ``exponent_v`` at load time (one
warning). ``exponent_v`` with any other sampling is an error.
"""

from __future__ import annotations

import os
import stat
import threading

import drjit as dr
import mitsuba as mi
import numpy as np

from . import _llvm, _native, jit
from ._native import KIND

SAMPLING_NAMES = tuple(_native.SAMPLING_KINDS)
BACKENDS = ("auto", "jit", "rust")
# How the traced backend puts the weights into kernels: "literal" constants (fastest renders;
# one compile per network, an update recompiles), "opaque" kernel parameters (updates without
# recompiling, gradients flow to the weights; one kernel shared by every network of a shape) or
# "auto" (the default: literals for a few live networks, the shared kernel for more, so that a
# scene of hundreds of materials compiles once; jit.AUTO_LITERAL_MAX).
JIT_WEIGHT_MODES = jit.WEIGHT_MODES
_default_backend = "auto"
#: Widest hidden layer the traced backend takes. Its kernels unroll the network into straight-line
#: code, so tracing and compiling grow with width^2. Measured: construction plus the first eval
#: of one 65536-lane wavefront (llvm_ad_rgb, literal weights, the shared 2-core machine):
#: width 21: 0.4 s, 32: 0.7 s, 40: 1.2 s, 48: 1.9 s, 64: 4.7 s, 96: 11.6 s, 200: ~25 s,
#: 1000: minutes and gigabytes. Wider networks go to the Rust backend (``auto``, with a
#: warning) or are refused (``jit``).
JIT_MAX_HIDDEN_WIDTH = 40
MAX_EXPONENT = jit.MAX_EXPONENT
# The MERL format: three little-endian int32 dimensions, then 3 * 90 * 90 * 180 float64.
_MERL_HEADER = np.array([90, 90, 180], dtype="<i4").tobytes()


def set_default_backend(backend: str) -> str:
    """The backend of BSDFs whose scene omits ``backend`` (``auto`` unless changed); returns
    the previous one. ``rust`` renders a whole scene through the reference library."""
    global _default_backend
    backend = str(backend).strip().lower()
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend '{backend}' (expected one of: {', '.join(BACKENDS)})")
    previous, _default_backend = _default_backend, backend
    return previous

# --------------------------------------------------------------------------------------------
# Wavefront mode

_WAVEFRONT_FLAGS = ("SymbolicLoops", "SymbolicCalls")


def use_wavefront_mode(reason: str = "requested") -> list[str]:
    """Switches Dr.Jit's symbolic loops and calls off on the calling thread (JIT variants).

    Only the ``rust`` backend needs this, on the thread that renders. Mitsuba's ``direct``
    integrator records the BSDF call symbolically (needs SymbolicCalls off); ``path`` also runs
    the bounce loop symbolically (needs SymbolicLoops off as well). Dr.Jit's flags are per
    thread and Mitsuba constructs a scene's plugins on worker threads, so no BSDF switches
    them: call this before rendering (a rust-backed BSDF called inside a symbolic scope uses its
    traced twin and logs a warning that says so). Returns the flags switched off.
    """
    if not dr.is_jit_v(mi.Float):
        return []
    changed = []
    for name in _WAVEFRONT_FLAGS:
        flag = getattr(dr.JitFlag, name)
        if dr.flag(flag):
            dr.set_flag(flag, False)
            changed.append(name)
    if changed:
        mi.Log(mi.LogLevel.Info, f"nbrdf_mitsuba: switched Dr.Jit's {' and '.join(changed)} off on this "
                                  f"thread ({reason}): the nbrdf/merl BSDFs call native code on whole "
                                  "wavefronts and cannot run inside symbolic loops or calls")
    return changed


# --------------------------------------------------------------------------------------------
# Scalar variants

_scalar_cost_said = False
_scalar_cost_lock = threading.Lock()  # Mitsuba builds a scene's plugins on several threads


def _say_scalar_cost() -> None:
    """Logs once per process (a warning, shown at Mitsuba's default level) that scalar variants
    evaluate these BSDFs one direction per call through Python: renders that are tens of times
    slower than in llvm_ad_rgb, measured in docs/mitsuba.md ("Performance"). Once, because the
    rust backend is the only one there and every scalar scene would repeat it."""
    global _scalar_cost_said
    with _scalar_cost_lock:
        if _scalar_cost_said:
            return
        _scalar_cost_said = True
    mi.Log(mi.LogLevel.Warn, f"nbrdf_mitsuba: in {mi.variant()} Mitsuba calls the nbrdf and merl BSDFs once "
                             "per direction, each call going through Python and cffi into the native library: "
                             "renders are tens of times slower than in llvm_ad_rgb (or than with Mitsuba's "
                             "own BSDFs). Use scalar variants for reference checks and small images "
                             "(said once per process).")


# --------------------------------------------------------------------------------------------
# Marshalling between Mitsuba values and planar float32 arrays


def _is_jit() -> bool:
    return dr.is_jit_v(mi.Float)


def _width(*values) -> int:
    return max(dr.width(v) for v in values)


def _planar(values, n: int) -> np.ndarray:
    """(k, n) float32 array of k Dr.Jit values of width 1 or n (already evaluated)."""
    if _is_jit():
        rows = [np.asarray(v if isinstance(v, (int, float)) else dr.detach(v).numpy(),
                           dtype=np.float32).reshape(-1) for v in values]
    else:
        rows = [np.asarray([v], dtype=np.float32) for v in values]
    return np.ascontiguousarray(np.stack([np.broadcast_to(r, (n,)) for r in rows]))


def _vector_rows(v) -> list:
    return [v.x, v.y, v.z]


def _to_color(rgb: np.ndarray):
    if _is_jit():
        return mi.Color3f(rgb)
    return mi.Color3f(float(rgb[0, 0]), float(rgb[1, 0]), float(rgb[2, 0]))


def _wavelength_rows(wavelengths) -> list:
    return [wavelengths[j] for j in range(len(wavelengths))]


def _to_wavelengths(values: np.ndarray):
    """A spectral variant's ``mi.UnpolarizedSpectrum`` of planar (wavelengths, n) values."""
    if _is_jit():
        return mi.UnpolarizedSpectrum(values)
    return mi.UnpolarizedSpectrum(*map(float, values[:, 0]))


def _to_spectrum(color, si):
    """The variant's ``mi.Spectrum`` of an RGB value (``mi.Color3f``) at ``si.wavelengths``.

    Monochrome variants take its luminance, as Mitsuba converts RGB data there (``mi.luminance``,
    Rec. 709 weights). Spectral variants uplift it per evaluation (each direction has its own
    colour) as Mitsuba uplifts unbounded RGB data (:func:`jit.spectrum_from_rgb`); sample and pdf
    never see the wavelengths, so there is one density. A spectral network evaluates its own
    spectrum instead (``_spectral_spectrum``, ``_native_spectrum``). Polarized variants get the
    depolarizer's Mueller matrix times the value, as Mitsuba's own non-polarizing BSDFs
    (``diffuse``, ``roughplastic``) return: a depolarizer needs no rotation between the BSDF's
    and Mitsuba's Stokes frames.
    """
    if mi.is_monochromatic:
        color = mi.UnpolarizedSpectrum(mi.luminance(color))
    elif mi.is_spectral:
        color = jit.spectrum_from_rgb(color, si.wavelengths)
    return mi.depolarizer(color) if mi.is_polarized else color


def _zero_spectrum(n: int):
    return dr.zeros(mi.Spectrum, n) if _is_jit() else mi.Spectrum(0.0)


def _to_vector(xyz: np.ndarray):
    if _is_jit():
        return mi.Vector3f(xyz)
    return mi.Vector3f(float(xyz[0, 0]), float(xyz[1, 0]), float(xyz[2, 0]))


def _to_float(values: np.ndarray):
    return mi.Float(values) if _is_jit() else float(values[0])


def _evaluate(*values) -> None:
    if _is_jit():
        dr.eval(*values)


def _directions(wi, wo) -> tuple[np.ndarray, np.ndarray]:
    """Planar (3, n) float32 copies of the view (``si.wi``) and light (``wo``) directions."""
    n = _width(wi, wo) if _is_jit() else 1
    _evaluate(wi, wo)  # one kernel for both
    return _planar(_vector_rows(wi), n), _planar(_vector_rows(wo), n)


def _both_above(active, wi, wo):
    return active & (mi.Frame3f.cos_theta(wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)


# --------------------------------------------------------------------------------------------
# The plugins (variant-independent part)


def _get(props, key, default=None):
    try:
        present = key in props
    except TypeError:  # Mitsuba < 3.7: no __contains__
        present = props.has_property(key)
    return props[key] if present else default


def _resolve(filename: str) -> str:
    resolver = mi.file_resolver() if hasattr(mi, "file_resolver") else mi.Thread.thread().file_resolver()
    return str(resolver.resolve(filename))


class _NativeBSDFMixin:
    """Shared implementation; subclasses set PLUGIN and MATERIAL_KIND and implement
    _default_sampling."""

    PLUGIN = ""  # the Mitsuba plugin name
    MATERIAL_KIND = ""  # what the library must load (a key of _native.MATERIAL_KINDS)

    def _init_native(self, props) -> None:
        mi.BSDF.__init__(self, props)
        filename = _get(props, "filename")
        if not filename:
            raise ValueError(f'{self._type_name()}: the "filename" parameter is required '
                             f'(e.g. <string name="filename" value="..."/>)')
        self._filename = str(filename)
        path = _resolve(self._filename)
        special = _special_file_problem(path)
        if special:
            raise RuntimeError(f'{self._type_name()}: cannot load "{path}": {special} [NBRDF_ERROR_IO]')
        # The library reads the file once; the plugin looks into it only to explain a failure.
        try:
            self._native = _native.Material(path)
        except _native.NbrdfError as error:
            problem = _format_problem(path, self.PLUGIN)
            if problem:
                raise RuntimeError(f'{self._type_name()}: cannot load "{path}": {problem} '
                                   f"[NBRDF_ERROR_FORMAT]") from None
            message = _strip_function(error)
            # Library messages name the file already: say it once.
            where = "" if path in message else f'"{path}": '
            raise RuntimeError(f"{self._type_name()}: cannot load {where}{message} "
                               f"[{error.status_name}]") from None
        problem = None
        if self._native.kind != self.MATERIAL_KIND:
            problem = _format_problem(path, self.PLUGIN) or (
                f"the library read it as a {self._native.kind} material, not a {self.MATERIAL_KIND} one")
        if problem:
            raise RuntimeError(f'{self._type_name()}: cannot load "{path}": {problem} [NBRDF_ERROR_FORMAT]')
        self._path = path
        self._spectral = self._spectral_output()
        flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        if getattr(self._native, "anisotropic", False):
            # An anisotropic network reads phi_h in the shading frame (x: si.sh_frame.s, the
            # tangent), like Mitsuba's anisotropic BSDFs.
            flags = flags | mi.BSDFFlags.Anisotropic
        self.m_components = [flags]
        self.m_flags = flags

        sampling = _get(props, "sampling")
        exponent = _get(props, "exponent")
        weight = _get(props, "specular_weight")
        second = (_get(props, "exponent2"), _get(props, "specular_weight2"))
        self._configure_sampling(sampling, exponent, weight, second, _get(props, "exponent_v"))
        self._backend = self._choose_backend(_get(props, "backend", _default_backend))
        if not _is_jit():
            _say_scalar_cost()

        if _is_jit():
            if mi.variant().startswith("llvm"):
                try:
                    _llvm.check_backend()
                except RuntimeError as error:
                    raise RuntimeError(f"{self._type_name()}: {error}") from None
            if mi.is_spectral:
                jit.srgb_model()  # Mitsuba's model file, read once per variant and before any trace
            # The rust backend keeps a traced twin for symbolic scopes: Dr.Jit traces a symbolic
            # call through every live BSDF, wherever it was built, and native code cannot run
            # there (see _traced_path).
            if self._backend == "jit" or not self._traced_width_problem():
                self._traced = self._trace(path, None if self._backend == "jit" else "literal")
                self._apply_traced_state()

    def _choose_backend(self, backend) -> str:
        backend = str(backend).strip().lower()
        if backend not in BACKENDS:
            raise ValueError(f'{self._type_name()} "{self._filename}": unknown backend "{backend}" '
                             f"(expected one of: {', '.join(BACKENDS)})")
        if backend == "jit" and not _is_jit():
            raise ValueError(f'{self._type_name()} "{self._filename}": backend "jit" needs a JIT '
                             f"variant (llvm_* or cuda_*); {mi.variant()} uses the rust backend")
        too_wide = self._traced_width_problem() if _is_jit() else None
        if backend == "auto":
            if too_wide:
                mi.Log(mi.LogLevel.Warn, f'{self._type_name()} "{self._filename}": {too_wide}; using '
                                         'the rust backend, which needs wavefront mode on the rendering '
                                         "thread (nbrdf_mitsuba.use_wavefront_mode())")
                return "rust"
            return "jit" if _is_jit() else "rust"
        if backend == "jit" and too_wide:
            raise ValueError(f'{self._type_name()} "{self._filename}": {too_wide}; use '
                             '<string name="backend" value="rust"/> (with wavefront mode)')
        return backend

    def _traced_width_problem(self) -> str | None:
        return None

    def _spectral_output(self):
        """``(count, min_nm, max_nm, M)`` of a spectral network (file format version 3; ``M`` the
        library's 3 x count sRGB projection), None for RGB networks and tables."""
        return None

    # -- configuration ------------------------------------------------------------------------

    def _type_name(self) -> str:
        return f'{type(self).__name__} (plugin "{self.PLUGIN}")'

    def _configure_sampling(self, sampling, exponent, weight, second=(None, None), exponent_v=None) -> None:
        if sampling is None:
            sampling = self._default_sampling(exponent, weight, second)
        sampling = str(sampling).strip().lower()
        if sampling not in SAMPLING_NAMES:
            raise ValueError(f'{self._type_name()} "{self._filename}": unknown sampling "{sampling}" '
                             f"(expected one of: {', '.join(SAMPLING_NAMES)})")
        exponent, weight = self._phong_parameters(sampling, exponent, weight)
        second = self._second_exponent_names(sampling, second, exponent_v)
        exponent2, weight2 = self._second_lobe(sampling, *second)
        self._sampling = sampling
        # The sampler's second exponent is n_v for anisotropic_phong, the second lobe's otherwise.
        self._set_sampler(exponent, weight, exponent2, weight2)
        # What traverse exposes: updated in place by SceneParameters, read only by
        # parameters_changed (the kernels use validated copies, see _apply_traced_state).
        anisotropic = sampling == KIND.anisotropic_phong
        self.exponent = _parameter(exponent)
        self.specular_weight = _parameter(weight)
        self.exponent2 = _parameter(0.0 if anisotropic else exponent2)
        self.exponent_v = _parameter(exponent2 if anisotropic else 0.0)
        self.specular_weight2 = _parameter(weight2)

    def _second_exponent_names(self, sampling, second, exponent_v):
        """(second exponent, specular_weight2) as the sampler takes them: ``exponent_v`` for
        anisotropic_phong (``exponent2`` there is its deprecated alias), ``exponent2`` otherwise."""
        exponent2, weight2 = second
        if sampling != KIND.anisotropic_phong:
            if exponent_v is not None:
                raise ValueError(f'{self._type_name()} "{self._filename}": "exponent_v" (n_v) is a parameter '
                                 f'of sampling "anisotropic_phong" only (this BSDF uses "{sampling}")')
            return second
        if exponent2 is not None:
            if exponent_v is not None:
                raise ValueError(f'{self._type_name()} "{self._filename}": give "exponent_v" only ("exponent2" '
                                 'is its deprecated alias for sampling "anisotropic_phong")')
            mi.Log(mi.LogLevel.Warn, f'{self._type_name()} "{self._filename}": "exponent2" for sampling '
                                     '"anisotropic_phong" is deprecated; use "exponent_v" (n_v, across the tangent)')
            exponent_v = exponent2
        return exponent_v, weight2

    def _second_lobe(self, sampling, exponent2, weight2) -> tuple[float, float]:
        """(exponent2, specular_weight2) with file defaults applied; errors when two_lobe lacks
        them."""
        if sampling == KIND.two_lobe and (exponent2 is None or weight2 is None):
            raise ValueError(f'{self._type_name()} "{self._filename}": sampling "two_lobe" needs '
                             '"exponent2" and "specular_weight2" (or a file that stores two lobes)')
        if sampling == KIND.anisotropic_phong:
            if exponent2 is None:
                raise ValueError(f'{self._type_name()} "{self._filename}": sampling "anisotropic_phong" '
                                 'needs "exponent_v" (n_v, across the tangent; or a file that stores an '
                                 'anisotropic lobe)')
            return _as_float(self, "exponent_v", exponent2, 0.0), _as_float(self, "specular_weight2", weight2, 0.0)
        return (_as_float(self, "exponent2", exponent2, 0.0),
                _as_float(self, "specular_weight2", weight2, 0.0))

    def _phong_parameters(self, sampling, exponent, weight) -> tuple[float, float]:
        """(exponent, weight) with file defaults applied; errors when phong lacks them."""
        if sampling in (KIND.phong, KIND.anisotropic_phong) and (exponent is None or weight is None):
            raise ValueError(f'{self._type_name()} "{self._filename}": sampling "{sampling}" needs '
                             '"exponent" and "specular_weight"')
        return _as_float(self, "exponent", exponent, 0.0), _as_float(self, "specular_weight", weight, 0.0)

    def _set_sampler(self, exponent: float, weight: float, exponent2: float = 0.0,
                     weight2: float = 0.0) -> None:
        problem = _sampling_problem(exponent, weight, (exponent2, weight2), self._sampling == KIND.two_lobe,
                                    self._second_exponent_name())
        if problem:
            raise ValueError(f'{self._type_name()} "{self._filename}": invalid sampling parameters: {problem}')
        try:
            if self._sampling == KIND.tabulated:
                # Built once from the material; the lobe parameters do not enter it.
                if getattr(self, "_table", None) is None:
                    self._table = _native.Sampler(self._sampling, material=self._native)
                self._sampler = self._table
            elif self._sampling == KIND.anisotropic_phong:
                self._sampler = _native.Sampler(self._sampling, exponent, weight, exponent_v=exponent2)
            else:
                self._sampler = _native.Sampler(self._sampling, exponent, weight, exponent2, weight2)
        except _native.NbrdfError as error:
            raise ValueError(f'{self._type_name()} "{self._filename}": invalid sampling parameters: '
                             f"{_strip_function(error)}") from None
        self._exponent_value, self._weight_value = exponent, weight
        self._exponent2_value, self._weight2_value = exponent2, weight2

    def _second_exponent_name(self) -> str:
        return "exponent_v" if self._sampling == KIND.anisotropic_phong else "exponent2"

    def _apply_traced_state(self) -> None:
        """The traced kernels' copies of the validated sampling parameters: kernel parameters
        rather than constants, so that new values do not recompile kernels."""
        self._exponent_jit = mi.Float(self._exponent_value)
        self._weight_jit = mi.Float(self._weight_value)
        self._exponent2_jit = mi.Float(self._exponent2_value)
        self._weight2_jit = mi.Float(self._weight2_value)
        dr.make_opaque(self._exponent_jit, self._weight_jit, self._exponent2_jit, self._weight2_jit)
        if self._sampling == KIND.tabulated and getattr(self, "_traced_table", None) is None:
            t = self._table
            self._traced_table = jit.TracedTable(t.rows, t.theta_bins, t.phi_bins, t.cosine_weight,
                                                 *t.arrays())

    # -- Mitsuba interface --------------------------------------------------------------------

    # -- traced backend -----------------------------------------------------------------------

    def _jit_eval(self, si, wo, active):
        f = self._traced.eval(si.wi, wo)
        if self._spectral is not None:
            return self._spectral_spectrum(f, jit.cos_theta(wo), _both_above(active, si.wi, wo), si)
        return _to_spectrum(dr.select(_both_above(active, si.wi, wo), f * jit.cos_theta(wo), 0.0), si)

    def _jit_pdf(self, si, wo, active):
        pdf = jit.pdf(self._sampling, si.wi, wo, self._exponent_jit, self._weight_jit,
                      self._exponent2_jit, self._weight2_jit, getattr(self, "_traced_table", None))
        return dr.select(_both_above(active, si.wi, wo), pdf, 0.0)

    def _jit_sample(self, ctx, si, sample1, sample2, active):
        bs = dr.zeros(mi.BSDFSample3f)
        light, pdf = jit.sample(self._sampling, si.wi, sample1, sample2.x, sample2.y,
                                self._exponent_jit, self._weight_jit, self._exponent2_jit, self._weight2_jit,
                                getattr(self, "_traced_table", None))
        active = active & ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
        active = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (pdf > 0)
        bs.wo = light
        bs.pdf = dr.select(active, pdf, 0.0)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        f = self._traced.eval(si.wi, light)
        if self._spectral is not None:
            return bs, self._spectral_spectrum(f, jit.cos_theta(light) / dr.select(active, pdf, 1.0), active, si)
        f_cos = f * jit.cos_theta(light)
        weight = f_cos / dr.select(active, pdf, 1.0)
        # As sampling/mod.rs sample_weight: 0 where a tiny pdf would overflow the quotient.
        weight = dr.select(active & dr.all(dr.isfinite(weight)), weight, 0.0)
        return bs, _to_spectrum(weight, si)

    def _spectral_spectrum(self, coefficients, scale, active, si):
        """A spectral network's value (its B-spline coefficients) times ``scale`` as the
        variant's spectrum, 0 where not ``active`` or not finite: per wavelength in spectral
        variants (no uplift: the network is spectral), the sRGB projection ``M c`` in RGB
        variants and its luminance in monochrome ones (as ``_to_spectrum`` does for RGB
        values); polarized variants get the depolarizer times the value."""
        _, min_nm, max_nm, matrix = self._spectral
        if mi.is_spectral:
            value = jit.spectral_value(coefficients, si.wavelengths, min_nm, max_nm) * scale
        else:
            value = jit.srgb_projection(coefficients, matrix) * scale
            value = mi.luminance(value) if mi.is_monochromatic else value
        # A Spectrum before dr.all: on a flat Float (mono) it would reduce over the lanes.
        value = mi.UnpolarizedSpectrum(value)
        value = mi.UnpolarizedSpectrum(dr.select(active & dr.all(dr.isfinite(value)), value, 0.0))
        return mi.depolarizer(value) if mi.is_polarized else value

    def _native_spectrum(self, view, light, active, si, weight=None, pdf=None):
        """The library's ``f_r cos`` at planar directions (or a sample's ``weight`` with its
        ``pdf``) as the variant's spectrum, 0 where not ``active``. A spectral network in a
        spectral variant is evaluated at the lane's wavelengths (``eval_spectral``) and divided
        by ``pdf`` (0 where the quotient is not finite, as ``sampling/mod.rs`` sample_weight);
        anything else is the library's RGB value."""
        if self._spectral is None or not mi.is_spectral:
            value = _to_color(self._native.eval(view, light) if weight is None else weight)
            return _to_spectrum(dr.select(active, value, 0.0), si)
        values = self._native.eval_spectral(view, light, _planar(_wavelength_rows(si.wavelengths), view.shape[1]))
        if pdf is not None:
            with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
                values = np.where(pdf > 0, values / np.where(pdf > 0, pdf, 1.0), 0.0)
            values = np.where(np.all(np.isfinite(values), axis=0), values, 0.0).astype(np.float32)
        value = mi.UnpolarizedSpectrum(dr.select(active, _to_wavelengths(values), 0.0))
        return mi.depolarizer(value) if mi.is_polarized else value

    def _traced_path(self, *values) -> bool:
        """Whether this call goes through the traced code: the jit backend, or the rust backend
        inside a symbolic loop or call. Dr.Jit's flags are per thread and plugins are built on
        worker threads, so a rust-backed BSDF cannot count on wavefront mode; in a symbolic
        scope it uses its traced twin (the same math, held to the library by
        tests/test_backends.py) and says so once in the log."""
        if not _is_jit() or _width(*values) == 0:
            return False
        if self._backend == "jit":
            return True
        if not dr.flag(dr.JitFlag.SymbolicScope):
            return False
        if not hasattr(self, "_traced"):
            raise RuntimeError(
                f'{self._type_name()} "{self._filename}": called inside a symbolic Dr.Jit loop or call, '
                f"where the rust backend cannot run and the traced one is refused "
                f"({self._traced_width_problem()}). Render in wavefront mode: call "
                "nbrdf_mitsuba.use_wavefront_mode() on the rendering thread before rendering")
        if not getattr(self, "_warned_twin", False):
            self._warned_twin = True
            mi.Log(mi.LogLevel.Warn,
                   f'{self._type_name()} "{self._filename}": backend "rust" called inside a symbolic '
                   "Dr.Jit loop or call (wavefront mode is off on this thread); evaluating its traced "
                   "twin instead. For the reference library, call nbrdf_mitsuba.use_wavefront_mode() "
                   "on the rendering thread before rendering")
        return True

    # -- Mitsuba interface --------------------------------------------------------------------

    def eval(self, ctx, si, wo, active=True):
        if self._traced_path(si.wi, wo):
            enabled = ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
            return self._jit_eval(si, wo, active & enabled)
        if not self._enabled(ctx, si.wi, wo):
            return _zero_spectrum(_width(si.wi, wo) if _is_jit() else 1)
        view, light = _directions(si.wi, wo)
        return self._native_spectrum(view, light, _both_above(active, si.wi, wo), si)

    def pdf(self, ctx, si, wo, active=True):
        if self._traced_path(si.wi, wo):
            return self._jit_pdf(si, wo, active & ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0))
        if not self._enabled(ctx, si.wi, wo):
            return dr.zeros(mi.Float, _width(si.wi, wo) if _is_jit() else 1)
        view, light = _directions(si.wi, wo)
        pdf = _to_float(self._sampler.pdf(view, light))
        return dr.select(_both_above(active, si.wi, wo), pdf, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        if self._traced_path(si.wi, wo):
            active = active & ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
            return self._jit_eval(si, wo, active), self._jit_pdf(si, wo, active)
        if not self._enabled(ctx, si.wi, wo):
            n = _width(si.wi, wo) if _is_jit() else 1
            return _zero_spectrum(n), dr.zeros(mi.Float, n)
        view, light = _directions(si.wi, wo)
        pdf = _to_float(self._sampler.pdf(view, light))
        active = _both_above(active, si.wi, wo)
        return self._native_spectrum(view, light, active, si), dr.select(active, pdf, 0.0)

    def sample(self, ctx, si, sample1, sample2, active=True):
        if self._traced_path(si.wi, sample1, sample2):
            return self._jit_sample(ctx, si, sample1, sample2, active)
        n = _width(si.wi, sample1, sample2) if _is_jit() else 1
        bs = dr.zeros(mi.BSDFSample3f, n) if _is_jit() else mi.BSDFSample3f()
        if not self._enabled(ctx, si.wi, sample1, sample2):
            return bs, _zero_spectrum(n)
        _evaluate(si.wi, sample1, sample2)
        view = _planar(_vector_rows(si.wi), n)
        u = _planar([sample1, sample2.x, sample2.y], n)
        light, weight, pdf = self._native.sample(self._sampler, view, u)
        bs.wo = _to_vector(light)
        bs.pdf = _to_float(pdf)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        active = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (bs.pdf > 0)
        bs.pdf = dr.select(active, bs.pdf, 0.0)
        # The library's weight is RGB; a spectral network in a spectral variant is evaluated
        # again at the sampled direction and the lane's wavelengths.
        return bs, self._native_spectrum(view, light, active, si, weight, pdf)

    @staticmethod
    def _enabled(ctx, *values) -> bool:
        """Whether there is anything to compute: the glossy lobe is selected and, in JIT
        variants, the wavefront is not empty (Dr.Jit cannot broadcast literals to width 0)."""
        if not ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0):
            return False
        return not _is_jit() or _width(*values) > 0

    def traverse(self, callback):
        # Mitsuba types (not Python floats) so that SceneParameters can update them in place.
        put = getattr(callback, "put", None) or callback.put_parameter
        put("exponent", self.exponent, mi.ParamFlags.NonDifferentiable)
        put("specular_weight", self.specular_weight, mi.ParamFlags.NonDifferentiable)
        put("exponent2", self.exponent2, mi.ParamFlags.NonDifferentiable)
        put("exponent_v", self.exponent_v, mi.ParamFlags.NonDifferentiable)
        put("specular_weight2", self.specular_weight2, mi.ParamFlags.NonDifferentiable)
        if self._backend == "jit":
            self._traverse_traced(put)

    def parameters_changed(self, keys=None):
        """Validates the whole update, then applies all of it or nothing.

        A rejected update raises ValueError (saying what was wrong), writes the last good values
        back into the traversed parameters (in place, so the ``SceneParameters`` that holds them
        sees them too) and leaves the BSDF as it was; later valid updates take effect."""
        try:
            exponent = _scalar(self.exponent, "exponent")
            weight = _scalar(self.specular_weight, "specular_weight")
            name = self._second_exponent_name()
            exponent2 = _scalar(getattr(self, name), name)
            # The other one of exponent2 / exponent_v does nothing here; checked all the same.
            unused = "exponent2" if name == "exponent_v" else "exponent_v"
            unused_value = _scalar(getattr(self, unused), unused)
            weight2 = _scalar(self.specular_weight2, "specular_weight2")
            problem = (_sampling_problem(exponent, weight, (exponent2, weight2), self._sampling == KIND.two_lobe, name)
                       or _sampling_problem(0.0, 0.0, (unused_value, 0.0), False, unused))
            if problem:
                raise ValueError(f"invalid sampling parameters: {problem}")
            weights = self._validated_weights(keys) if self._backend == "jit" else None
        except ValueError as error:
            self._restore_parameters()
            raise ValueError(f'{self._type_name()} "{self._filename}": update rejected, the BSDF keeps '
                             f"its previous parameters: {error}") from None
        if weights is not None:
            self._apply_weights(weights)
        new = (exponent, weight, exponent2, weight2)
        old = (self._exponent_value, self._weight_value, self._exponent2_value, self._weight2_value)
        if unused_value != self._unused_value():
            mi.Log(mi.LogLevel.Warn, f'{self._type_name()} "{self._filename}": {unused} does nothing with sampling '
                                     f'"{self._sampling}" (exponent_v is n_v of "anisotropic_phong", exponent2 the '
                                     'second lobe of "two_lobe")')
            self._unused_second = unused_value
        if new != old:
            self._set_sampler(*new)  # validated above: cannot fail
            if self._sampling not in (KIND.phong, KIND.two_lobe, KIND.anisotropic_phong) or (
                    self._sampling == KIND.phong and new[2:] != old[2:]) or (
                    self._sampling == KIND.anisotropic_phong and new[3] != old[3]):
                mi.Log(mi.LogLevel.Warn, f'{self._type_name()} "{self._filename}": exponent and '
                                         f'specular_weight only affect sampling "phong", "two_lobe" and '
                                         f'"anisotropic_phong", exponent2 and specular_weight2 only '
                                         f'"two_lobe", exponent_v only "anisotropic_phong" (this '
                                         f'BSDF uses "{self._sampling}")')
        if hasattr(self, "_traced"):
            self._apply_traced_state()

    def _unused_value(self) -> float:
        """The last good value of whichever of exponent2 / exponent_v this sampling ignores."""
        return getattr(self, "_unused_second", 0.0)

    def _restore_parameters(self) -> None:
        _assign(self.exponent, self._exponent_value)
        _assign(self.specular_weight, self._weight_value)
        used, unused = ((self.exponent_v, self.exponent2) if self._sampling == KIND.anisotropic_phong
                        else (self.exponent2, self.exponent_v))
        _assign(used, self._exponent2_value)
        _assign(unused, self._unused_value())
        _assign(self.specular_weight2, self._weight2_value)
        if self._backend == "jit":
            self._restore_weights()

    def _validated_weights(self, keys):
        return None

    def _apply_weights(self, weights) -> None:
        pass

    def _restore_weights(self) -> None:
        pass

    def to_string(self):
        lines = [f'filename = "{self._filename}"', *self._describe(), f"backend = {self._backend}",
                 f"sampling = {self._sampling}"]
        if self._sampling in (KIND.phong, KIND.two_lobe, KIND.anisotropic_phong):
            lines += [f"exponent = {self._exponent_value:g}", f"specular_weight = {self._weight_value:g}"]
        if self._sampling == KIND.anisotropic_phong:
            lines += [f"exponent_v = {self._exponent2_value:g}"]
        if self._sampling == KIND.two_lobe:
            lines += [f"exponent2 = {self._exponent2_value:g}", f"specular_weight2 = {self._weight2_value:g}"]
        return f"{type(self).__name__}[\n" + ",\n".join("  " + line for line in lines) + "\n]"


class NbrdfMixin(_NativeBSDFMixin):
    """``nbrdf``: a neural BRDF from an ``*.nbrdf.json`` file.

    Parameters: ``filename``; ``sampling`` = the file's ``sampling.default`` when it names one
    (the strategy ``nbrdf fit-phong`` measured with the lowest variance) | ``tabulated`` (a
    half-vector table built from the network at load time) | ``two_lobe`` (default when the
    file stores two Blinn-Phong lobes) | ``anisotropic_phong`` (default when it stores an
    anisotropic lobe, ``sampling.exponent_v``; ``exponent`` is then ``n_u`` and ``exponent_v``
    ``n_v``) | ``phong`` (default when it stores one; with a two-lobe file, its first lobe) |
    ``cosine`` (default otherwise) | ``uniform``; ``exponent``, ``specular_weight``,
    ``exponent2``, ``specular_weight2`` and ``exponent_v`` override the stored lobes.
    """

    PLUGIN = "nbrdf"
    MATERIAL_KIND = "network"

    def __init__(self, props):
        self._props_jit_weights = _get(props, "jit_weights", "auto")
        self._init_native(props)

    def _trace(self, path, mode=None):
        # The network as the library loaded, validated and proved it: no second read or proof.
        # Only literal kernels leave units out; "auto" proves when it first traces one.
        mode = str(self._props_jit_weights if mode is None else mode).strip().lower()
        if mode not in JIT_WEIGHT_MODES:
            raise ValueError(f'{self._type_name()} "{self._filename}": unknown jit_weights "{mode}" '
                             f"(expected one of: {', '.join(JIT_WEIGHT_MODES)})")
        layers, active = self._native.network(prove=mode == "literal")
        return jit.TracedNetwork(layers, weights=mode, anisotropic=self._native.anisotropic,
                                 active_units=self._native.active_units, active=active)

    def _traverse_traced(self, put):
        # The network's 675 (for width 21) weights, W1 b1 W2 b2 W3 b3, updatable through
        # params.update(). Only "opaque" weights carry gradients; literals are constants of the
        # kernel, and an update recompiles it ("auto": literal or shared-kernel parameters, no
        # gradients, so that its kernels never depend on whether gradients are on).
        differentiable = self._traced.mode == "opaque"
        put("weights", self._traced.flat,
            mi.ParamFlags.Differentiable if differentiable else mi.ParamFlags.NonDifferentiable)

    def _validated_weights(self, keys):
        """The new network weights (NumPy) when the update names them, if valid; raises ValueError."""
        if keys is not None and not any(str(key).endswith("weights") for key in keys):
            return None
        flat = self._traced.flat
        count = dr.width(flat)
        if count != self._traced.parameter_count:
            raise ValueError(f'"weights" must hold {self._traced.parameter_count} values, got {count}')
        values = np.asarray(dr.detach(flat).numpy(), dtype=np.float32).reshape(-1)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            k = int(bad[0])
            raise ValueError(f'"weights" value {k} ({self._traced.describe_index(k)}) is '
                             f"{_non_finite_name(values[k])}; {bad.size} of {values.size} weights are "
                             "not finite (every weight must be a finite float32)")
        return values  # refreshed even when equal: enabling gradients marks the key as changed

    def _apply_weights(self, weights) -> None:
        self._traced.refresh()

    def _restore_weights(self) -> None:
        if not np.array_equal(np.asarray(dr.detach(self._traced.flat).numpy()).reshape(-1), self._traced.good):
            _assign(self._traced.flat, self._traced.good)

    def _spectral_output(self):
        count = self._native.spectral_count
        if not count:
            return None
        min_nm, max_nm = self._native.spectral_range_nm
        return count, min_nm, max_nm, self._native.spectral_srgb_matrix()

    def _traced_width_problem(self) -> str | None:
        width = self._native.hidden_width
        if width <= JIT_MAX_HIDDEN_WIDTH:
            return None
        return (f"hidden width {width} is above {JIT_MAX_HIDDEN_WIDTH}, the widest network the traced "
                f"(jit) backend evaluates in reasonable time (JIT_MAX_HIDDEN_WIDTH)")

    def _default_sampling(self, exponent, weight, second=(None, None)) -> str:
        # The file's measured best (nbrdf fit-phong), unless the scene gives lobe parameters.
        if self._native.default_sampling and exponent is None and weight is None:
            return self._native.default_sampling
        if self._native.stored_sampling in (KIND.two_lobe, KIND.anisotropic_phong):
            return self._native.stored_sampling
        if self._native.has_sampling or (exponent is not None and weight is not None):
            return KIND.two_lobe if None not in second else KIND.phong
        return KIND.cosine

    def _phong_parameters(self, sampling, exponent, weight):
        if self._native.has_sampling:
            exponent = self._native.exponent if exponent is None else exponent
            weight = self._native.specular_weight if weight is None else weight
        return _NativeBSDFMixin._phong_parameters(self, sampling, exponent, weight)

    def _second_lobe(self, sampling, exponent2, weight2):
        if self._native.stored_sampling == KIND.two_lobe:
            exponent2 = self._native.exponent2 if exponent2 is None else exponent2
            weight2 = self._native.specular_weight2 if weight2 is None else weight2
        if self._native.stored_sampling == KIND.anisotropic_phong and sampling == KIND.anisotropic_phong:
            exponent2 = self._native.exponent_v if exponent2 is None else exponent2
        return _NativeBSDFMixin._second_lobe(self, sampling, exponent2, weight2)

    def _describe(self) -> list[str]:
        net = self._native
        lines = [f'name = "{net.name}"', f"hidden_width = {net.hidden_width}",
                 f"parameter_count = {net.parameter_count}", f"anisotropic = {str(net.anisotropic).lower()}"]
        if self._spectral is not None:
            count, min_nm, max_nm, _ = self._spectral
            lines.append(f"spectral = cubic B-spline, {count} coefficients over {min_nm:g}-{max_nm:g} nm")
        if self._backend == "jit":
            lines.append(f"jit_weights = {self._traced.mode}")
            if self._traced.mode == "auto":
                lines.append(f"kernel = {self._traced.kernel()}")
        return lines


class MerlMixin(_NativeBSDFMixin):
    """``merl``: a MERL-format table (``.binary``), trilinearly interpolated.

    Parameters: ``filename``; ``sampling`` = ``cosine`` (default) | ``uniform`` | ``tabulated``
    (a half-vector table built from the table at load time) | ``phong``
    (requires ``exponent`` and ``specular_weight``) | ``two_lobe`` (requires those and
    ``exponent2``, ``specular_weight2``).
    """

    PLUGIN = "merl"
    MATERIAL_KIND = "merl"

    def __init__(self, props):
        self._init_native(props)

    def _trace(self, path, mode=None):
        # The library has validated size, header and values.
        stored = np.fromfile(path, dtype="<f8", offset=12)
        return jit.TracedMerl(stored)

    def _traverse_traced(self, put):
        pass

    def _default_sampling(self, exponent, weight, second=(None, None)) -> str:
        if exponent is None or weight is None:
            return KIND.cosine
        return KIND.two_lobe if None not in second else KIND.phong

    def _describe(self) -> list[str]:
        return []


def _as_float(bsdf, name, value, default) -> float:
    if value is None:
        return default
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f'{bsdf._type_name()} "{bsdf._filename}": "{name}" must be a number, '
                         f"got {value!r}") from None


def _parameter(value: float):
    """A Mitsuba value that SceneParameters can update in place (a Python float cannot be)."""
    return mi.Float(value) if _is_jit() else mi.Vector1f(value)


def _assign(target, values) -> None:
    """Writes ``values`` into the Mitsuba array ``target`` in place (what SceneParameters holds)."""
    values = np.asarray(values, dtype=np.float32).reshape(-1)
    mi.set_property(target, type(target)(values) if _is_jit() else type(target)(*map(float, values)))


def _scalar(value, name: str = "value") -> float:
    if isinstance(value, (int, float)):
        return float(value)
    array = np.asarray(dr.detach(value).numpy() if _is_jit() else value, dtype=np.float64).reshape(-1)
    if array.size != 1:
        raise ValueError(f'"{name}" must be a single value, got {array.size}')
    return float(array[0])


def _non_finite_name(value) -> str:
    return "NaN" if np.isnan(value) else ("+inf" if value > 0 else "-inf")


def _sampling_problem(exponent: float, weight: float, second=None, two_lobe: bool = False,
                      second_exponent: str = "exponent2") -> str | None:
    """Why (exponent, specular_weight) and the optional second lobe (``second_exponent``:
    exponent2, or exponent_v of the anisotropic lobe; specular_weight2) cannot be used, naming
    NaN where NaN is the problem; the weights' sum matters only to ``two_lobe`` sampling."""
    lobes = [("exponent", "specular_weight", exponent, weight)]
    if second is not None:
        lobes.append((second_exponent, "specular_weight2", *second))
    for exponent_name, weight_name, n, w in lobes:
        if not np.isfinite(n):
            return f"{exponent_name} is {_non_finite_name(n)} (must be finite, in [0, {MAX_EXPONENT:g}])"
        if n < 0:
            return f"{exponent_name} {n:g} is negative (must be in [0, {MAX_EXPONENT:g}])"
        if n > MAX_EXPONENT:
            return (f"{exponent_name} {n:g} is above the maximum {MAX_EXPONENT:g} (MAX_EXPONENT: "
                    "sharper lobes are not resolved by float32 directions)")
        if not np.isfinite(w):
            return f"{weight_name} is {_non_finite_name(w)} (must be in [0, 1])"
        if not 0.0 <= w <= 1.0:
            return f"{weight_name} {w:g} is outside [0, 1]"
    # The library's tolerance (sampling/two_lobe.rs WEIGHT_SUM_TOLERANCE): float32 weights may sum to 1 + ulp.
    if two_lobe and second is not None and weight + second[1] > 1.0 + 1e-6:
        return (f"specular_weight {weight:g} + specular_weight2 {second[1]:g} is above 1 (the "
                "cosine lobe takes 1 - specular_weight - specular_weight2)")
    return None


def _special_file_problem(path: str) -> str | None:
    """Why ``path`` cannot be read as a BSDF without blocking (a FIFO would block, /dev/zero
    never ends), judged from its metadata alone."""
    try:
        info = os.stat(path)
    except OSError:
        return None  # the library reports missing and unreadable files
    if not stat.S_ISREG(info.st_mode):
        return "not a regular file (a directory, FIFO or device cannot be read as a BSDF)"
    return None


def _format_problem(path: str, plugin: str) -> str | None:
    """Why the library could not load ``path`` for ``plugin`` (or loaded the other plugin's
    kind), in the user's terms: the other plugin's format, binary data, a table's values."""
    try:
        with open(path, "rb") as file:
            head = file.read(64)
    except OSError:
        return None  # the library's I/O error says it
    is_merl = head[:12] == _MERL_HEADER
    is_json = head.lstrip()[:1] in (b"{", b"[")
    if plugin == "nbrdf" and is_merl:
        return ("this is a MERL table; the nbrdf BSDF reads *.nbrdf.json networks "
                '(use the merl BSDF: "type": "merl")')
    if plugin == "nbrdf" and b"\0" in head:
        return ("this is binary data, not an *.nbrdf.json network (JSON text); MERL tables go to "
                'the merl BSDF ("type": "merl")')
    if plugin == "merl" and is_json:
        return ("this is a JSON file (an *.nbrdf.json network?); the merl BSDF reads MERL .binary "
                'tables (use the nbrdf BSDF for networks: "type": "nbrdf")')
    if plugin == "merl" and is_merl:
        return None  # the library names the bad size or value (nbrdf-core merl/io.rs)
    if plugin == "merl":
        # The library reads a file without a table's header as a network, and would say why
        # it is not one.
        return "not a MERL table (a .binary table starts with the resolutions 90, 90, 180 as int32)"
    return None


def _strip_function(error: Exception) -> str:
    """A library message without its leading ``nbrdf_xxx: `` function name."""
    message = str(error)
    head, sep, tail = message.partition(": ")
    return tail if sep and head.startswith("nbrdf_") and " " not in head else message


_CLASSES: dict[str, tuple[type, type]] = {}


def _namespace(mixin: type) -> dict:
    """The attributes of ``mixin`` and its bases, to build a class with a single base.

    nanobind types accept exactly one base, so the plugin classes cannot inherit from both
    ``mi.BSDF`` and a mixin; their methods are copied instead (and use no ``super()``).
    """
    namespace = {}
    for klass in reversed(mixin.__mro__[:-1]):
        namespace.update({k: v for k, v in vars(klass).items() if k not in ("__dict__", "__weakref__")})
    return namespace


def classes() -> tuple[type, type]:
    """(NbrdfBSDF, MerlBSDF) for the current Mitsuba variant."""
    variant = mi.variant()
    if variant is None:
        raise RuntimeError("nbrdf_mitsuba: set a Mitsuba variant first (mi.set_variant(...))")
    if variant not in _CLASSES:
        made = []
        for name, mixin in (("NbrdfBSDF", NbrdfMixin), ("MerlBSDF", MerlMixin)):
            namespace = {**_namespace(mixin), "__module__": __name__, "__qualname__": name}
            made.append(type(name, (mi.BSDF,), namespace))
        _CLASSES[variant] = (made[0], made[1])
    return _CLASSES[variant]


__all__ = ["classes", "use_wavefront_mode", "set_default_backend", "NbrdfMixin", "MerlMixin", "SAMPLING_NAMES", "BACKENDS"]
