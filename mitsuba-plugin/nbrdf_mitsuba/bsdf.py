"""The Mitsuba BSDF plugins ``nbrdf`` (a neural BRDF, ``*.nbrdf.json``) and ``merl`` (a
MERL-format ``.binary`` table).

Mitsuba's ``BSDF`` base class differs per variant, so :func:`classes` builds the two plugin
classes for the current variant from the variant-independent mixins below. RGB variants only.

Two backends (parameter ``backend``):

* ``jit`` (default in JIT variants): the network, the table lookup and the Blinn-Phong mixture
  written as Dr.Jit arithmetic (:mod:`nbrdf_mitsuba.jit`), traced into Mitsuba's own kernels.
  Symbolic loops and calls stay on; it runs at Mitsuba's full speed, on LLVM and CUDA alike.
* ``rust`` (default in scalar variants, the reference): the native library evaluates whole
  wavefronts on the host. Directions are evaluated (``dr.eval``), copied to NumPy in Dr.Jit's
  planar (3, N) layout, handed to the library, and copied back. That cannot happen while Dr.Jit
  records a symbolic loop or call, so in JIT variants this backend needs wavefront mode (see
  :func:`use_wavefront_mode`). Outputs are not differentiable.
"""

from __future__ import annotations

import json

import drjit as dr
import mitsuba as mi
import numpy as np

from . import _llvm, _native, jit

SAMPLING_NAMES = tuple(_native.SAMPLING_KINDS)
BACKENDS = ("auto", "jit", "rust")
# How the traced backend puts the weights into kernels: "literal" constants (fastest renders;
# one compile per scene, an update recompiles) or "opaque" kernel parameters (updates without
# recompiling, gradients flow to the weights; a few to 15 % slower).
JIT_WEIGHT_MODES = ("literal", "opaque")
_default_backend = "auto"


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

    Only the ``rust`` backend needs this. Mitsuba's ``direct`` integrator records the BSDF call
    symbolically (needs SymbolicCalls off); ``path`` also runs the bounce loop symbolically
    (needs SymbolicLoops off as well). Dr.Jit's flags are per thread and Mitsuba may construct
    plugins on a scene-loading thread, so constructing a ``rust``-backed BSDF switches them on
    the constructing thread, and a render on another thread must call this first (a BSDF called
    inside a symbolic scope raises an error that says so). Returns the flags switched off.
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


def _require_wavefront(type_name: str) -> None:
    if dr.flag(dr.JitFlag.SymbolicScope):
        raise RuntimeError(
            f"{type_name}: called inside a symbolic Dr.Jit loop or call, but the BSDF evaluates "
            "native code on host arrays. Render with wavefront mode on the rendering thread: "
            "dr.set_flag(dr.JitFlag.SymbolicLoops, False); dr.set_flag(dr.JitFlag.SymbolicCalls, "
            "False) (nbrdf_mitsuba.use_wavefront_mode() does this on the calling thread), or use "
            'the traced backend: <string name="backend" value="jit"/>'
        )


# --------------------------------------------------------------------------------------------
# Marshalling between Mitsuba values and planar float32 arrays


def _is_jit() -> bool:
    return dr.is_jit_v(mi.Float)


def _width(*values) -> int:
    return max(dr.width(v) for v in values)


def _planar(values, n: int) -> np.ndarray:
    """(k, n) float32 array of k Dr.Jit values of width 1 or n (already evaluated)."""
    if _is_jit():
        rows = [np.asarray(dr.detach(v).numpy(), dtype=np.float32).reshape(-1) for v in values]
    else:
        rows = [np.asarray([v], dtype=np.float32) for v in values]
    return np.ascontiguousarray(np.stack([np.broadcast_to(r, (n,)) for r in rows]))


def _vector_rows(v) -> list:
    return [v.x, v.y, v.z]


def _to_color(rgb: np.ndarray):
    if _is_jit():
        return mi.Color3f(rgb)
    return mi.Color3f(float(rgb[0, 0]), float(rgb[1, 0]), float(rgb[2, 0]))


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
    """Shared implementation; subclasses set PLUGIN and implement _load/_default_sampling."""

    PLUGIN = ""  # the Mitsuba plugin name

    def _init_native(self, props) -> None:
        mi.BSDF.__init__(self, props)
        if not mi.is_rgb or mi.is_polarized:
            raise RuntimeError(f"{self._type_name()}: only RGB variants are supported (the current variant is "
                               f"{mi.variant()}; use e.g. scalar_rgb or llvm_ad_rgb)")
        flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        self.m_components = [flags]
        self.m_flags = flags

        filename = _get(props, "filename")
        if not filename:
            raise ValueError(f'{self._type_name()}: the "filename" parameter is required '
                             f'(e.g. <string name="filename" value="..."/>)')
        self._filename = str(filename)
        path = _resolve(self._filename)
        try:
            self._native = self._load(path)
        except _native.NbrdfError as error:
            raise RuntimeError(f'{self._type_name()}: cannot load "{path}": {_strip_function(error)} '
                               f"[{error.status_name}]") from None
        self._path = path

        sampling = _get(props, "sampling")
        exponent = _get(props, "exponent")
        weight = _get(props, "specular_weight")
        self._configure_sampling(sampling, exponent, weight)
        self._backend = self._choose_backend(_get(props, "backend", _default_backend))

        if _is_jit():
            if mi.variant().startswith("llvm"):
                try:
                    _llvm.check_backend()
                except RuntimeError as error:
                    raise RuntimeError(f"{self._type_name()}: {error}") from None
            if self._backend == "rust":
                use_wavefront_mode(f'{self.PLUGIN} BSDF "{self._filename}" with backend "rust"')
            else:
                self._traced = self._trace(path)

    def _choose_backend(self, backend) -> str:
        backend = str(backend).strip().lower()
        if backend not in BACKENDS:
            raise ValueError(f'{self._type_name()} "{self._filename}": unknown backend "{backend}" '
                             f"(expected one of: {', '.join(BACKENDS)})")
        if backend == "auto":
            return "jit" if _is_jit() else "rust"
        if backend == "jit" and not _is_jit():
            raise ValueError(f'{self._type_name()} "{self._filename}": backend "jit" needs a JIT '
                             f"variant (llvm_* or cuda_*); {mi.variant()} uses the rust backend")
        return backend

    # -- configuration ------------------------------------------------------------------------

    def _type_name(self) -> str:
        return f'{type(self).__name__} (plugin "{self.PLUGIN}")'

    def _configure_sampling(self, sampling, exponent, weight) -> None:
        if sampling is None:
            sampling = self._default_sampling(exponent, weight)
        sampling = str(sampling).strip().lower()
        if sampling not in SAMPLING_NAMES:
            raise ValueError(f'{self._type_name()} "{self._filename}": unknown sampling "{sampling}" '
                             f"(expected one of: {', '.join(SAMPLING_NAMES)})")
        exponent, weight = self._phong_parameters(sampling, exponent, weight)
        self._sampling = sampling
        self._set_sampler(exponent, weight)
        self.exponent = _parameter(exponent)
        self.specular_weight = _parameter(weight)
        if _is_jit():
            # Kernel parameters rather than constants: new values do not recompile kernels.
            dr.make_opaque(self.exponent, self.specular_weight)

    def _phong_parameters(self, sampling, exponent, weight) -> tuple[float, float]:
        """(exponent, weight) with file defaults applied; errors when phong lacks them."""
        if sampling == "phong" and (exponent is None or weight is None):
            raise ValueError(f'{self._type_name()} "{self._filename}": sampling "phong" needs '
                             '"exponent" and "specular_weight"')
        return _as_float(self, "exponent", exponent, 0.0), _as_float(self, "specular_weight", weight, 0.0)

    def _set_sampler(self, exponent: float, weight: float) -> None:
        try:
            self._sampler = _native.sampler(self._sampling, exponent, weight)
        except _native.NbrdfError as error:
            raise ValueError(f'{self._type_name()} "{self._filename}": invalid sampling parameters: '
                             f"{_strip_function(error)}") from None
        self._exponent_value, self._weight_value = exponent, weight

    # -- Mitsuba interface --------------------------------------------------------------------

    # -- traced backend -----------------------------------------------------------------------

    def _jit_eval(self, si, wo, active):
        f = self._traced.eval(si.wi, wo)
        return dr.select(_both_above(active, si.wi, wo), f * mi.Frame3f.cos_theta(wo), 0.0)

    def _jit_pdf(self, si, wo, active):
        pdf = jit.pdf(self._sampling, si.wi, wo, self.exponent, self.specular_weight)
        return dr.select(_both_above(active, si.wi, wo), pdf, 0.0)

    def _jit_sample(self, ctx, si, sample1, sample2, active):
        bs = dr.zeros(mi.BSDFSample3f)
        light, pdf = jit.sample(self._sampling, si.wi, sample1, sample2.x, sample2.y,
                                self.exponent, self.specular_weight)
        active = active & ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
        active = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (pdf > 0)
        bs.wo = light
        bs.pdf = dr.select(active, pdf, 0.0)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        f_cos = self._traced.eval(si.wi, light) * mi.Frame3f.cos_theta(light)
        weight = dr.select(active, f_cos / dr.select(active, pdf, 1.0), 0.0)
        return bs, weight

    # -- Mitsuba interface --------------------------------------------------------------------

    def eval(self, ctx, si, wo, active=True):
        if self._backend == "jit" and _width(si.wi, wo) > 0:
            enabled = ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
            return self._jit_eval(si, wo, active & enabled)
        if not self._enabled(ctx, si.wi, wo):
            return dr.zeros(mi.Color3f, _width(si.wi, wo) if _is_jit() else 1)
        _require_wavefront(self._type_name())
        view, light = _directions(si.wi, wo)
        value = _to_color(self._native.eval(view, light))
        return dr.select(_both_above(active, si.wi, wo), value, 0.0)

    def pdf(self, ctx, si, wo, active=True):
        if self._backend == "jit" and _width(si.wi, wo) > 0:
            return self._jit_pdf(si, wo, active & ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0))
        if not self._enabled(ctx, si.wi, wo):
            return dr.zeros(mi.Float, _width(si.wi, wo) if _is_jit() else 1)
        _require_wavefront(self._type_name())
        view, light = _directions(si.wi, wo)
        pdf = _to_float(_native.pdf(self._sampler, view, light))
        return dr.select(_both_above(active, si.wi, wo), pdf, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        if self._backend == "jit" and _width(si.wi, wo) > 0:
            active = active & ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
            return self._jit_eval(si, wo, active), self._jit_pdf(si, wo, active)
        if not self._enabled(ctx, si.wi, wo):
            n = _width(si.wi, wo) if _is_jit() else 1
            return dr.zeros(mi.Color3f, n), dr.zeros(mi.Float, n)
        _require_wavefront(self._type_name())
        view, light = _directions(si.wi, wo)
        value = _to_color(self._native.eval(view, light))
        pdf = _to_float(_native.pdf(self._sampler, view, light))
        active = _both_above(active, si.wi, wo)
        return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)

    def sample(self, ctx, si, sample1, sample2, active=True):
        if self._backend == "jit" and _width(si.wi, sample1, sample2) > 0:
            return self._jit_sample(ctx, si, sample1, sample2, active)
        n = _width(si.wi, sample1, sample2) if _is_jit() else 1
        bs = dr.zeros(mi.BSDFSample3f, n) if _is_jit() else mi.BSDFSample3f()
        if not self._enabled(ctx, si.wi, sample1, sample2):
            return bs, dr.zeros(mi.Color3f, n) if _is_jit() else mi.Color3f(0.0)
        _require_wavefront(self._type_name())
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
        return bs, dr.select(active, _to_color(weight), 0.0)

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
        if self._backend == "jit":
            self._traverse_traced(put)

    def parameters_changed(self, keys=None):
        """Re-validates the sampling parameters; invalid ones raise and leave the previous
        (valid) sampler in use."""
        if self._backend == "jit":
            self._traced_changed(keys)
        exponent = _scalar(self.exponent)
        weight = _scalar(self.specular_weight)
        if (exponent, weight) == (self._exponent_value, self._weight_value):
            return
        try:
            self._set_sampler(exponent, weight)
        except ValueError:
            self.exponent = _parameter(self._exponent_value)
            self.specular_weight = _parameter(self._weight_value)
            raise
        if _is_jit():
            dr.make_opaque(self.exponent, self.specular_weight)
        if self._sampling != "phong":
            mi.Log(mi.LogLevel.Warn, f'{self._type_name()} "{self._filename}": exponent and '
                                     f'specular_weight only affect sampling "phong" (this BSDF '
                                     f'uses "{self._sampling}")')

    def to_string(self):
        lines = [f'filename = "{self._filename}"', *self._describe(), f"backend = {self._backend}",
                 f"sampling = {self._sampling}"]
        if self._sampling == "phong":
            lines += [f"exponent = {self._exponent_value:g}", f"specular_weight = {self._weight_value:g}"]
        return f"{type(self).__name__}[\n" + ",\n".join("  " + line for line in lines) + "\n]"


class NbrdfMixin(_NativeBSDFMixin):
    """``nbrdf``: a neural BRDF from an ``*.nbrdf.json`` file.

    Parameters: ``filename``; ``sampling`` = ``phong`` (default when the file stores Blinn-Phong
    parameters) | ``cosine`` (default otherwise) | ``uniform``; ``exponent`` and
    ``specular_weight`` override the stored Blinn-Phong parameters.
    """

    PLUGIN = "nbrdf"

    def __init__(self, props):
        self._props_jit_weights = _get(props, "jit_weights", "literal")
        self._init_native(props)

    def _load(self, path):
        return _native.Network(path)

    def _trace(self, path):
        # The library has validated the file; its layers are plain JSON.
        with open(path, encoding="utf-8") as file:
            layers = json.load(file)["layers"]
        mode = str(self._props_jit_weights).strip().lower()
        if mode not in JIT_WEIGHT_MODES:
            raise ValueError(f'{self._type_name()} "{self._filename}": unknown jit_weights "{mode}" '
                             f"(expected one of: {', '.join(JIT_WEIGHT_MODES)})")
        return jit.TracedNetwork([
            (np.asarray(layer["weights"], dtype=np.float32).reshape(layer["inputs"], layer["outputs"]),
             np.asarray(layer["bias"], dtype=np.float32)) for layer in layers
        ], weights=mode)

    def _traverse_traced(self, put):
        # The network's 675 (for width 21) weights, W1 b1 W2 b2 W3 b3, updatable through
        # params.update(). Only kernel parameters ("opaque") carry gradients; literals are
        # constants of the kernel, and an update recompiles it.
        differentiable = self._traced.mode == "opaque"
        put("weights", self._traced.flat,
            mi.ParamFlags.Differentiable if differentiable else mi.ParamFlags.NonDifferentiable)

    def _traced_changed(self, keys):
        if keys is None or any(str(key).endswith("weights") for key in keys):
            if dr.width(self._traced.flat) != self._traced.parameter_count:
                raise ValueError(f'{self._type_name()} "{self._filename}": "weights" must hold '
                                 f"{self._traced.parameter_count} values")
            self._traced.refresh()

    def _default_sampling(self, exponent, weight) -> str:
        if self._native.has_sampling or (exponent is not None and weight is not None):
            return "phong"
        return "cosine"

    def _phong_parameters(self, sampling, exponent, weight):
        if self._native.has_sampling:
            exponent = self._native.exponent if exponent is None else exponent
            weight = self._native.specular_weight if weight is None else weight
        return _NativeBSDFMixin._phong_parameters(self, sampling, exponent, weight)

    def _describe(self) -> list[str]:
        net = self._native
        lines = [f'name = "{net.name}"', f"hidden_width = {net.hidden_width}",
                 f"parameter_count = {net.parameter_count}"]
        if self._backend == "jit":
            lines.append(f"jit_weights = {self._traced.mode}")
        return lines


class MerlMixin(_NativeBSDFMixin):
    """``merl``: a MERL-format table (``.binary``), trilinearly interpolated.

    Parameters: ``filename``; ``sampling`` = ``cosine`` (default) | ``uniform`` | ``phong``
    (requires ``exponent`` and ``specular_weight``).
    """

    PLUGIN = "merl"

    def __init__(self, props):
        self._init_native(props)

    def _load(self, path):
        return _native.MerlTable(path)

    def _trace(self, path):
        # The library has validated size, header and values.
        stored = np.fromfile(path, dtype="<f8", offset=12)
        return jit.TracedMerl(stored)

    def _traverse_traced(self, put):
        pass

    def _traced_changed(self, keys):
        pass

    def _default_sampling(self, exponent, weight) -> str:
        return "phong" if exponent is not None and weight is not None else "cosine"

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


def _scalar(value) -> float:
    if isinstance(value, (int, float)):
        return float(value)
    array = np.asarray(value.numpy() if _is_jit() else value, dtype=np.float64).reshape(-1)
    if array.size != 1:
        raise ValueError(f"expected a single value, got {array.size}")
    return float(array[0])


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
