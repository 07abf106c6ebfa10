"""``python -m nbrdf_mitsuba.estimate SCENE.xml --images IMG... --bsdf-id ID -o OUT``: a material
estimated from images of a known scene by differentiable rendering (Mitsuba's ``prb``).

The scene holds the object whose BSDF (the one with id ``ID``, whatever its type) is to be
estimated, its sensors and emitters; image ``i`` (EXR, linear RGB) is the scene seen by its
``i``-th sensor. That BSDF is replaced by the model (``--model``) and the model's parameters
are optimised by Adam on the images' error relative to ``1 + radiance`` (:func:`image_loss`), every
view each step:

* ``nbrdf`` (default): first the 32-value latent code through the pretrained decoder
  (:mod:`nbrdf_mitsuba.latent`: the gradient of the weights, which ``jit_weights="opaque"``
  makes scene parameters, chained to the code), starting from the best of 49 training codes,
  with a Gaussian penalty on the code (the training codes' mean and spread); then the 675
  weights themselves, with a pull toward the decoded network in function space (the squared
  difference of the two networks' log-space outputs at fixed direction pairs over the whole
  hemisphere, so that where no image constrains the BRDF it stays the decoded one). Beside them
  the analytic candidates (:mod:`.analytic_start`): ``principled``, ``roughconductor`` and
  ``roughplastic``, each fitted through the same images for ``ANALYTIC_STEP_SHARE`` of the steps. The pull
  strength, or an analytic candidate, is chosen by a held-out training view (``--pull-strength``
  fixes the pull instead, and then no analytic model is fitted): the code is fitted on every
  view once per strength of ``CODE_STRENGTHS`` (by default one, 0; the screening of the starts
  shared); from the decoded code every strength of ``PULL_STRENGTHS`` fits the weights on all
  views but the last (the held-out one) for a share of the steps, and each analytic model is
  fitted on the same views; each is judged by one render of the held-out view at ``JUDGE_SPP``
  samples. The candidate with the lowest loss is kept: a network candidate's fit goes on over
  every view for the rest of the weight phase's steps; an analytic one's goes on over every view
  for ``ANALYTIC_REFIT_SHARE`` of the steps and is written as the network's base (file field
  ``base``) under a zero network.
  A candidate or final network whose directional albedo exceeds its bound (:func:`albedo_bound`:
  1, or the network's own albedo where the lights fall square if higher, plus ``ALBEDO_MARGIN``;
  at most ``ALBEDO_BOUND``) is no material and is not kept; the prior is then attempted again
  with other render seeds, up to ``PRIOR_ATTEMPTS`` times, before the estimate falls back to the
  ``nbrdf-no-prior`` estimate itself. A fixed ``--pull-strength`` holds no view out: the
  code strength is then ``--code-strength``, else 0. Writes an ``*.nbrdf.json`` with ``nbrdf
  fit-phong``'s sampling.
* ``nbrdf-no-prior``: the weights alone, from the common initialisation (the trainer's seed-0
  start, twin of ``network/mod.rs`` ``paper_init``).
* ``principled``, ``roughconductor``, ``roughplastic``: Mitsuba's BSDFs' parameters (colours and
  roughness through a sigmoid into their ranges). Writes the fitted BSDF as a ``mi.load_dict``
  JSON dictionary.

The marked BSDF may be declared anywhere: at the top of the scene (and shared by shapes), nested
in its shape or in a ``twosided``; it is found by the object (:func:`scene.bsdf_key_prefix`).

Robust, with ``python -m nbrdf_mitsuba``'s exit statuses: images of the wrong count or size,
non-finite pixels, no BSDF with the id, a variant without automatic differentiation or images that
do not depend on the BSDF are usage or input errors (exit status 2, one line naming the
problem). A step whose loss or gradient is not finite (or whose weights the BSDF rejects), or
whose loss has run away to ten times the phase's lowest, is taken back and the step size halved;
an estimate that still diverges, or whose result cannot be written, has failed (exit status 1);
no non-finite result is ever written. An unexpected error is one line and a hint (exit status 1),
not a traceback. Deterministic for a seed (each render's seed derives from it).

The package: :mod:`.cli` (the command line), :mod:`.scene` (the scene file, variant and images),
:mod:`.models` (the fitted models and the files written), :mod:`.plan` (how the steps and the
candidate strengths are laid out), :mod:`.optimiser` (Adam and the descent that takes back a
diverging step), :mod:`.priors` (the code penalty, the pull and the albedo check),
:mod:`.analytic_start` (the analytic candidates and the zero residual on the chosen one) and :mod:`.estimator` (the loss,
its gradient and the estimate's course).
"""

from __future__ import annotations

from .. import _llvm

_llvm.configure()  # must precede the first import of drjit

from .cli import main, parser  # noqa: E402
from .errors import EstimateError, EstimateFailed  # noqa: E402
from .estimator import Estimator, estimate  # noqa: E402
from .models import MODELS, Analytic, Network, common_initialisation, fit_sampling, write_network  # noqa: E402
from .analytic_start import ANALYTIC_MODELS  # noqa: E402
from .estimator import JUDGE_SPP  # noqa: E402
from .plan import (ANALYTIC_REFIT_SHARE, ANALYTIC_STEP_SHARE, CODE_STRENGTHS, PULL_STRENGTHS, Plan,  # noqa: E402
                   schedule)
from .priors import ALBEDO_BOUND, ALBEDO_LIT_INCIDENCE, ALBEDO_MARGIN  # noqa: E402
from .scene import Scene  # noqa: E402

__all__ = ["ALBEDO_BOUND", "ALBEDO_LIT_INCIDENCE", "ALBEDO_MARGIN", "ANALYTIC_MODELS", "ANALYTIC_REFIT_SHARE",
           "ANALYTIC_STEP_SHARE", "CODE_STRENGTHS", "JUDGE_SPP", "MODELS", "PULL_STRENGTHS", "Analytic",
           "EstimateError", "EstimateFailed", "Estimator", "Network", "Plan", "Scene", "common_initialisation",
           "estimate", "fit_sampling", "main", "parser", "schedule", "write_network"]
