"""The two backends of the ``nbrdf`` and ``merl`` BSDFs, chosen once when a BSDF is built; each
has ``eval``, ``pdf``, ``eval_pdf`` and ``sample`` with Mitsuba's signatures.

* :class:`JitBackend` (``jit``, the default in JIT variants): the network, the table lookup and
  the Blinn-Phong mixture written as Dr.Jit arithmetic (:mod:`nbrdf_mitsuba.jit`), traced into
  Mitsuba's own kernels. Symbolic loops and calls stay on; it runs at Mitsuba's full speed, on
  LLVM and CUDA alike.
* :class:`RustBackend` (``rust``, the default in scalar variants, the reference): the native
  library through its C ABI (:mod:`nbrdf_mitsuba._native`), one direction per call in scalar
  variants (:class:`ScalarArrays`) and whole wavefronts on the host in JIT variants
  (:class:`WavefrontArrays`): directions are evaluated (``dr.eval``), copied to NumPy in Dr.Jit's
  planar (3, N) layout, handed to the library, and copied back. That cannot happen while Dr.Jit
  records a symbolic loop or call, so in JIT variants the library runs in wavefront mode on the
  thread that renders (:func:`use_wavefront_mode`). Dr.Jit's flags are per thread, Mitsuba
  builds a scene's plugins on worker threads, and a symbolic call is traced through every live
  BSDF, so constructing a BSDF changes no flag; inside a symbolic scope a rust-backed BSDF
  evaluates its traced twin instead (logged once), on whichever thread. Outputs are not
  differentiable.

Every variant: RGB, monochrome, spectral (the RGB value uplifted per wavelength as Mitsuba uplifts
unbounded RGB data) and polarized (see :func:`_to_spectrum`).
"""

from __future__ import annotations

import threading

import drjit as dr
import mitsuba as mi
import numpy as np

from . import _llvm, jit
from ._native import KIND

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


_scalar_cost_said = False
_scalar_cost_lock = threading.Lock()  # Mitsuba builds a scene's plugins on several threads


def say_scalar_cost() -> None:
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


def prepare_variant(arrays, label: str) -> None:
    """What the variant needs before a BSDF's backends are built: in scalar variants, the
    warning of :func:`say_scalar_cost`; in JIT ones, a usable libLLVM (llvm_*; errors start with
    ``label``) and, in spectral ones, Mitsuba's RGB-to-spectrum model read before any trace."""
    if not arrays.wavefront:
        say_scalar_cost()
        return
    if mi.variant().startswith("llvm"):
        try:
            _llvm.check_backend()
        except RuntimeError as error:
            raise RuntimeError(f"{label}: {error}") from None
    if mi.is_spectral:
        jit.srgb_model()  # Mitsuba's model file, read once per variant and before any trace


# --------------------------------------------------------------------------------------------
# Mitsuba values as planar float32 arrays and back


def _width(*values) -> int:
    return max(dr.width(v) for v in values)


class _Arrays:
    """How the variant's values become planar (k, n) float32 arrays and back."""

    #: Whether Mitsuba calls with wavefronts (JIT variants) rather than one direction.
    wavefront = False

    def planar(self, values, n: int) -> np.ndarray:
        """(k, n) float32 array of k values of width 1 or n (already evaluated)."""
        rows = [self._row(v) for v in values]
        return np.ascontiguousarray(np.stack([np.broadcast_to(r, (n,)) for r in rows]))

    def assign(self, target, values) -> None:
        """Writes ``values`` into the Mitsuba array ``target`` in place (what SceneParameters holds)."""
        values = np.asarray(values, dtype=np.float32).reshape(-1)
        mi.set_property(target, self._array(type(target), values))

    def scalar(self, value, name: str = "value") -> float:
        if isinstance(value, (int, float)):
            return float(value)
        array = np.asarray(self._numpy(value), dtype=np.float64).reshape(-1)
        if array.size != 1:
            raise ValueError(f'"{name}" must be a single value, got {array.size}')
        return float(array[0])


class ScalarArrays(_Arrays):
    """Scalar variants: one direction per call, Python floats and Mitsuba's scalar types."""

    @staticmethod
    def width(*values) -> int:
        return 1

    @staticmethod
    def _row(v) -> np.ndarray:
        return np.asarray([v], dtype=np.float32)

    @staticmethod
    def _array(kind, values: np.ndarray):
        return kind(*map(float, values))

    @staticmethod
    def _numpy(value):
        return value

    @staticmethod
    def evaluate(*values) -> None:
        pass

    @staticmethod
    def color(rgb: np.ndarray):
        return mi.Color3f(float(rgb[0, 0]), float(rgb[1, 0]), float(rgb[2, 0]))

    @staticmethod
    def wavelengths(values: np.ndarray):
        """A spectral variant's ``mi.UnpolarizedSpectrum`` of planar (wavelengths, n) values."""
        return mi.UnpolarizedSpectrum(*map(float, values[:, 0]))

    @staticmethod
    def vector(xyz: np.ndarray):
        return mi.Vector3f(float(xyz[0, 0]), float(xyz[1, 0]), float(xyz[2, 0]))

    @staticmethod
    def float_(values: np.ndarray):
        return float(values[0])

    @staticmethod
    def zero_spectrum(n: int):
        return mi.Spectrum(0.0)

    @staticmethod
    def empty_sample(n: int):
        return mi.BSDFSample3f()

    @staticmethod
    def parameter(value: float):
        """A Mitsuba value that SceneParameters can update in place (a Python float cannot be)."""
        return mi.Vector1f(value)


class WavefrontArrays(_Arrays):
    """JIT variants: wavefronts of Dr.Jit arrays, evaluated before they are copied."""

    wavefront = True

    @staticmethod
    def width(*values) -> int:
        return _width(*values)

    @staticmethod
    def _row(v) -> np.ndarray:
        return np.asarray(v if isinstance(v, (int, float)) else dr.detach(v).numpy(), dtype=np.float32).reshape(-1)

    @staticmethod
    def _array(kind, values: np.ndarray):
        return kind(values)

    @staticmethod
    def _numpy(value):
        return dr.detach(value).numpy()

    @staticmethod
    def evaluate(*values) -> None:
        dr.eval(*values)

    @staticmethod
    def color(rgb: np.ndarray):
        return mi.Color3f(rgb)

    @staticmethod
    def wavelengths(values: np.ndarray):
        """A spectral variant's ``mi.UnpolarizedSpectrum`` of planar (wavelengths, n) values."""
        return mi.UnpolarizedSpectrum(values)

    @staticmethod
    def vector(xyz: np.ndarray):
        return mi.Vector3f(xyz)

    @staticmethod
    def float_(values: np.ndarray):
        return mi.Float(values)

    @staticmethod
    def zero_spectrum(n: int):
        return dr.zeros(mi.Spectrum, n)

    @staticmethod
    def empty_sample(n: int):
        return dr.zeros(mi.BSDFSample3f, n)

    @staticmethod
    def parameter(value: float):
        """A Mitsuba value that SceneParameters can update in place (a Python float cannot be)."""
        return mi.Float(value)


def variant_arrays() -> _Arrays:
    """The arrays of the current Mitsuba variant."""
    return WavefrontArrays() if dr.is_jit_v(mi.Float) else ScalarArrays()


# --------------------------------------------------------------------------------------------
# Shared by both backends


def _both_above(active, wi, wo):
    return active & (mi.Frame3f.cos_theta(wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)


def _to_spectrum(color, si):
    """The variant's ``mi.Spectrum`` of an RGB value (``mi.Color3f``) at ``si.wavelengths``.

    Monochrome variants take its luminance, as Mitsuba converts RGB data there (``mi.luminance``,
    Rec. 709 weights). Spectral variants uplift it per evaluation (each direction has its own
    colour) as Mitsuba uplifts unbounded RGB data (:func:`jit.spectrum_from_rgb`); sample and pdf
    never see the wavelengths, so there is one density. A spectral network or spatially varying
    material evaluates its own spectrum instead (``JitBackend._spectral_spectrum``,
    ``RustBackend._spectral_value``). Polarized
    variants get the depolarizer's Mueller matrix times the value, as Mitsuba's own
    non-polarizing BSDFs (``diffuse``, ``roughplastic``) return: a depolarizer needs no rotation
    between the BSDF's and Mitsuba's Stokes frames.
    """
    if mi.is_monochromatic:
        color = mi.UnpolarizedSpectrum(mi.luminance(color))
    elif mi.is_spectral:
        color = jit.spectrum_from_rgb(color, si.wavelengths)
    return mi.depolarizer(color) if mi.is_polarized else color


def _glossy(ctx):
    return ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)


# --------------------------------------------------------------------------------------------
# The traced backend


class JitBackend:
    """The material's traced twin (a :class:`jit.TracedNetwork` or :class:`jit.TracedMerl`) and
    the traced sampler of ``sampling``, traced into Mitsuba's kernels. ``spectral``: a spectral
    material's ``(count, min_nm, max_nm, M)``, else None."""

    name = "jit"

    def __init__(self, traced, spectral, sampling: str):
        self.traced = traced
        self.spectral = spectral
        self.sampling = sampling
        #: The sampling parameters as kernel parameters (exponent, weight, exponent2, weight2).
        self.lobes = None
        #: The traced table of ``tabulated`` sampling, built once from the library's.
        self.table = None

    def use(self, sampler, lobes) -> None:
        """Takes the validated sampling parameters ``lobes`` (the library's ``sampler`` made from
        them) as kernel parameters rather than constants, so that new values do not recompile
        kernels."""
        self.lobes = tuple(mi.Float(value) for value in lobes)
        dr.make_opaque(*self.lobes)
        if self.sampling == KIND.tabulated and self.table is None:
            self.table = jit.TracedTable(sampler.rows, sampler.theta_bins, sampler.phi_bins, sampler.cosine_weight,
                                         *sampler.arrays())

    # An empty wavefront gets empty values: Dr.Jit cannot broadcast literals to width 0.

    def eval(self, ctx, si, wo, active=True):
        if _width(si.wi, wo) == 0:
            return dr.zeros(mi.Spectrum, 0)
        return self._eval(si, wo, active & _glossy(ctx))

    def pdf(self, ctx, si, wo, active=True):
        if _width(si.wi, wo) == 0:
            return dr.zeros(mi.Float, 0)
        return self._pdf(si, wo, active & _glossy(ctx))

    def eval_pdf(self, ctx, si, wo, active=True):
        if _width(si.wi, wo) == 0:
            return dr.zeros(mi.Spectrum, 0), dr.zeros(mi.Float, 0)
        active = active & _glossy(ctx)
        return self._eval(si, wo, active), self._pdf(si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        if _width(si.wi, sample1, sample2) == 0:
            return dr.zeros(mi.BSDFSample3f, 0), dr.zeros(mi.Spectrum, 0)
        bs = dr.zeros(mi.BSDFSample3f)
        light, pdf = jit.sample(self.sampling, si.wi, sample1, sample2.x, sample2.y, *self.lobes, self.table)
        active = active & _glossy(ctx)
        active = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (pdf > 0)
        bs.wo = light
        bs.pdf = dr.select(active, pdf, 0.0)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        f = self.traced.eval(si.wi, light)
        if self.spectral is not None:
            return bs, self._spectral_spectrum(f, jit.cos_theta(light) / dr.select(active, pdf, 1.0), active, si)
        f_cos = f * jit.cos_theta(light)
        weight = f_cos / dr.select(active, pdf, 1.0)
        # As sampling/mod.rs sample_weight: 0 where a tiny pdf would overflow the quotient.
        weight = dr.select(active & dr.all(dr.isfinite(weight)), weight, 0.0)
        return bs, _to_spectrum(weight, si)

    def _eval(self, si, wo, active):
        f = self.traced.eval(si.wi, wo)
        if self.spectral is not None:
            return self._spectral_spectrum(f, jit.cos_theta(wo), _both_above(active, si.wi, wo), si)
        return _to_spectrum(dr.select(_both_above(active, si.wi, wo), f * jit.cos_theta(wo), 0.0), si)

    def _pdf(self, si, wo, active):
        pdf = jit.pdf(self.sampling, si.wi, wo, *self.lobes, self.table)
        return dr.select(_both_above(active, si.wi, wo), pdf, 0.0)

    def _spectral_spectrum(self, coefficients, scale, active, si):
        """A spectral material's value (its B-spline coefficients) times ``scale`` as the
        variant's spectrum, 0 where not ``active`` or not finite: per wavelength in spectral
        variants (no uplift: the network is spectral), the sRGB projection ``M c`` in RGB
        variants and its luminance in monochrome ones (as ``_to_spectrum`` does for RGB
        values); polarized variants get the depolarizer times the value."""
        _, min_nm, max_nm, matrix = self.spectral
        if mi.is_spectral:
            value = jit.spectral_value(coefficients, si.wavelengths, min_nm, max_nm) * scale
        else:
            value = jit.srgb_projection(coefficients, matrix) * scale
            value = mi.luminance(value) if mi.is_monochromatic else value
        # A Spectrum before dr.all: on a flat Float (mono) it would reduce over the lanes.
        value = mi.UnpolarizedSpectrum(value)
        value = mi.UnpolarizedSpectrum(dr.select(active & dr.all(dr.isfinite(value)), value, 0.0))
        return mi.depolarizer(value) if mi.is_polarized else value


# --------------------------------------------------------------------------------------------
# The library's backend


class RustBackend:
    """The native library (``_native.Material`` ``native``, with the sampler of the validated
    parameters) on planar arrays made by ``arrays``. Native code cannot run while Dr.Jit records
    a symbolic loop or call; there it evaluates ``twin`` (a :class:`JitBackend`, the same math,
    held to the library by tests/test_backends.py) and says so once, or, without a twin, raises
    saying why (``twin_refused``). ``label`` names the BSDF in messages."""

    name = "rust"

    def __init__(self, native, spectral, arrays: _Arrays, twin: JitBackend | None, label: str,
                 twin_refused: str | None):
        self.native = native
        self.spectral = spectral
        self.arrays = arrays
        self.twin = twin
        self.label = label
        self.twin_refused = twin_refused
        self.sampler = None
        self.warned_twin = False

    def use(self, sampler, lobes) -> None:
        """Samples with the library's ``sampler`` (made from the validated ``lobes``)."""
        self.sampler = sampler
        if self.twin is not None:
            self.twin.use(sampler, lobes)

    @property
    def table(self):
        """The twin's traced table of ``tabulated`` sampling (None without)."""
        return None if self.twin is None else self.twin.table

    def eval(self, ctx, si, wo, active=True):
        if self._in_symbolic_scope(si.wi, wo):
            return self.twin.eval(ctx, si, wo, active)
        if not self._enabled(ctx, si.wi, wo):
            return self.arrays.zero_spectrum(self.arrays.width(si.wi, wo))
        view, light = self._directions(si.wi, wo)
        return self._spectrum(view, light, _both_above(active, si.wi, wo), si)

    def pdf(self, ctx, si, wo, active=True):
        if self._in_symbolic_scope(si.wi, wo):
            return self.twin.pdf(ctx, si, wo, active)
        if not self._enabled(ctx, si.wi, wo):
            return dr.zeros(mi.Float, self.arrays.width(si.wi, wo))
        view, light = self._directions(si.wi, wo)
        pdf = self.arrays.float_(self.sampler.pdf(view, light))
        return dr.select(_both_above(active, si.wi, wo), pdf, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        if self._in_symbolic_scope(si.wi, wo):
            return self.twin.eval_pdf(ctx, si, wo, active)
        if not self._enabled(ctx, si.wi, wo):
            n = self.arrays.width(si.wi, wo)
            return self.arrays.zero_spectrum(n), dr.zeros(mi.Float, n)
        view, light = self._directions(si.wi, wo)
        pdf = self.arrays.float_(self.sampler.pdf(view, light))
        active = _both_above(active, si.wi, wo)
        return self._spectrum(view, light, active, si), dr.select(active, pdf, 0.0)

    def sample(self, ctx, si, sample1, sample2, active=True):
        if self._in_symbolic_scope(si.wi, sample1, sample2):
            return self.twin.sample(ctx, si, sample1, sample2, active)
        arrays = self.arrays
        n = arrays.width(si.wi, sample1, sample2)
        bs = arrays.empty_sample(n)
        if not self._enabled(ctx, si.wi, sample1, sample2):
            return bs, arrays.zero_spectrum(n)
        arrays.evaluate(si.wi, sample1, sample2)
        view = arrays.planar([si.wi.x, si.wi.y, si.wi.z], n)
        u = arrays.planar([sample1, sample2.x, sample2.y], n)
        light, weight, pdf = self.native.sample(self.sampler, view, u)
        bs.wo = arrays.vector(light)
        bs.pdf = arrays.float_(pdf)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        active = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (bs.pdf > 0)
        bs.pdf = dr.select(active, bs.pdf, 0.0)
        # The library's weight is RGB; a spectral network in a spectral variant is evaluated
        # again at the sampled direction and the lane's wavelengths.
        return bs, self._spectrum(view, light, active, si, weight, pdf)

    def _in_symbolic_scope(self, *values) -> bool:
        """Whether this call is recorded in a symbolic loop or call, where it goes to the twin.
        Dr.Jit's flags are per thread and plugins are built on worker threads, so a rust-backed
        BSDF cannot count on wavefront mode."""
        if not self.arrays.wavefront or self.arrays.width(*values) == 0:
            return False
        if not dr.flag(dr.JitFlag.SymbolicScope):
            return False
        if self.twin is None:
            raise RuntimeError(
                f"{self.label}: called inside a symbolic Dr.Jit loop or call, "
                f"where the rust backend cannot run and the traced one is refused "
                f"({self.twin_refused}). Render in wavefront mode: call "
                "nbrdf_mitsuba.use_wavefront_mode() on the rendering thread before rendering")
        if not self.warned_twin:
            self.warned_twin = True
            mi.Log(mi.LogLevel.Warn,
                   f'{self.label}: backend "rust" called inside a symbolic '
                   "Dr.Jit loop or call (wavefront mode is off on this thread); evaluating its traced "
                   "twin instead. For the reference library, call nbrdf_mitsuba.use_wavefront_mode() "
                   "on the rendering thread before rendering")
        return True

    def _enabled(self, ctx, *values) -> bool:
        """Whether there is anything to compute: the glossy lobe is selected and, in JIT
        variants, the wavefront is not empty (Dr.Jit cannot broadcast literals to width 0)."""
        if not _glossy(ctx):
            return False
        return self.arrays.width(*values) > 0

    def _directions(self, wi, wo) -> tuple[np.ndarray, np.ndarray]:
        """Planar (3, n) float32 copies of the view (``si.wi``) and light (``wo``) directions."""
        n = self.arrays.width(wi, wo)
        self.arrays.evaluate(wi, wo)  # one kernel for both
        return self.arrays.planar([wi.x, wi.y, wi.z], n), self.arrays.planar([wo.x, wo.y, wo.z], n)

    def _spectrum(self, view, light, active, si, weight=None, pdf=None):
        """The library's ``f_r cos`` at planar directions (or a sample's ``weight`` with its
        ``pdf``) as the variant's spectrum, 0 where not ``active``: a spectral network in a
        spectral variant at the lane's wavelengths (:meth:`_spectral_value`), anything else the
        library's RGB value."""
        if self.spectral is None or not mi.is_spectral:
            value = self.arrays.color(self.native.eval(view, light) if weight is None else weight)
            return _to_spectrum(dr.select(active, value, 0.0), si)
        return self._spectral_value(view, light, active, si, pdf)

    def _spectral_value(self, view, light, active, si, pdf=None, uv=None):
        """A spectral material's ``f_r cos`` at planar directions (and, for a spatially varying
        one, planar texture coordinates ``uv``) evaluated at the lane's wavelengths
        (``eval_spectral``; no uplift) as the variant's spectrum, 0 where not ``active``; divided
        by ``pdf`` when given (0 where the quotient is not finite, as ``sampling/mod.rs``
        sample_weight)."""
        wavelengths = [si.wavelengths[j] for j in range(len(si.wavelengths))]
        values = self.native.eval_spectral(view, light, self.arrays.planar(wavelengths, view.shape[1]), uv=uv)
        if pdf is not None:
            with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
                values = np.where(pdf > 0, values / np.where(pdf > 0, pdf, 1.0), 0.0)
            values = np.where(np.all(np.isfinite(values), axis=0), values, 0.0).astype(np.float32)
        value = mi.UnpolarizedSpectrum(dr.select(active, self.arrays.wavelengths(values), 0.0))
        return mi.depolarizer(value) if mi.is_polarized else value
