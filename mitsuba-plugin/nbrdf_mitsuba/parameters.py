"""The sampling lobes of the ``nbrdf`` and ``merl`` BSDFs as parameters: read from the scene with
the file's defaults, validated, made into the library's sampler, exposed to ``mi.traverse`` and
updated atomically (``parameters_changed``)."""

from __future__ import annotations

import mitsuba as mi

from . import _native
from ._native import KIND
from .validation import sampling_problem, strip_function

SAMPLING_NAMES = tuple(_native.SAMPLING_KINDS)


def _as_float(bsdf, name, value, default) -> float:
    if value is None:
        return default
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f'{bsdf._type_name()} "{bsdf._filename}": "{name}" must be a number, '
                         f"got {value!r}") from None


class SamplingParameters:
    """The lobe parameters of the BSDF mixins (``bsdf._NativeBSDFMixin``, which provides
    ``_type_name``, ``_filename``, ``_native``, ``_arrays``, ``_table``, ``_unused_second``,
    ``_backend`` and the material's ``_default_sampling``). The validated values are ``_lobes``
    (exponent, weight, exponent2, weight2), the library's sampler of them ``_sampler``."""

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
        # parameters_changed (the backends use validated copies, see _set_sampler).
        anisotropic = sampling == KIND.anisotropic_phong
        parameter = self._arrays.parameter
        self.exponent = parameter(exponent)
        self.specular_weight = parameter(weight)
        self.exponent2 = parameter(0.0 if anisotropic else exponent2)
        self.exponent_v = parameter(exponent2 if anisotropic else 0.0)
        self.specular_weight2 = parameter(weight2)

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
        """Validates the lobes and makes the library's sampler of them (``_sampler``); the
        validated values are ``_lobes`` (exponent, weight, exponent2, weight2)."""
        problem = sampling_problem(exponent, weight, (exponent2, weight2), self._sampling == KIND.two_lobe,
                                   self._second_exponent_name())
        if problem:
            raise ValueError(f'{self._type_name()} "{self._filename}": invalid sampling parameters: {problem}')
        try:
            if self._sampling == KIND.tabulated:
                # Built once from the material; the lobe parameters do not enter it.
                if self._table is None:
                    self._table = _native.Sampler(self._sampling, material=self._native)
                self._sampler = self._table
            elif self._sampling == KIND.anisotropic_phong:
                self._sampler = _native.Sampler(self._sampling, exponent, weight, exponent_v=exponent2)
            else:
                self._sampler = _native.Sampler(self._sampling, exponent, weight, exponent2, weight2)
        except _native.NbrdfError as error:
            raise ValueError(f'{self._type_name()} "{self._filename}": invalid sampling parameters: '
                             f"{strip_function(error)}") from None
        self._lobes = (exponent, weight, exponent2, weight2)

    def _second_exponent_name(self) -> str:
        return "exponent_v" if self._sampling == KIND.anisotropic_phong else "exponent2"

    def _second_exponents(self):
        """``(name, traversed value)`` of the second exponent this sampling reads, then of the
        one it ignores (exponent_v for anisotropic_phong, exponent2 otherwise)."""
        if self._sampling == KIND.anisotropic_phong:
            return ("exponent_v", self.exponent_v), ("exponent2", self.exponent2)
        return ("exponent2", self.exponent2), ("exponent_v", self.exponent_v)

    def parameters_changed(self, keys=None):
        """Validates the whole update, then applies all of it or nothing.

        A rejected update raises ValueError (saying what was wrong), writes the last good values
        back into the traversed parameters (in place, so the ``SceneParameters`` that holds them
        sees them too) and leaves the BSDF as it was; later valid updates take effect."""
        (name, used), (unused, ignored) = self._second_exponents()
        scalar = self._arrays.scalar
        try:
            exponent = scalar(self.exponent, "exponent")
            weight = scalar(self.specular_weight, "specular_weight")
            exponent2 = scalar(used, name)
            # The other one of exponent2 / exponent_v does nothing here; checked all the same.
            unused_value = scalar(ignored, unused)
            weight2 = scalar(self.specular_weight2, "specular_weight2")
            problem = (sampling_problem(exponent, weight, (exponent2, weight2), self._sampling == KIND.two_lobe, name)
                       or sampling_problem(0.0, 0.0, (unused_value, 0.0), False, unused))
            if problem:
                raise ValueError(f"invalid sampling parameters: {problem}")
            weights = self._validated_weights(keys) if self._backend.name == "jit" else None
        except ValueError as error:
            self._restore_parameters()
            raise ValueError(f'{self._type_name()} "{self._filename}": update rejected, the BSDF keeps '
                             f"its previous parameters: {error}") from None
        if weights is not None:
            self._apply_weights(weights)
        new = (exponent, weight, exponent2, weight2)
        old = self._lobes
        if unused_value != self._unused_second:
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
        self._backend.use(self._sampler, self._lobes)

    def _restore_parameters(self) -> None:
        exponent, weight, exponent2, weight2 = self._lobes
        (_, used), (_, ignored) = self._second_exponents()
        assign = self._arrays.assign
        assign(self.exponent, exponent)
        assign(self.specular_weight, weight)
        assign(used, exponent2)
        assign(ignored, self._unused_second)
        assign(self.specular_weight2, weight2)
        if self._backend.name == "jit":
            self._restore_weights()

    def _validated_weights(self, keys):
        return None

    def _apply_weights(self, weights) -> None:
        pass

    def _restore_weights(self) -> None:
        pass
