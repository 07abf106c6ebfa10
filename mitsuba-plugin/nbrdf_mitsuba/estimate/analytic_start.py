"""The analytic candidates: Mitsuba's analytic models fitted through the same images, judged by the
held-out view beside the network's candidates; the one chosen is distilled into the network
(:mod:`nbrdf_mitsuba.distill`'s evaluation and the trainer, in process), so that the estimate is
never much worse than the best analytic fit."""

from __future__ import annotations

import json

import mitsuba as mi
import numpy as np

from .errors import EstimateFailed

#: The analytic models fitted as candidates: every analytic model the estimate command fits (a
#: single one, ``principled``, left conductors 4-12x worse than their ``roughconductor`` fit;
#: docs/experiments.md, Estimation: "The analytic fits judged at many samples").
ANALYTIC_MODELS = ("principled", "roughconductor", "roughplastic")
#: Trainer settings that differ from its defaults in the distillation (none: the defaults). The
#: test suite cuts them, so that an estimate choosing an analytic fit does not take a minute there.
DISTIL_SETTINGS: dict = {}


def distil(fitted: dict, threads: int | None) -> np.ndarray:
    """The flat width-21 weights of a network learnt from the BSDF ``fitted`` (a ``mi.load_dict``
    dictionary) by the trainer at its defaults (those of ``python -m nbrdf_mitsuba.distill``), from
    the common initialisation: the estimate's result where an analytic fit is chosen. Not fewer
    pairs or epochs: on the tuning set's roughplastic truth the distillation, not the fit, set the
    novel-view error (docs/experiments.md, Estimation: "The analytic fits judged at many samples")."""
    from .. import _train_native as native
    from ..distill import eval_cos
    from .models import HIDDEN

    config = native.default_config()
    config.threads, config.hidden = threads or 0, HIDDEN
    for field, value in DISTIL_SETTINGS.items():
        setattr(config, field, value)
    try:
        view, light, n_validation = native.sample_directions(config)
        values = eval_cos(mi.load_dict(fitted), view, light)
        if not np.all(np.isfinite(values)):
            raise EstimateFailed(f"internal: the fitted {fitted['type']} is not finite at some directions")
        text = native.train_from_arrays(config, view, light, values, n_validation, name="analytic fit",
                                        source=f"the estimate's {fitted['type']} fit")
    except native.TrainError as error:
        raise EstimateFailed(f"the distillation of the analytic fit failed: {error}") from None
    layers = json.loads(text)["layers"]
    return np.concatenate([np.concatenate([layer["weights"], layer["bias"]]) for layer in layers]).astype(np.float64)
