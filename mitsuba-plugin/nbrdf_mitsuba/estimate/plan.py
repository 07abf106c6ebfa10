"""The prior's plan: how the steps split between the code phase, the weight phase and the
held-out view's candidates, and which strengths the candidates take."""

from __future__ import annotations

from dataclasses import dataclass

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
#: phase of its own whose decoded start runs every candidate of the weight phase; the held-out view
#: judges the pairs together: 0 is no penalty; the other keeps the code near the training codes,
#: which helps most materials but not all, hence the choice (docs/experiments.md, Estimation: "The
#: code penalty's strength chosen by the held-out view").
CODE_STRENGTHS = (0.0, 1e-3)
#: The code strength where nothing is chosen (one image, no weight step, or a fixed
#: ``--pull-strength``): no penalty.
FALLBACK_CODE_STRENGTH = 0.0
#: Share of the weight phase's steps each candidate strength is fitted for before it is judged.
CANDIDATE_SHARE = 0.5


@dataclass(frozen=True)
class Plan:
    """Steps of the code phase and of the weight phase, the candidate strengths of the weight
    phase's pull and of the code's penalty (one each: no choice), and the steps of each decoded
    candidate's weight fit (0: nothing to choose)."""

    code_steps: int
    weight_steps: int
    pull_strengths: tuple[float, ...]
    code_strengths: tuple[float, ...]
    candidate_steps: int

    @property
    def selecting(self) -> bool:
        """Whether the held-out view chooses among candidates."""
        return self.candidate_steps > 0

    def total_steps(self) -> int:
        """Steps of one attempt of the prior: every code phase, every candidate's fit, and the
        chosen one's fit to the end of the weight phase (the code and weight phases add up to the
        estimate's steps)."""
        codes = len(self.code_strengths)
        return (self.code_steps + self.weight_steps + (codes - 1) * self.code_steps
                + (codes * len(self.pull_strengths) - 1) * self.candidate_steps)


def schedule(steps: int, views: int, pull_strength: float | None, code_strength: float | None = None) -> Plan:
    """The plan of an estimate of ``steps`` steps on ``views`` images. A fixed ``pull_strength``
    fixes the code's strength too (``code_strength``, else none)."""
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
    selecting = len(strengths) * len(code_strengths) > 1
    candidate = max(1, round(CANDIDATE_SHARE * weights)) if selecting else 0
    return Plan(code, weights, strengths, code_strengths, candidate)
