"""The analytic start: an analytic model fitted through the same images, distilled into the
network (:mod:`nbrdf_mitsuba.distill`'s evaluation and the trainer, in process), so that the
held-out view can choose it against the decoded starts and the estimate is never much worse than
the analytic fit."""

from __future__ import annotations

import json

import mitsuba as mi
import numpy as np

from .errors import EstimateFailed

#: The analytic model fitted as a start: the best analytic model on the estimate report's measured
#: truths (docs/results/estimation.md).
ANALYTIC_MODEL = "principled"
#: The distillation's training pairs and epochs (the trainer's defaults are 800,000 and up to 300):
#: the start only needs the BRDF's shape, which its candidate fit then refines on the images
#: (docs/estimation.md, "Defaults, and why").
DISTIL_SAMPLES = 200_000
DISTIL_EPOCHS = 30


def distil(fitted: dict, threads: int | None) -> np.ndarray:
    """The flat width-21 weights of a network learnt from the BSDF ``fitted`` (a ``mi.load_dict``
    dictionary) by the trainer, from the common initialisation, on ``DISTIL_SAMPLES`` pairs for
    ``DISTIL_EPOCHS`` epochs."""
    from .. import _train_native as native
    from ..distill import eval_cos
    from .models import HIDDEN

    config = native.default_config()
    config.samples, config.max_epochs, config.threads, config.hidden = DISTIL_SAMPLES, DISTIL_EPOCHS, threads or 0, HIDDEN
    try:
        view, light, n_validation = native.sample_directions(config)
        values = eval_cos(mi.load_dict(fitted), view, light)
        if not np.all(np.isfinite(values)):
            raise EstimateFailed(f"internal: the fitted {fitted['type']} is not finite at some directions")
        text = native.train_from_arrays(config, view, light, values, n_validation, name="analytic start",
                                        source=f"the estimate's {fitted['type']} fit")
    except native.TrainError as error:
        raise EstimateFailed(f"the distillation of the analytic start failed: {error}") from None
    layers = json.loads(text)["layers"]
    return np.concatenate([np.concatenate([layer["weights"], layer["bias"]]) for layer in layers]).astype(np.float64)
