"""The estimator (the scene with the model in place of the marked BSDF, its loss and gradient)
and the estimate's course: the model's phases, the prior's held-out choice, its attempts and
fallback, the written result."""

from __future__ import annotations

import contextlib
import gc
import json
import math
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from ..freezing import FrozenOrTraced
from ..jit.adjoints import AdjointRecorder, RecorderOverflow, decode_records
from .analytic_start import residual_start
from .errors import EstimateError, EstimateFailed
from .models import Analytic, Network, common_initialisation, fit_sampling, write_network, write_text
from .numpy_network import recorded_gradient
from .optimiser import Descent, Phase
from .plan import Plan, schedule
from .renders import differentiated_renders, forward_loss, recorded_renders, render_seed
from .priors import albedo_check, pull_penalty, code_penalty
from .scene import Scene, bsdf_key_prefix, check_paths, load_images, parse_defines, require_differentiable_variant

#: Training codes tried as starts of the latent phase (evenly spaced through the anchors, besides
#: their mean), each judged by one render per view at a quarter of the samples (a few steps' cost
#: in all): a wider screening starts lower than the code phase would bring a narrower one
#: (docs/experiments.md, Estimation: the first entry, on the code phase's step, share and starts).
SCREENED_STARTS = 48
#: The start the estimate falls back to where the prior's network is no material (its albedo above
#: :func:`albedo_bound`): the common initialisation, no pull, the ``nbrdf-no-prior`` estimate. No
#: candidate of the held-out choice: where the view chose it, the decoded network was better on the
#: novel views or no material, which the albedo check catches (docs/experiments.md, Estimation: "The
#: albedo check instead of the common candidate").
COMMON_START = "common"
#: Samples per pixel of the held-out view's render that judges each candidate (one render per
#: candidate, the same seed for all): at 4x a training render's samples an analytic fit and a
#: network were within the noise of each other, at this many the better one was lowest on every
#: view (docs/experiments.md, Estimation: "Can the training views tell the analytic fit from the
#: decoded network?").
JUDGE_SPP = 256
#: How much lower than the best analytic candidate's held-out loss a network candidate's must be to
#: be chosen over it: twice the spread of the difference of two candidates' losses over the judging
#: render's seeds, measured on the tuning set (docs/experiments.md, Estimation: "A margin for the
#: analytic fit"). Within that spread the held-out view cannot tell them apart, and the analytic
#: fit, with a handful of parameters, is the one that holds under lights the images do not show.
ANALYTIC_MARGIN = 1.08
#: Attempts of the prior (code phases, candidates, final fit) before the fallback to the common
#: start, each with its own render seeds: the renders' noise decides which code the code phase
#: reaches, and a later attempt can give a material where the first did not (docs/experiments.md,
#: Estimation: "Attempts of the prior with other render seeds").
PRIOR_ATTEMPTS = 3
#: Offset of the estimate's seed from one attempt to the next.
ATTEMPT_SEED_STRIDE = 7919
#: The most network evaluations one trace of a render may record (``jit.adjoints``; 72 bytes
#: each, a few traces a render): beyond, a scene (large images, many bounces on the object) is
#: differentiated by Dr.Jit itself, slower but without the records' memory.
MAX_RECORDS = 1 << 22


class Estimator(Descent):
    """The loaded scene with the model in place of the marked BSDF, and its optimiser."""

    def __init__(self, scene_file: Scene, model, images: list[Path], spp: int, seed: int, max_depth: int,
                 workdir: Path):
        super().__init__()
        self.model, self.spp, self.seed = model, spp, seed
        #: The held-out renders' seed: the estimate's, whatever the attempt, so that every candidate
        #: is judged on the same samples.
        self.judge_seed = seed
        self.bsdf_id = scene_file.bsdf_id
        self.scene = scene_file.load(model.element(workdir))
        self.references = load_images(images, self.scene)
        #: The views the loss sums over (all but the held-out one while a prior strength is chosen).
        self.views = list(range(len(self.references)))
        self.integrator = mi.load_dict({"type": "prb", "max_depth": max_depth})
        self.params = mi.traverse(self.scene)
        #: What the model's parameters are called in ``params``: ``PREFIX.weights`` and so on.
        self.prefix = bsdf_key_prefix(self.params, self.bsdf_id)
        #: Records the network's adjoints in its phases' backward passes (None: Dr.Jit's own
        #: derivative, as for the analytic models).
        self.recorder = self._attach_recorder()
        #: Evaluations a recorded trace may hold: a render's lanes to start with (one evaluation
        #: per lane and call site, a convex object's), grown where a scene needs more.
        self.record_capacity = min(max(self._lanes(i) for i in self.views), MAX_RECORDS)
        #: The recorded step's renders and backward pass, frozen (``dr.freeze``): replayed without
        #: tracing from the second step on (docs/estimation.md, "Cost").
        self._recorded_renders = None if self.recorder is None else FrozenOrTraced(recorded_renders(self.recorder))
        self._forward_loss = FrozenOrTraced(forward_loss)
        # A network without a recorder (a scene past MAX_RECORDS) is traced: recording Dr.Jit's
        # derivative of the network, a reduction per weight, took minutes.
        differentiated = differentiated_renders(self.params)
        self._differentiated_renders = differentiated if isinstance(model, Network) else FrozenOrTraced(differentiated)

    def _attach_recorder(self) -> AdjointRecorder | None:
        # SceneParameters keeps each parameter's object (value, type, object, flags): the BSDF.
        if not isinstance(self.model, Network):
            return None
        bsdf = self.params.properties[f"{self.prefix}.weights"][2]
        traced = getattr(bsdf, "traced_network", None)
        if traced is None:
            return None
        traced.recorder = AdjointRecorder()
        return traced.recorder

    def _lanes(self, view: int) -> int:
        width, height = self.scene.sensors()[view].film().crop_size()
        return int(width) * int(height) * self.spp

    def release(self) -> None:
        """Lets the scene go: Mitsuba's symbolic calls trace every live BSDF, so a scene alive beside
        the one rendered adds its BSDFs' code to each step's kernels (the network's most:
        docs/estimation.md, "Cost")."""
        for frozen in (self._recorded_renders, self._forward_loss, self._differentiated_renders):
            if isinstance(frozen, FrozenOrTraced):
                frozen.clear()
        self.scene = self.params = self.recorder = None
        self._recorded_renders = self._forward_loss = self._differentiated_renders = None
        gc.collect()

    def view_references(self) -> list:
        return [self.references[i] for i in self.views]

    def seeds(self, step: int) -> list:
        """The training views' render seeds at ``step`` (each step renders them once), opaque: a
        literal is part of a frozen function's key, and each step's would record anew."""
        return [dr.opaque(mi.UInt32, render_seed(self.seed, step, view)) for view in self.views]

    def _loss_of(self, views: list[int], seeds: list, spp: int) -> float:
        """The image loss of the scene as it is on ``views`` (one render each of ``spp`` samples)."""
        loss = self._forward_loss(self.scene, self.integrator, [self.references[i] for i in views], seeds,
                                  tuple(views), spp)
        return float(np.asarray(loss.numpy()).reshape(-1)[0])

    def held_out_loss(self, theta: np.ndarray, view: int, apply=Network._set_weights) -> float:
        """The image loss of the parameters ``theta`` (set by ``apply``: by default the network's
        weights) on the training view ``view`` (one render of ``JUDGE_SPP``, a fixed seed)."""
        with dr.suspend_grad():
            apply(self.params, self.prefix, mi.Float(np.asarray(theta, np.float32)))
            self.params.update()
        return self._loss_of([view], [dr.opaque(mi.UInt32, render_seed(self.judge_seed, 1 << 20, view))], JUDGE_SPP)

    def loss_and_grad(self, phase: Phase, theta: np.ndarray, step: int):
        """(loss, gradient) at ``theta``, or ``(nan, None)`` where either is not finite or the
        BSDF rejects the values."""
        variable = mi.Float(theta.astype(np.float32))
        dr.enable_grad(variable)
        try:
            phase.apply(self.params, self.prefix, variable)
            self.params.update()
        except ValueError:
            return math.nan, None
        loss = self._recorded_backward(step) if self.recorder is not None and phase.kind != "analytic" else None
        if loss is None:
            loss = self._differentiated_renders(self.scene, self.integrator, self.view_references(), self.seeds(step),
                                                tuple(self.views), self.spp)
        grad = np.asarray(dr.grad(variable).numpy(), dtype=np.float64)
        value = float(loss.array[0]) if hasattr(loss, "array") else float(np.asarray(loss.numpy()).reshape(-1)[0])
        if phase.penalty is not None:
            extra, extra_grad = phase.penalty(theta)
            value, grad = value + extra, grad + extra_grad
        if not (math.isfinite(value) and np.all(np.isfinite(grad))):
            return math.nan, None
        return value, grad

    def _recorded_backward(self, step: int):
        """The image loss, its gradient carried to the phase's variable through the network's
        weights: the renders' backward passes record the network's adjoints, from which NumPy
        computes the weights' gradient (:mod:`nbrdf_mitsuba.jit.adjoints`). None where a scene
        needs more records than ``MAX_RECORDS`` (the estimate then goes on with Dr.Jit's own
        derivative)."""
        weights = self.params[f"{self.prefix}.weights"]  # attached to the phase's variable
        seeds = self.seeds(step)
        while True:
            loss, received = self._recorded_renders(self.scene, self.integrator, self.view_references(), seeds,
                                                    tuple(self.views), self.spp, self.record_capacity)
            try:
                x, adjoint = decode_records(received, self.record_capacity)
                break
            except RecorderOverflow as overflow:
                if overflow.needed > MAX_RECORDS:
                    self.recorder = self._recorded_renders = None
                    return None
                # The same step again with room for all (its renders' seeds give the same samples).
                self.record_capacity = min(overflow.needed + overflow.needed // 4, MAX_RECORDS)
        gradient = recorded_gradient(np.asarray(dr.detach(weights).numpy(), np.float64), x, adjoint)
        dr.backward(dr.sum(weights * mi.Float(gradient.astype(np.float32))))
        return loss

    def check_first_gradient(self, grad: np.ndarray) -> None:
        if not np.any(grad != 0):
            raise EstimateError(f"the images do not depend on BSDF '{self.bsdf_id}' (zero gradient at the "
                                "start): is the object visible to the sensors and lit?")

    @contextlib.contextmanager
    def holding_out(self):
        """Fits within see every view but the last, the held-out one, whose index it yields."""
        held_out = len(self.references) - 1
        views, self.views = self.views, list(range(held_out))
        try:
            yield held_out
        finally:
            self.views = views

    def run_candidate(self, phase: Phase, bar, first_step: int) -> np.ndarray | None:
        """:meth:`run`, or ``None`` where the candidate's fit runs away; its halvings are given back,
        so the estimate goes on without it with the whole budget."""
        halvings = self.halvings
        try:
            return self.run(phase, bar, first_step)
        except EstimateFailed:
            self.halvings = halvings
            return None

    def screen_codes(self, decoder, candidates: np.ndarray) -> np.ndarray:
        """The candidate code whose renders (a quarter of the samples) fit the images best."""
        best, best_loss = candidates[0], math.inf
        for code in candidates:
            with dr.suspend_grad():
                self.params[f"{self.prefix}.weights"] = decoder.decode(mi.Float(code.astype(np.float32)))
                self.params.update()
            value = self._loss_of(self.views, self.seeds(-1), max(1, self.spp // 4))
            if value < best_loss:
                best, best_loss = code, value
        return best


def estimate(args, on_step=None) -> dict:
    """Runs the estimate of the parsed ``args``, writes ``args.output``; a summary.
    ``on_step(kind, steps_done, theta)``, if given, is called after every step."""
    check_paths(args.scene, args.output)
    require_differentiable_variant(args.variant)
    if args.threads is not None and args.threads < 1:
        raise EstimateError("--threads must be at least 1")
    previous = dr.thread_count()
    try:
        return _estimate(args, on_step, previous)
    finally:
        dr.set_thread_count(previous)


def _estimate(args, on_step, loading_threads: int) -> dict:
    if args.steps < 1 or args.spp < 1:
        raise EstimateError("--steps and --spp must be at least 1")
    for name, value in (("--pull-strength", args.pull_strength), ("--code-strength", args.code_strength)):
        if value is not None and not (value >= 0 and math.isfinite(value)):
            raise EstimateError(f"{name} must be a finite number >= 0")
    scene_file = Scene(args.scene, args.bsdf_id, parse_defines(args.define))
    model = Network(args.model == "nbrdf") if args.model.startswith("nbrdf") else Analytic(args.model)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="nbrdf-estimate-") as workdir:
        def load(fitted) -> Estimator:
            """An estimator of the model ``fitted`` (the scene with it in the BSDF's place). Loaded
            with Dr.Jit's threads as they were (Mitsuba builds the Python plugins on its worker
            threads), then ``--threads``: one thread fixes the order of the gradients' float sums
            (bit-identical reruns)."""
            # Garbage freed now, not during the estimate's frozen renders: Dr.Jit's recordings see
            # every live BSDF (freezing.FrozenOrTraced).
            gc.collect()
            dr.set_thread_count(loading_threads)
            loaded = Estimator(scene_file, fitted, args.images, args.spp, args.seed, args.max_depth, Path(workdir))
            if args.threads is not None:
                dr.set_thread_count(args.threads)
            return loaded

        plan = schedule(args.steps, len(args.images), args.pull_strength if model_has_prior(model) else 0.0,
                        args.code_strength)
        from tqdm import tqdm

        with tqdm(total=plan.total_steps(), unit="step", desc=f"estimate {args.model}", disable=args.quiet,
                  file=sys.stderr) as bar:
            # The analytic candidates first, each in a scene of its own, none beside another (release).
            models = plan.analytic_models if model_has_prior(model) else ()
            analytic = fit_analytic_candidates([lambda kind=kind: load(Analytic(kind)) for kind in models], plan, bar)
            est = load(model)
            est.on_step = on_step
            try:
                result = _optimise(est, model, args, bar, plan, analytic, load)
            finally:
                est.release()
    result["seconds"] = time.perf_counter() - start
    result["loss_first"], result["loss_last"] = est.history[0], est.history[-1]
    result["halvings"] = est.halvings + analytic.halvings
    return result


def model_has_prior(model) -> bool:
    return isinstance(model, Network) and model.prior

def candidate_name(candidate) -> str:
    """A network candidate's key in ``held_out_losses``: its pull's strength."""
    return str(candidate[1])


def choose_start(est: Estimator, starts: dict, plan: Plan, bar) -> tuple:
    """The network candidate whose short fit on the training views but the held-out one (the last)
    has the lowest loss on the held-out view: a pair (code strength of the decoded start in
    ``starts``, strength of the pull toward it); ties go to the first (the tightest pull). A
    candidate whose fit fails the albedo check (:func:`albedo_check`) or diverges is not chosen;
    where none is left, ``COMMON_START``. Returns the choice, the held-out losses by candidate,
    the albedos of the rejected ones, the chosen candidate's fitted weights (``None`` for
    ``COMMON_START``) and the candidates that diverged."""
    on_step, est.on_step = est.on_step, None  # candidates are no snapshots of the estimate
    losses, rejected, fits, diverged = {}, {}, {}, []
    try:
        with est.holding_out() as held_out:
            for name, start in starts.items():
                for strength in plan.pull_strengths:
                    phase = Phase("weights", start, plan.candidate_steps, Network._set_weights,
                                  pull_penalty(start, strength))
                    fitted = est.run_candidate(phase, bar, plan.code_steps)
                    if fitted is None:
                        diverged.append((name, strength))
                        continue
                    fits[name, strength] = fitted
                    losses[name, strength] = est.held_out_loss(fitted, held_out)
                    albedo, material = albedo_check(fitted)
                    if not material:
                        rejected[name, strength] = albedo
    finally:
        est.on_step = on_step
    allowed = [k for k in losses if k not in rejected]
    choice = min(allowed, key=losses.__getitem__) if allowed else COMMON_START
    return choice, losses, rejected, fits.get(choice), diverged


def fit_codes(est: Estimator, decoder, plan: Plan, bar) -> dict:
    """Per strength of the code penalty: the code fitted through the decoder from the best
    screened training code (the screening shared), each phase with the same render seeds."""
    picks = np.linspace(0, len(decoder.anchors) - 1, SCREENED_STARTS).round().astype(int)
    candidates = np.concatenate([decoder.anchors.mean(axis=0, keepdims=True), decoder.anchors[picks]])
    code0 = est.screen_codes(decoder, candidates)
    spread = decoder.code_distribution() if any(plan.code_strengths) else (None, None)

    def apply(params, prefix, code):
        params[f"{prefix}.weights"] = decoder.decode(code)

    return {strength: est.run(Phase("code", code0, plan.code_steps, apply, code_penalty(*spread, strength)), bar, 0)
            for strength in plan.code_strengths}


#: The name in the provenance's ``diverged`` of the chosen network candidate's fit over every view.
CONTINUATION = "continuation"


def best_analytic(analytic_losses: dict) -> str | None:
    """The analytic candidate of the lowest held-out loss (``analytic_losses`` by model); None
    without any."""
    return min(analytic_losses, key=analytic_losses.__getitem__) if analytic_losses else None


def analytic_wins(analytic_loss: float, network_loss: float) -> bool:
    """Whether the best analytic candidate (held-out loss ``analytic_loss``) is chosen over the best
    network candidate: unless the network's is lower by more than ``ANALYTIC_MARGIN``."""
    return network_loss * ANALYTIC_MARGIN >= analytic_loss


def prior_attempt(est: Estimator, decoder, plan: Plan, bar, analytic_losses: dict | None = None) -> tuple:
    """One attempt of the prior at the estimator's seed: the code through the decoder, then the
    weights pulled toward the decoded ones by the chosen strength. Returns the weights (``None``
    where the albedo check rejected every candidate or the final network, or where an analytic
    candidate won), the analytic candidate that won (its held-out loss, of ``analytic_losses`` by
    model, not ``ANALYTIC_MARGIN`` times the best kept network candidate's: :func:`analytic_wins`;
    else None), the summary's additions, and the rejected albedos by candidate name (``final``: the
    final network)."""
    # The code phase sees every view, the held-out one too: its 32 values are too few to fit that
    # view's noise, and the view's light often decides which code is reached (docs/experiments.md,
    # Estimation: "The code phase on every training view"). The candidates' weights, which can fit
    # noise, are fitted without it.
    codes = fit_codes(est, decoder, plan, bar)
    starts = {k: decoder.decode_numpy(code).astype(np.float64) for k, code in codes.items()}
    extra = {}
    if len(starts) > 1:
        # The held-out view judges the decoded networks, and only the best code's start runs the
        # candidates (docs/experiments.md, Estimation: "One code phase, or candidates from every code").
        judged = {k: est.held_out_loss(w, len(est.references) - 1) for k, w in starts.items()}
        extra["code_held_out_losses"] = {str(k): v for k, v in judged.items()}
        best = min(judged, key=judged.__getitem__)
        starts = {best: starts[best]}
    code_strength = next(iter(starts))
    choice, losses, rejected, fitted, diverged = (code_strength, plan.pull_strengths[0]), {}, {}, None, []
    if plan.selecting:
        choice, losses, rejected, fitted, diverged = choose_start(est, starts, plan, bar)
    analytic_losses = analytic_losses or {}
    held_out_losses = {**{candidate_name(k): v for k, v in losses.items()}, **analytic_losses}
    if held_out_losses:
        extra["held_out_losses"] = held_out_losses
    if diverged:
        extra["diverged"] = [candidate_name(k) for k in diverged]
    rejected = {candidate_name(k): v for k, v in rejected.items()}
    extra["code"] = [float(c) for c in codes[code_strength]]
    if choice == COMMON_START:
        return None, None, extra, rejected
    analytic = best_analytic(analytic_losses)
    if analytic is not None and analytic_wins(analytic_losses[analytic], losses[choice]):
        return None, analytic, extra, rejected
    strength = choice[1]
    extra.update({"start": "decoded", "pull_strength": strength, "code_strength": code_strength})
    # The chosen candidate's fit goes on over every view (its first steps' render seeds, as a refit
    # from its start had): refitted from the start instead, the network lost what the held-out
    # view had judged (docs/experiments.md, Estimation: "The chosen candidate's fit goes on").
    center = starts[choice[0]]
    weights, steps = (center, plan.weight_steps) if fitted is None else (fitted, plan.weight_steps - plan.candidate_steps)
    if steps > 0:
        phase = Phase("weights", weights, steps, Network._set_weights, pull_penalty(center, strength))
        continued = est.run_candidate(phase, bar, plan.code_steps)
        if continued is None:
            # Its fit over every view ran away: the network the held-out view chose is kept.
            extra["diverged"] = extra.get("diverged", []) + [CONTINUATION]
        else:
            weights = continued
    albedo, material = albedo_check(weights)
    if not material:
        rejected["final"] = albedo
        return None, None, extra, rejected
    extra["albedo_max"] = albedo
    return weights, None, extra, rejected


@dataclass
class AnalyticCandidates:
    """The analytic candidates' fitted parameters and held-out losses by model, the models whose fit
    diverged (no candidates), and the halvings of their steps."""

    thetas: dict = field(default_factory=dict)
    losses: dict = field(default_factory=dict)
    diverged: list = field(default_factory=list)
    halvings: int = 0


def fit_analytic_candidates(loaders: list, plan: Plan, bar) -> AnalyticCandidates:
    """Each analytic model (``loaders``: one estimator each, loaded when its turn comes and released
    after) fitted through the training views but the held-out one (the last), as the model's own
    estimate of the same steps and seed would be on them, and judged on the held-out view."""
    candidates = AnalyticCandidates()
    for load in loaders:
        est = load()
        kind = est.model.kind
        (phase,) = est.model.phases(plan.analytic_steps)
        with est.holding_out() as held_out:
            theta = est.run_candidate(phase, bar, 0)
            if theta is None:
                candidates.diverged.append(kind)
            else:
                candidates.thetas[kind] = theta
                candidates.losses[kind] = est.held_out_loss(theta, held_out, est.model._apply)
        candidates.halvings += est.halvings
        est.release()
    return candidates


def refit_analytic(est: Estimator, theta: np.ndarray, plan: Plan, bar) -> dict:
    """The chosen analytic candidate's fit gone on over every view: the estimate's base
    (:func:`analytic_start.residual_start`)."""
    bar.total += plan.analytic_refit_steps
    phase = Phase("analytic", theta, plan.analytic_refit_steps, est.model._apply, None)
    return est.model.result(est.run(phase, bar, plan.analytic_steps))


def fit_with_prior(est: Estimator, args, plan: Plan, bar, analytic: AnalyticCandidates,
                   load) -> tuple[np.ndarray, dict]:
    """Given the analytic candidates (``analytic``; ``load(model)`` loads an estimator), up to
    ``PRIOR_ATTEMPTS`` attempts of the prior, each with its own render seeds, until the albedo
    check keeps a network or an analytic candidate wins the held-out view (its fit then goes on
    over every view and becomes the network's base, under a zero network); where no attempt keeps
    a network, the best analytic candidate, and without one the common start, the nbrdf-no-prior
    estimate (its start, steps and seeds, so the same network). The weights and the summary's
    additions."""
    from ..latent import Decoder, LatentError

    try:
        decoder = Decoder(args.ae)
    except LatentError as error:
        raise EstimateError(str(error)) from None
    analytic_losses = analytic.losses
    seed, rejected_all, diverged_all, attempt_steps, chosen = est.seed, {}, [], plan.attempt_steps(), None
    try:
        for attempt in range(PRIOR_ATTEMPTS):
            est.seed = seed + ATTEMPT_SEED_STRIDE * attempt
            if attempt > 0:
                bar.total += attempt_steps
            try:
                weights, chosen, extra, rejected = prior_attempt(est, decoder, plan, bar, analytic_losses)
            except LatentError as error:
                raise EstimateError(str(error)) from None
            prefix = f"attempt {attempt}: " if attempt else ""
            rejected_all.update({prefix + k: v for k, v in rejected.items()})
            diverged_all += [prefix + name for name in extra.pop("diverged", [])]
            if weights is not None or chosen is not None:
                extra["attempts"] = attempt + 1
                break
        else:
            # No attempt gave a material: the best analytic candidate, else the nbrdf-no-prior
            # estimate; the last attempt's best code is kept for the record.
            extra["attempts"] = PRIOR_ATTEMPTS
            chosen = best_analytic(analytic_losses)
        if weights is None and chosen is None:
            est.seed = seed
            bar.total += plan.code_steps + plan.weight_steps
            extra.update({"start": COMMON_START, "pull_strength": None, "code_strength": None})
            weights = est.run(Phase("weights", common_initialisation(), plan.code_steps + plan.weight_steps,
                                    Network._set_weights, None), bar, 0)
    finally:
        est.seed = seed
    if chosen is not None:
        est.release()  # the network's scene would be traced into the refit's every step
        candidate = load(Analytic(chosen))
        fitted = refit_analytic(candidate, analytic.thetas[chosen], plan, bar)
        analytic.halvings += candidate.halvings
        candidate.release()
        weights = residual_start()
        extra.update({"start": "analytic", "analytic": fitted, "pull_strength": None, "code_strength": None})
    diverged_all += analytic.diverged
    if diverged_all:
        extra["diverged"] = diverged_all
    if rejected_all:
        extra["albedo_rejected"] = rejected_all
    return weights, extra


def _optimise(est: Estimator, model, args, bar, plan: Plan, analytic: AnalyticCandidates, load) -> dict:
    summary = {"output": str(args.output), "model": args.model, "steps": args.steps}
    if isinstance(model, Analytic):
        (phase,) = model.phases(args.steps)
        theta = est.run(phase, bar, 0)
        fitted = model.result(theta)
        write_text(args.output, json.dumps(fitted, indent=2) + "\n")
        summary["bsdf"] = fitted
        return summary
    if model.prior:
        weights, extra = fit_with_prior(est, args, plan, bar, analytic, load)
        summary.update(extra)
    else:
        weights = est.run(Phase("weights", model.start, args.steps, Network._set_weights, None), bar, 0)
    # The prior's kept network has passed already; a zero network on the chosen analytic fit (its
    # base) has nothing to check (the base is the fitted model, energy conserving as Mitsuba
    # implements it).
    base = summary.get("analytic")
    material = "albedo_max" in summary or base is not None
    if not material:
        summary["albedo_max"], material = albedo_check(weights)
    if not material:
        # Nothing to fall back to (the common start, or no prior asked): written, but not silently.
        print(f"warning: the estimated network reflects up to {summary['albedo_max']:.3g} times the light it "
              "receives (directional albedo; a material reflects at most 1): the images do not constrain it "
              "where their lights do not reach", file=sys.stderr)
    provenance = {"estimated_by": "nbrdf_mitsuba.estimate", "model": args.model, "steps": args.steps,
                  "spp": args.spp, "seed": args.seed, "images": [str(p) for p in args.images],
                  "scene": str(args.scene), "bsdf_id": args.bsdf_id}
    for key in ("code", "start", "pull_strength", "code_strength", "code_held_out_losses", "held_out_losses",
                "albedo_rejected", "attempts", "analytic", "albedo_max", "diverged"):
        if key in summary:
            provenance[key] = summary[key]
    name = args.output.name.split(".")[0]
    write_network(args.output, weights, name, provenance, base=base)
    # A zero network is never sampled: the nbrdf BSDF samples its base (nbrdf_mitsuba.base).
    summary["sampling"] = "base" if base is not None else fit_sampling(args.output)
    return summary
