"""Adam on NumPy vectors, and the descent that takes back a diverging step and halves the step
size."""

from __future__ import annotations

import math

import numpy as np

from .errors import EstimateFailed

#: Adam step sizes per kind of variable. The code's is a fraction of the training codes' spread,
#: large enough for the code to cross that spread within its phase; the analytic models' settles
#: lower than twice it (docs/experiments.md, Estimation: the first entry, on the code phase's step,
#: share and starts, and "Analytic models' step").
LEARNING_RATES = {"code": 0.2, "weights": 0.003, "analytic": 0.05}
#: Times the step may halve after non-finite or run-away losses before the estimate gives up.
MAX_HALVINGS = 12
#: A step whose loss is this many times the phase's lowest so far has run away: a finite loss
#: growing step after step, which the non-finite check lets through; a step's Monte Carlo noise
#: stays far below this factor (docs/experiments.md, Estimation: the entry on larger training
#: images over three seeds, where a network's loss ran away).
RUNAWAY_FACTOR = 10.0


class Phase:
    """One optimisation of ``steps`` steps: ``theta`` (NumPy) set into the scene by ``apply(params,
    prefix, theta_ad)`` (``prefix``: the model's BSDF in ``params``); ``penalty(theta)``, if any:
    ``(value, gradient)`` added to the image loss."""

    def __init__(self, kind, theta, steps, apply, penalty):
        self.kind, self.steps, self.apply, self.penalty = kind, steps, apply, penalty
        self.theta = np.asarray(theta, np.float64)


class Adam:
    """Adam on a NumPy vector (float64, so that a seed gives the same steps everywhere)."""

    def __init__(self, size: int, rate: float, betas=(0.9, 0.999), eps=1e-8):
        self.rate, self.betas, self.eps = rate, betas, eps
        self.m, self.v, self.t = np.zeros(size), np.zeros(size), 0

    def state(self):
        return self.m.copy(), self.v.copy(), self.t

    def restore(self, state) -> None:
        self.m, self.v, self.t = state[0].copy(), state[1].copy(), state[2]

    def step(self, theta: np.ndarray, grad: np.ndarray) -> np.ndarray:
        b1, b2 = self.betas
        self.t += 1
        self.m = b1 * self.m + (1 - b1) * grad
        self.v = b2 * self.v + (1 - b2) * grad * grad
        m_hat = self.m / (1 - b1 ** self.t)
        v_hat = self.v / (1 - b2 ** self.t)
        return theta - self.rate * m_hat / (np.sqrt(v_hat) + self.eps)


class Descent:
    """Adam over one phase at a time on ``loss_and_grad(phase, theta, step)`` (a subclass's), with
    the accepted losses (``history``) and the step's halvings counted over every phase."""

    def __init__(self):
        self.halvings = 0
        self.history: list[float] = []
        #: ``on_step(kind, steps_done, theta)`` after each step (a convergence study's snapshots).
        self.on_step = None

    def loss_and_grad(self, phase: Phase, theta: np.ndarray, step: int):
        raise NotImplementedError

    def check_first_gradient(self, grad: np.ndarray) -> None:
        """Called with the gradient of the estimate's first step."""

    def run(self, phase: Phase, bar, first_step: int) -> np.ndarray:
        adam = Adam(phase.theta.size, LEARNING_RATES[phase.kind])
        theta = phase.theta.copy()
        accepted = (theta.copy(), adam.state())
        best = (math.inf, accepted)
        step = 0
        while step < phase.steps:
            value, grad = self.loss_and_grad(phase, theta, first_step + step)
            runaway = grad is not None and value > RUNAWAY_FACTOR * best[0]
            if grad is None or runaway:
                # A diverging step: back to the last state with a finite loss (where the loss ran
                # away, to the phase's best: the states before it were already running away),
                # half the step.
                self.halvings += 1
                if self.halvings > MAX_HALVINGS:
                    raise EstimateFailed(f"the optimisation diverged: the loss stayed non-finite or ran away after "
                                        f"{MAX_HALVINGS} halvings of the step")
                back = best[1] if runaway else accepted
                theta = back[0].copy()
                adam.restore(back[1])
                adam.rate *= 0.5
                continue
            accepted = (theta.copy(), adam.state())
            if value < best[0]:
                best = (value, accepted)
            self.history.append(value)
            if step == 0 and first_step == 0:
                self.check_first_gradient(grad)
            theta = adam.step(theta, grad)
            step += 1
            if self.on_step is not None:
                self.on_step(phase.kind, first_step + step, theta)
            bar.update(1)
            bar.set_postfix(loss=f"{value:.4g}", phase=phase.kind)
        return theta if np.all(np.isfinite(theta)) else accepted[0]
