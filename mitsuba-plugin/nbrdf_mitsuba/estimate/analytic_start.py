"""The analytic candidates: Mitsuba's analytic models fitted through the same images, judged by the
held-out view beside the network's candidates; the one chosen becomes the base of the written
network (``f_r = base + network``, :mod:`nbrdf_mitsuba.base`) under a zero residual, so that the
estimate is never worse than the best analytic fit the held-out view saw."""

from __future__ import annotations

import numpy as np

#: The analytic models fitted as candidates: every analytic model the estimate command fits (a
#: single one, ``principled``, left conductors 4-12x worse than their ``roughconductor`` fit;
#: docs/experiments.md, Estimation: "The analytic fits judged at many samples").
ANALYTIC_MODELS = ("principled", "roughconductor", "roughplastic")


def residual_start() -> np.ndarray:
    """The flat width-21 weights of the network written on the chosen analytic fit (its base,
    file field ``base``): all zero, a network that adds exactly nothing, so that the estimate is
    that fit itself. Distilling the fit into the network instead added the network's own error to
    the fit's (docs/experiments.md, Estimation: "The chosen fit distilled into the network")."""
    from .models import HIDDEN

    return np.zeros(HIDDEN * HIDDEN + 11 * HIDDEN + 3)
