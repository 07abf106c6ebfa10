"""A network on an analytic base (the file's ``base``, docs/formats.md): ``f_r = base + network``.

The base is a Mitsuba BSDF built from the file's dictionary; :class:`OnBase` wraps the network's
backend (either one) and adds the base to every value. Sampling picks the base with probability
:data:`BASE_SAMPLING_PROBABILITY`, else the network's own strategy, and reports the mixture's
pdf, so that MIS sees the exact density; a network that is exactly zero (every weight and bias of
its last layer 0, what ``estimate`` writes where an analytic fit wins) is neither evaluated nor
sampled (except in a frozen function's recording, :mod:`.freezing`).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

#: The chance of sampling the base where the network is not zero: an even split keeps each
#: strategy's variance within a factor of two of its own, whichever of the two dominates.
BASE_SAMPLING_PROBABILITY = 0.5


def load_base(base: dict, label: str) -> mi.BSDF:
    """The Mitsuba BSDF of a file's ``base`` dictionary; ValueError naming ``label`` where Mitsuba
    cannot build it or where it has a delta (smooth) component, which a sum with a network
    cannot sample or weigh."""
    try:
        bsdf = mi.load_dict(base)
    except Exception as error:  # Mitsuba raises RuntimeError, or TypeError for bad values
        raise ValueError(f'{label}: cannot build its "base" BSDF {base.get("type")!r}: {error}') from None
    if not isinstance(bsdf, mi.BSDF):
        raise ValueError(f'{label}: "base" must be a BSDF, got a {type(bsdf).__name__}')
    if mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta):
        raise ValueError(f'{label}: "base" {base["type"]!r} has a delta (smooth) component; an '
                         "nbrdf base must be rough (e.g. roughconductor, roughplastic, principled)")
    return bsdf


def network_is_zero(flat, last_layer: tuple[int, int]) -> bool:
    """Whether a network outputs exactly 0 everywhere: its last layer's weights and biases (the
    tail of ``flat``, W1 b1 W2 b2 W3 b3; ``last_layer`` its (inputs, outputs)) are 0, so every
    output is ``max(exp(0) - 1, 0) = 0``."""
    n_in, n_out = last_layer
    return not np.any(np.asarray(flat)[-(n_in * n_out + n_out):])


def _mix(chosen, a, b):
    """``a`` where ``chosen``, else ``b``: a plain branch in scalar variants (a Python truth value)."""
    if not dr.is_array_v(chosen):
        return a if chosen else b
    return dr.select(chosen, a, b)


class OnBase:
    """The backend of a network on a base: ``network`` (a :class:`JitBackend` or
    :class:`RustBackend`) plus ``base`` (a Mitsuba BSDF). Everything else (``name``, ``use``,
    ``traced``) is the network backend's."""

    def __init__(self, network, base: mi.BSDF, zero: bool, differentiable: bool):
        self.network = network
        self.base = base
        #: Weights with gradients are always evaluated: skipping them would cut their gradient.
        self.differentiable = differentiable
        self.network_changed(zero)

    def __getattr__(self, name):
        return getattr(self.__dict__["network"], name)

    def network_changed(self, zero: bool) -> None:
        """Takes the network's new weights into account (``zero``: :func:`network_is_zero`)."""
        self.zero = zero

    def _zero_now(self) -> bool:
        # A frozen function's recording takes the network as non-zero: replayed after an update
        # that made it non-zero, a recording without it would leave it out.
        return self.zero and not dr.flag(dr.JitFlag.FreezingScope)

    @property
    def skip_network(self) -> bool:
        return self._zero_now() and not self.differentiable

    @property
    def probability(self) -> float:
        return 1.0 if self._zero_now() else BASE_SAMPLING_PROBABILITY

    def eval(self, ctx, si, wo, active=True):
        f = self.base.eval(ctx, si, wo, active)
        return f if self.skip_network else f + self.network.eval(ctx, si, wo, active)

    def _mixture_pdf(self, base_pdf, ctx, si, wo, active):
        """The sampling mixture's pdf at ``wo`` from the base's pdf there."""
        if self.probability == 1.0:
            return base_pdf
        return dr.fma(self.probability, base_pdf,
                      (1.0 - self.probability) * self.network.pdf(ctx, si, wo, active))

    def pdf(self, ctx, si, wo, active=True):
        return self._mixture_pdf(self.base.pdf(ctx, si, wo, active), ctx, si, wo, active)

    def eval_pdf(self, ctx, si, wo, active=True):
        f, pdf = self.base.eval_pdf(ctx, si, wo, active)
        if not self.skip_network:
            f = f + self.network.eval(ctx, si, wo, active)
        return f, self._mixture_pdf(pdf, ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        p = self.probability
        if p == 1.0 and self.skip_network:
            return self.base.sample(ctx, si, sample1, sample2, active)
        if p == 1.0:
            bs, _ = self.base.sample(ctx, si, sample1, sample2, active)
        else:
            use_base = sample1 < p
            use_network = ~use_base if dr.is_array_v(use_base) else not use_base
            bs_base, _ = self.base.sample(ctx, si, sample1 / p, sample2, active & use_base)
            bs_network, _ = self.network.sample(ctx, si, (sample1 - p) / (1.0 - p), sample2,
                                                active & use_network)
            bs = _mix(use_base, bs_base, bs_network)
        # The weight and pdf of the sum and the mixture, whichever strategy drew the direction.
        f, pdf = self.eval_pdf(ctx, si, bs.wo, active)
        ok = active & (pdf > 0)
        bs.pdf = _mix(ok, pdf, 0.0)
        weight = f / _mix(ok, pdf, 1.0)
        finite = dr.all(dr.isfinite(mi.unpolarized_spectrum(weight)))
        return bs, _mix(ok & finite, weight, 0.0)
