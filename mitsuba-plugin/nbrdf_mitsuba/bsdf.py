"""The Mitsuba BSDF plugins ``nbrdf`` (a neural BRDF, ``*.nbrdf.json``, or a spatially varying
material of format version 4: :mod:`nbrdf_mitsuba.textured`) and ``merl`` (a MERL-format
``.binary`` table).

Mitsuba's ``BSDF`` base class differs per variant, so :func:`classes` builds the two plugin
classes for the current variant from the variant-independent mixins below. Every variant: RGB,
monochrome, spectral (the RGB value uplifted per wavelength as Mitsuba uplifts unbounded RGB data)
and polarized (see :mod:`nbrdf_mitsuba.backends`).

Two backends (parameter ``backend``), chosen once when the BSDF is built; its ``eval``, ``pdf``,
``eval_pdf`` and ``sample`` are the backend's (:mod:`nbrdf_mitsuba.backends`): ``jit`` (default in
JIT variants; the traced twin, :mod:`nbrdf_mitsuba.jit`, in Mitsuba's own kernels) and ``rust``
(default in scalar variants, the reference: the native library; in JIT variants it runs in
wavefront mode, :func:`use_wavefront_mode`, and inside symbolic scopes evaluates its traced twin).

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

import drjit as dr
import mitsuba as mi
import numpy as np

from . import _native, base, jit, textured
from ._native import KIND
from .backends import JitBackend, RustBackend, prepare_variant, use_wavefront_mode, variant_arrays
from .freezing import JitState
from .parameters import SAMPLING_NAMES, SamplingParameters
from .validation import format_problem, non_finite_name, special_file_problem, strip_function

BACKENDS = ("auto", "jit", "rust")
# How the traced backend puts the weights into kernels: "literal" constants (fastest renders;
# one compile per network, an update recompiles), "opaque" kernel parameters (updates without
# recompiling, gradients flow to the weights; one kernel shared by every network of a shape) or
# "auto" (the default: literals for a few live networks, the shared kernel for more, so that a
# scene of hundreds of materials compiles once; jit.network.AUTO_LITERAL_MAX).
JIT_WEIGHT_MODES = jit.WEIGHT_MODES
_default_backend = "auto"
#: Widest hidden layer the traced backend takes. Its kernels unroll the network into straight-line
#: code, so tracing and compiling grow with width^2. Wider networks go to the Rust backend
#: (``auto``, with a warning) or are refused (``jit``). Measured: docs/results/performance.md,
#: "Traced backend: hidden width".
JIT_MAX_HIDDEN_WIDTH = 40
MAX_EXPONENT = jit.MAX_EXPONENT


def set_default_backend(backend: str) -> str:
    """The backend of BSDFs whose scene omits ``backend`` (``auto`` unless changed); returns
    the previous one. ``rust`` renders a whole scene through the reference library."""
    global _default_backend
    backend = str(backend).strip().lower()
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend '{backend}' (expected one of: {', '.join(BACKENDS)})")
    previous, _default_backend = _default_backend, backend
    return previous


def _get(props, key, default=None):
    try:
        present = key in props
    except TypeError:  # Mitsuba < 3.7: no __contains__
        present = props.has_property(key)
    return props[key] if present else default


def _resolve(filename: str) -> str:
    resolver = mi.file_resolver() if hasattr(mi, "file_resolver") else mi.Thread.thread().file_resolver()
    return str(resolver.resolve(filename))


# --------------------------------------------------------------------------------------------
# The plugins (variant-independent part)


class _NativeBSDFMixin(SamplingParameters):
    """Shared implementation (the lobe parameters and their updates: :mod:`.parameters`);
    subclasses set PLUGIN and MATERIAL_KIND and implement _default_sampling."""

    PLUGIN = ""  # the Mitsuba plugin name
    MATERIAL_KIND = ""  # what the library must load (a key of _native.MATERIAL_KINDS)
    TEXTURED = False  # whether the plugin also takes spatially varying materials
    _textured = None  # their state (textured.TexturedMaterial), for such a file

    def _init_native(self, props) -> None:
        mi.BSDF.__init__(self, props)
        #: Dr.Jit's frozen functions find this BSDF's arrays through it (:mod:`.freezing`).
        self._jit_state = JitState(self.__dict__, self._type_name())
        #: How this variant's values become the library's arrays (one direction or wavefronts).
        self._arrays = variant_arrays()
        #: The traced network or table (JIT variants, unless too wide for the traced backend).
        self._traced = None
        #: The library's tabulated sampler, built once (``tabulated`` sampling only).
        self._table = None
        #: The last good value of whichever of exponent2 / exponent_v this sampling ignores.
        self._unused_second = 0.0
        filename = _get(props, "filename")
        if not filename:
            raise ValueError(f'{self._type_name()}: the "filename" parameter is required '
                             f'(e.g. <string name="filename" value="..."/>)')
        self._filename = str(filename)
        path = _resolve(self._filename)
        special = special_file_problem(path)
        if special:
            raise RuntimeError(f'{self._type_name()}: cannot load "{path}": {special} [NBRDF_ERROR_IO]')
        # The library reads the file once; the plugin looks into it only to explain a failure.
        try:
            self._native = _native.Material(path)
        except _native.NbrdfError as error:
            problem = format_problem(path, self.PLUGIN)
            if problem:
                raise RuntimeError(f'{self._type_name()}: cannot load "{path}": {problem} '
                                   f"[NBRDF_ERROR_FORMAT]") from None
            message = strip_function(error)
            # Library messages name the file already: say it once.
            where = "" if path in message else f'"{path}": '
            raise RuntimeError(f"{self._type_name()}: cannot load {where}{message} "
                               f"[{error.status_name}]") from None
        if self.TEXTURED and self._native.kind == "textured":
            self._path = path
            textured.TexturedMaterial(self, lambda key: _get(props, key), _get(props, "backend", _default_backend),
                                      self._props_jit_weights)
            return
        problem = None
        if self._native.kind != self.MATERIAL_KIND:
            problem = format_problem(path, self.PLUGIN) or (
                f"the library read it as a {self._native.kind} material, not a {self.MATERIAL_KIND} one")
        if problem:
            raise RuntimeError(f'{self._type_name()}: cannot load "{path}": {problem} [NBRDF_ERROR_FORMAT]')
        self._path = path
        self._spectral = self._spectral_output()
        flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        if self._native.anisotropic:
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
        self._backend = self._make_backend(_get(props, "backend", _default_backend))
        if self._native.base is not None:
            self._add_base(self._native.base)

    def _add_base(self, dictionary: dict) -> None:
        """Puts the file's analytic base under the network (:mod:`.base`): the BSDF is their sum."""
        label = f'{self._type_name()} "{self._filename}"'
        bsdf = base.load_base(dictionary, label)
        layers, _ = self._native.network(prove=False)
        W, b = layers[-1]  # network_is_zero reads the tail of the flat weights: the last layer
        flat = np.concatenate([W.ravel(), b.ravel()])
        differentiable = self._traced is not None and self._traced.mode == "opaque"
        self._backend = base.OnBase(self._backend, bsdf, base.network_is_zero(flat, self._native.layer_shapes[-1]),
                                    differentiable)
        self.m_flags = self.m_flags | bsdf.flags()
        self.m_components = [self.m_flags]

    def _make_backend(self, requested) -> JitBackend | RustBackend:
        """The backend object that evaluates and samples this BSDF from now on."""
        name = self._choose_backend(requested)
        twin = None
        prepare_variant(self._arrays, self._type_name())
        if self._arrays.wavefront:
            # The rust backend keeps a traced twin for symbolic scopes: Dr.Jit traces a symbolic
            # call through every live BSDF, wherever it was built, and native code cannot run
            # there (see RustBackend).
            if name == "jit" or not self._traced_width_problem():
                self._traced = self._trace(self._path, None if name == "jit" else "literal")
                twin = JitBackend(self._traced, self._spectral, self._sampling)
        if name == "jit":
            backend = twin
        else:
            backend = RustBackend(self._native, self._spectral, self._arrays, twin,
                                  f'{self._type_name()} "{self._filename}"',
                                  self._traced_width_problem() if twin is None else None)
        backend.use(self._sampler, self._lobes)
        return backend

    def _choose_backend(self, backend) -> str:
        backend = str(backend).strip().lower()
        if backend not in BACKENDS:
            raise ValueError(f'{self._type_name()} "{self._filename}": unknown backend "{backend}" '
                             f"(expected one of: {', '.join(BACKENDS)})")
        if backend == "jit" and not self._arrays.wavefront:
            raise ValueError(f'{self._type_name()} "{self._filename}": backend "jit" needs a JIT '
                             f"variant (llvm_* or cuda_*); {mi.variant()} uses the rust backend")
        too_wide = self._traced_width_problem() if self._arrays.wavefront else None
        if backend == "auto":
            if too_wide:
                mi.Log(mi.LogLevel.Warn, f'{self._type_name()} "{self._filename}": {too_wide}; using '
                                         'the rust backend, which needs wavefront mode on the rendering '
                                         "thread (nbrdf_mitsuba.use_wavefront_mode())")
                return "rust"
            return "jit" if self._arrays.wavefront else "rust"
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

    def _type_name(self) -> str:
        return f'{type(self).__name__} (plugin "{self.PLUGIN}")'

    # -- Mitsuba interface --------------------------------------------------------------------

    def eval(self, ctx, si, wo, active=True):
        return self._backend.eval(ctx, si, wo, active)

    def pdf(self, ctx, si, wo, active=True):
        return self._backend.pdf(ctx, si, wo, active)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self._backend.eval_pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        return self._backend.sample(ctx, si, sample1, sample2, active)

    def traverse(self, callback):
        # Mitsuba types (not Python floats) so that SceneParameters can update them in place.
        put = getattr(callback, "put", None) or callback.put_parameter
        if self._textured is not None:
            return self._textured.traverse(put)
        put("exponent", self.exponent, mi.ParamFlags.NonDifferentiable)
        put("specular_weight", self.specular_weight, mi.ParamFlags.NonDifferentiable)
        put("exponent2", self.exponent2, mi.ParamFlags.NonDifferentiable)
        put("exponent_v", self.exponent_v, mi.ParamFlags.NonDifferentiable)
        put("specular_weight2", self.specular_weight2, mi.ParamFlags.NonDifferentiable)
        if self._backend.name == "jit":
            self._traverse_traced(put)

    def to_string(self):
        if self._textured is not None:
            return self._textured.to_string(type(self).__name__)
        exponent, weight, exponent2, weight2 = self._lobes
        lines = [f'filename = "{self._filename}"', *self._describe(), f"backend = {self._backend.name}",
                 f"sampling = {self._sampling}"]
        if self._sampling in (KIND.phong, KIND.two_lobe, KIND.anisotropic_phong):
            lines += [f"exponent = {exponent:g}", f"specular_weight = {weight:g}"]
        if self._sampling == KIND.anisotropic_phong:
            lines += [f"exponent_v = {exponent2:g}"]
        if self._sampling == KIND.two_lobe:
            lines += [f"exponent2 = {exponent2:g}", f"specular_weight2 = {weight2:g}"]
        return f"{type(self).__name__}[\n" + ",\n".join("  " + line for line in lines) + "\n]"


class NbrdfMixin(_NativeBSDFMixin):
    """``nbrdf``: a neural BRDF from an ``*.nbrdf.json`` file (a spatially varying file, format
    version 4, goes to :class:`nbrdf_mitsuba.textured.TexturedMaterial`, which takes ``filename``,
    ``backend`` and ``jit_weights`` only).

    Parameters: ``filename``; ``sampling`` = the file's ``sampling.default`` when it names one
    (the strategy ``nbrdf fit-phong`` measured with the lowest variance) | ``tabulated`` (a
    half-vector table built from the network at load time) | ``two_lobe`` (default when the
    file stores two Blinn-Phong lobes) | ``anisotropic_phong`` (default when it stores an
    anisotropic lobe, ``sampling.exponent_v``; ``exponent`` is then ``n_u`` and ``exponent_v``
    ``n_v``) | ``phong`` (default when it stores one; with a two-lobe file, its first lobe) |
    ``cosine`` (default otherwise) | ``uniform``; ``exponent``, ``specular_weight``,
    ``exponent2``, ``specular_weight2`` and ``exponent_v`` override the stored lobes (the network's
    strategy; a file with an analytic ``base`` is the sum of the two, :mod:`nbrdf_mitsuba.base`).
    """

    PLUGIN = "nbrdf"
    MATERIAL_KIND = "network"
    TEXTURED = True

    def __init__(self, props):
        self._props_jit_weights = _get(props, "jit_weights", "auto")
        self._init_native(props)

    def parameters_changed(self, keys=None):
        if self._textured is not None:
            return self._textured.parameters_changed(keys)
        return SamplingParameters.parameters_changed(self, keys)

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

    @property
    def traced_network(self):
        """The network as traced into Mitsuba's kernels (a :class:`jit.TracedNetwork`) where the
        ``jit`` backend evaluates it, else None: an estimate records its adjoints there
        (:mod:`nbrdf_mitsuba.jit.adjoints`)."""
        return self._traced if self._textured is None and self._backend.name == "jit" else None

    def _traverse_traced(self, put):
        # The network's weights, W1 b1 W2 b2 W3 b3, updatable through params.update(). Only
        # "opaque" weights carry gradients; literals are constants of the kernel, and an update
        # recompiles it ("auto": literal or shared-kernel parameters, no gradients, so that its
        # kernels never depend on whether gradients are on).
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
                             f"{non_finite_name(values[k])}; {bad.size} of {values.size} weights are "
                             "not finite (every weight must be a finite float32)")
        return values  # refreshed even when equal: enabling gradients marks the key as changed

    def _apply_weights(self, weights) -> None:
        self._traced.refresh()
        if isinstance(self._backend, base.OnBase):
            self._backend.network_changed(base.network_is_zero(weights, self._native.layer_shapes[-1]))

    def _restore_weights(self) -> None:
        if not np.array_equal(np.asarray(dr.detach(self._traced.flat).numpy()).reshape(-1), self._traced.good):
            self._arrays.assign(self._traced.flat, self._traced.good)

    def _spectral_output(self):
        count = self._native.spectral_count
        if not count:
            return None
        min_nm, max_nm = self._native.spectral_range_nm
        return count, min_nm, max_nm, self._native.spectral_srgb_matrix()

    def _traced_width_problem(self) -> str | None:
        width = self._native.hidden_width if self._textured is None else self._textured.hidden_width
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
        if isinstance(self._backend, base.OnBase):
            lines.append(f"base = {self._native.base['type']}")
        if self._backend.name == "jit":
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
