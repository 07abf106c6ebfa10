"""The prior's plan: how the steps split between the code phase, the weight phase and the
held-out view's candidates, and which strengths the candidates take."""

from __future__ import annotations

from dataclasses import dataclass

from .analytic_start import ANALYTIC_MODELS

#: Share of the steps spent on the latent code before the weights (model ``nbrdf``): the weight
#: phase needs the larger share, its loss still falling steeply at the end of a shorter one
#: (docs/experiments.md, Estimation: the first entry, on the code phase's step, share and starts).
CODE_SHARE = 0.4
#: Strengths of the weight phase's pull toward the decoded network (:func:`pull_penalty`), one
#: picked per estimate by the held-out training view: a pull, and none at all (the decoded start
#: only). In function space because a pull on the weights kept the weights, not the BRDF, and a
#: stronger pull was never chosen (docs/experiments.md, Estimation: "A pull in function space
#: instead of weight space").
PULL_STRENGTHS = (1e-1, 0.0)
#: The pull strength where no view can be held out (one image) or no weight step is left to judge.
FALLBACK_PULL_STRENGTH = 1e-1
#: Strengths of the code phase's Gaussian penalty (the training codes' mean and spread), each a code
#: phase of its own; where several, the held-out view judges their decoded networks and only the
#: best one's start runs the weight phase's candidates. One, no penalty: a second strength (1e-3)
#: helped some materials and cost others about as much, for a fifth of the estimate's time more
#: (docs/experiments.md, Estimation: "One code phase, or candidates from every code").
CODE_STRENGTHS = (0.0,)
#: The code strength where nothing is chosen (one image, no weight step, or a fixed
#: ``--pull-strength``): no penalty.
FALLBACK_CODE_STRENGTH = 0.0
#: Share of the weight phase's steps each candidate strength is fitted for before it is judged.
CANDIDATE_SHARE = 0.5
#: Share of the estimate's steps each analytic candidate is fitted for: on the tuning set's
#: roughplastic truth its fit's loss had levelled off by a third of the steps.
ANALYTIC_STEP_SHARE = 0.5
#: Share of the estimate's steps the chosen analytic fit goes on for over every view, the held-out
#: one too: its fit as a candidate saw all views but that one.
ANALYTIC_REFIT_SHARE = 0.25


@dataclass(frozen=True)
class Plan:
    """Steps of the code phase and of the weight phase, the candidate strengths of the weight
    phase's pull and of the code's penalty (one each: no choice), the steps of each candidate's
    weight fit (0: nothing to choose), the analytic candidates' models and the steps of each one's
    fit (none and 0: no analytic candidate), and the steps the chosen analytic fit goes on for."""

    code_steps: int
    weight_steps: int
    pull_strengths: tuple[float, ...]
    code_strengths: tuple[float, ...]
    candidate_steps: int
    analytic_steps: int = 0
    analytic_models: tuple[str, ...] = ()
    analytic_refit_steps: int = 0

    @property
    def selecting(self) -> bool:
        """Whether the held-out view chooses among candidates."""
        return self.candidate_steps > 0

    def total_steps(self) -> int:
        """Steps of the analytic candidates' fits and of one attempt of the prior: every code phase,
        every candidate's fit, and the chosen one's fit to the end of the weight phase (the code and
        weight phases add up to the estimate's steps). Where an analytic fit is chosen, its
        ``analytic_refit_steps`` come on top."""
        return len(self.analytic_models) * self.analytic_steps + self.attempt_steps()

    def attempt_steps(self) -> int:
        """Steps of one attempt of the prior (:meth:`total_steps` without the analytic fit)."""
        codes = len(self.code_strengths)
        candidates = len(self.pull_strengths)
        return (self.code_steps + self.weight_steps + (codes - 1) * self.code_steps
                + (candidates - 1) * self.candidate_steps)


def schedule(steps: int, views: int, pull_strength: float | None, code_strength: float | None = None) -> Plan:
    """The plan of an estimate of ``steps`` steps on ``views`` images. A fixed ``pull_strength``
    fixes the code's strength too (``code_strength``, else none) and leaves out the analytic
    candidates, which the held-out view judges beside the network's (each fitted for
    ``ANALYTIC_STEP_SHARE`` of the steps)."""
    code = max(1, round(CODE_SHARE * steps)) if steps > 1 else 1
    weights = steps - code
    fixed_code = (code_strength if code_strength is not None else FALLBACK_CODE_STRENGTH,)
    if pull_strength is not None:
        strengths, code_strengths = (pull_strength,), fixed_code
    elif views < 2 or weights < 1:
        strengths, code_strengths = (FALLBACK_PULL_STRENGTH,), fixed_code
    else:
        strengths = PULL_STRENGTHS
        code_strengths = fixed_code if code_strength is not None else CODE_STRENGTHS
    analytic = ANALYTIC_MODELS if pull_strength is None and views >= 2 and weights >= 1 else ()
    selecting = len(strengths) + len(analytic) > 1
    candidate = max(1, round(CANDIDATE_SHARE * weights)) if selecting else 0
    refit = max(1, round(ANALYTIC_REFIT_SHARE * steps)) if analytic else 0
    analytic_steps = max(1, round(ANALYTIC_STEP_SHARE * steps)) if analytic else 0
    return Plan(code, weights, strengths, code_strengths, candidate, analytic_steps, analytic, refit)
