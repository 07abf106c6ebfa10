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
#: The distillation's trainer settings that differ from its defaults, and how many trainings from
#: different seeds it makes, keeping the one of the lowest validation loss: a distillation's result
#: depends on its seed far more than on its length, and the validation loss ranks the seeds' results
#: (docs/estimation.md, "Defaults, and why"). The test suite cuts both (conftest.py
#: ``quick_distillation``).
DISTIL_SETTINGS: dict = {"samples": 400_000, "max_epochs": 100}
DISTIL_RESTARTS = 8


def distil(fitted: dict, threads: int | None) -> np.ndarray:
    """The flat width-21 weights of a network learnt from the BSDF ``fitted`` (a ``mi.load_dict``
    dictionary) by the trainer at ``DISTIL_SETTINGS``: the best of ``DISTIL_RESTARTS`` trainings,
    each from its own seed, by validation loss. The estimate's result where an analytic fit is
    chosen."""
    from .. import _train_native as native
    from ..distill import eval_cos
    from .models import HIDDEN

    config = native.default_config()
    config.threads, config.hidden = threads or 0, HIDDEN
    for field, value in DISTIL_SETTINGS.items():
        setattr(config, field, value)
    first_seed, best = config.seed, None
    try:
        view, light, n_validation = native.sample_directions(config)
        values = eval_cos(mi.load_dict(fitted), view, light)
        if not np.all(np.isfinite(values)):
            raise EstimateFailed(f"internal: the fitted {fitted['type']} is not finite at some directions")
        for restart in range(DISTIL_RESTARTS):
            # The seed draws the initial weights and the batches; the pairs stay the ones sampled.
            config.seed = first_seed + restart
            document = json.loads(native.train_from_arrays(
                config, view, light, values, n_validation, name="analytic fit",
                source=f"the estimate's {fitted['type']} fit"))
            loss = document["provenance"]["best_validation_loss"]
            if np.isfinite(loss) and (best is None or loss < best[0]):
                best = (loss, document["layers"])
    except native.TrainError as error:
        raise EstimateFailed(f"the distillation of the analytic fit failed: {error}") from None
    if best is None:
        raise EstimateFailed(f"the distillation of the analytic fit failed: no training of the fitted "
                             f"{fitted['type']} reached a finite validation loss")
    return np.concatenate([np.concatenate([layer["weights"], layer["bias"]]) for layer in best[1]]).astype(np.float64)
