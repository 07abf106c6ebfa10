"""``python -m nbrdf_mitsuba.estimate`` (issue 33): the user's errors, a synthetic recovery,
determinism, a diverging step taken back, and the common initialisation's twin.

Tiny on purpose: 16 x 16 images of a sphere seen by two sensors, a few steps."""

from __future__ import annotations

import json
import math
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

SENSOR = """
    <sensor type="perspective">
        <float name="fov" value="30"/>
        <transform name="to_world"><lookat origin="{origin}" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/>
            <rfilter type="box"/></film>
    </sensor>"""
SCENE = """<scene version="3.0.0">
    <default name="res" value="16"/>
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    {sensors}
    <bsdf type="roughplastic" id="mat">
        <rgb name="diffuse_reflectance" value="0.6, 0.2, 0.1"/>
        <float name="alpha" value="0.15"/>
    </bsdf>
    <shape type="sphere"><ref id="mat"/></shape>
    <emitter type="point"><point name="position" x="3" y="3" z="4"/><rgb name="intensity" value="40"/></emitter>
    <emitter type="constant"><rgb name="radiance" value="0.1"/></emitter>
</scene>"""
VIEWS = ["0, 0, 4", "3, 1, 2.5"]
NOVEL = "-3, 1.5, 2.5"
TRUTH = {"diffuse_reflectance": [0.6, 0.2, 0.1], "alpha": 0.15}
AE_FILE = Path(__file__).resolve().parent.parent / "nbrdf-core" / "data" / "models" / "autoencoder.json"


def write_scene(path: Path, origins=VIEWS) -> Path:
    path.write_text(SCENE.format(sensors="".join(SENSOR.format(origin=o) for o in origins)))
    return path


def render_views(scene_file: Path, out: Path, spp=128, prefix="view", **defines) -> list[Path]:
    scene = mi.load_file(str(scene_file), **defines)
    paths = []
    for i in range(len(scene.sensors())):
        image = mi.render(scene, sensor=i, spp=spp, seed=99)
        paths.append(out / f"{prefix}{i}.exr")
        mi.Bitmap(image).write(str(paths[-1]))
    return paths


@pytest.fixture
def setup(llvm_variant, tmp_path):
    scene = write_scene(tmp_path / "scene.xml")
    return scene, render_views(scene, tmp_path)


def run(scene, images, out, *extra):
    from nbrdf_mitsuba import estimate

    return estimate.main([str(scene), "--images", *map(str, images), "--bsdf-id", "mat", "-o", str(out), "-q", *extra])


def expect_error(capsys, status, out, *needles):
    assert status == 2
    message = capsys.readouterr().err
    for needle in needles:
        assert needle in message, message
    assert not out.exists()


def test_wrong_image_count_and_size(setup, tmp_path, capsys):
    scene, images = setup
    out = tmp_path / "out.json"
    expect_error(capsys, run(scene, images[:1], out, "--model", "roughplastic"), out, "1 images for 2 sensors")
    small = tmp_path / "small.exr"
    mi.Bitmap(np.ones((8, 8, 3), dtype=np.float32)).write(str(small))
    expect_error(capsys, run(scene, [images[0], small], out, "--model", "roughplastic"), out,
                 "image 1", "is 8x8, sensor 1 renders 16x16")


def test_nan_pixels_are_an_error(setup, tmp_path, capsys):
    scene, images = setup
    array = np.array(mi.Bitmap(str(images[1])), dtype=np.float32)
    array[3, 5, 1] = np.nan
    bad = tmp_path / "nan.exr"
    mi.Bitmap(array).write(str(bad))
    out = tmp_path / "out.nbrdf.json"
    expect_error(capsys, run(scene, [images[0], bad], out), out, "1 pixels are NaN or infinite", "x=5, y=3")


def test_missing_bsdf_and_non_differentiable_variant(setup, tmp_path, capsys):
    scene, images = setup
    out = tmp_path / "out.nbrdf.json"
    status = run(scene, images, out, "--bsdf-id", "nothing")
    expect_error(capsys, status, out, "no BSDF with id 'nothing'", "mat")
    expect_error(capsys, run(scene, images, out, "--variant", "scalar_rgb"), out, "not differentiable")
    mi.set_variant("llvm_ad_rgb")


def test_images_that_do_not_see_the_object_are_an_error(llvm_variant, tmp_path, capsys):
    # Sensors behind the light looking away from the sphere: the images hold the background only.
    scene = write_scene(tmp_path / "away.xml", ["0, 0, 4"])
    scene.write_text(scene.read_text().replace('target="0, 0, 0"', 'target="0, 0, 8"'))
    images = render_views(scene, tmp_path, spp=4)
    out = tmp_path / "out.json"
    expect_error(capsys, run(scene, images, out, "--model", "roughplastic", "--steps", "2"), out,
                 "do not depend on BSDF 'mat'")


def test_a_diverging_estimate_is_failed_work(setup, tmp_path, monkeypatch, capsys):
    """An estimate whose loss stays non-finite through every halving of the step has failed (exit
    status 1, not the input's 2), and writes nothing."""
    from nbrdf_mitsuba.estimate import estimator, optimiser

    monkeypatch.setattr(estimator.Estimator, "loss_and_grad", lambda self, phase, theta, step: (math.nan, None))
    scene, images = setup
    out = tmp_path / "out.json"
    assert run(scene, images, out, "--model", "roughplastic", "--steps", "2") == 1
    message = capsys.readouterr().err
    assert message.startswith("error: the optimisation diverged") and f"{optimiser.MAX_HALVINGS} halvings" in message
    assert not out.exists()

def test_a_diverging_candidate_is_left_out_not_the_estimate(setup, tmp_path, monkeypatch):
    """Candidates of the held-out choice whose fit runs away through every halving (here the first
    network candidate and the roughconductor fit, made to) are left out of the choice and named
    in the provenance; the estimate goes on with the others and the whole budget of halvings, and
    writes a network."""
    from nbrdf_mitsuba.estimate import estimator, plan

    real_loss = estimator.Estimator.loss_and_grad
    first_weights = []

    def loss_and_grad(self, phase, theta, step):
        if phase.kind == "weights" and not first_weights:
            first_weights.append(phase)
        if (phase.kind == "weights" and phase is first_weights[0]) or \
                getattr(self.model, "kind", None) == "roughconductor":
            return math.nan, None
        return real_loss(self, phase, theta, step)

    real_choose = estimator.choose_start
    halvings_after = []

    def choose_start(est, starts, plan, bar):
        chosen = real_choose(est, starts, plan, bar)
        halvings_after.append(est.halvings)
        return chosen

    real_run = estimator.Estimator.run

    def run_phase(self, phase, bar, first_step):
        theta = real_run(self, phase, bar, first_step)
        halvings_after.append(self.halvings)
        return theta

    monkeypatch.setattr(estimator.Estimator, "loss_and_grad", loss_and_grad)
    monkeypatch.setattr(estimator.Estimator, "run", run_phase)
    monkeypatch.setattr(estimator, "choose_start", choose_start)
    scene, images = setup
    out = tmp_path / "prior.nbrdf.json"
    assert run(scene, images, out, "--steps", "6", "--spp", "2", "--threads", "1") == 0
    provenance = json.loads(out.read_text())["provenance"]
    first = str(plan.PULL_STRENGTHS[0])
    assert provenance["diverged"] == [first, "roughconductor"]
    assert set(provenance["held_out_losses"]) == ({str(s) for s in plan.PULL_STRENGTHS[1:]}
                                                  | set(plan.ANALYTIC_MODELS) - {"roughconductor"})
    assert provenance["attempts"] == 1
    # Their halvings (one more than the budget) were given back: none are counted after them.
    assert halvings_after == [0] * len(halvings_after) and len(halvings_after) >= 4, halvings_after


def run_away_in_the_first_continuation(monkeypatch, estimator) -> tuple[list, list]:
    """Makes the first attempt's chosen network candidate's fit over every view run away (every
    step non-finite), with no analytic candidates; returns the held-out choices made (one per
    attempt) and that continuation's phase once it has run."""
    chosen, real_choose, real_loss, continuation = [], estimator.choose_start, estimator.Estimator.loss_and_grad, []

    def choose_start(est, starts, plan, bar):
        chosen.append(real_choose(est, starts, plan, bar))
        return chosen[-1]

    def loss_and_grad(self, phase, theta, step):
        if len(chosen) == 1 and phase.kind == "weights" and not continuation:
            continuation.append(phase)  # the first attempt's weights phase after the choice
        if continuation and phase is continuation[0]:
            return math.nan, None
        return real_loss(self, phase, theta, step)

    monkeypatch.setattr(estimator, "choose_start", choose_start)
    monkeypatch.setattr(estimator, "fit_analytic_candidates", lambda loaders, plan, bar: estimator.AnalyticCandidates())
    monkeypatch.setattr(estimator.Estimator, "loss_and_grad", loss_and_grad)
    return chosen, continuation


def test_a_runaway_continuation_stays_named_where_the_albedo_check_then_rejects_its_attempt(setup, tmp_path,
                                                                                          monkeypatch):
    """Where the chosen network candidate's fit over every view runs away and the albedo check then
    rejects the network kept, the next attempt runs, and the provenance still names the first
    attempt's continuation among what diverged (as it names its rejected albedo)."""
    from nbrdf_mitsuba.estimate import estimator

    chosen, continuation = run_away_in_the_first_continuation(monkeypatch, estimator)
    real_albedo, rejections = estimator.albedo_check, []

    def albedo_check(weights):
        if continuation and not rejections:  # the first attempt's final network
            rejections.append(weights)
            return 2.0, False
        return real_albedo(weights)

    monkeypatch.setattr(estimator, "albedo_check", albedo_check)
    scene, images = setup
    out = tmp_path / "prior.nbrdf.json"
    assert run(scene, images, out, "--steps", "6", "--spp", "2", "--threads", "1") == 0
    provenance = json.loads(out.read_text())["provenance"]
    assert len(chosen) == 2 and provenance["attempts"] == 2 and len(rejections) == 1
    assert provenance["albedo_rejected"] == {"final": 2.0}
    assert provenance["diverged"] == [estimator.CONTINUATION]


def test_a_chosen_network_whose_fit_on_every_view_runs_away_is_kept_as_chosen(setup, tmp_path, monkeypatch):
    """Where the chosen network candidate's fit over every view runs away through every halving,
    the estimate writes that candidate's network as the held-out view chose it and names the
    continuation in the provenance, instead of failing."""
    from nbrdf_mitsuba.estimate import estimator

    chosen, _ = run_away_in_the_first_continuation(monkeypatch, estimator)
    scene, images = setup
    out = tmp_path / "prior.nbrdf.json"
    assert run(scene, images, out, "--steps", "6", "--spp", "2", "--threads", "1") == 0
    document = json.loads(out.read_text())
    assert document["provenance"]["diverged"] == [estimator.CONTINUATION]
    # One attempt: the albedo check kept the chosen candidate, and it is the network written.
    assert len(chosen) == 1 and document["provenance"]["attempts"] == 1
    choice, _, _, fitted, _ = chosen[0]
    assert document["provenance"]["pull_strength"] == choice[1]
    flat = np.concatenate([np.concatenate([layer["weights"], layer["bias"]]) for layer in document["layers"]])
    np.testing.assert_allclose(flat, np.float32(fitted), rtol=0, atol=1e-6)


def test_an_unexpected_error_is_one_line_and_a_hint_not_a_traceback(setup, tmp_path, monkeypatch, capsys):
    from nbrdf_mitsuba.estimate import estimator

    def broken(self, phase, theta, step):
        raise KeyError("a key the estimate lost")

    monkeypatch.setattr(estimator.Estimator, "loss_and_grad", broken)
    scene, images = setup
    out = tmp_path / "out.json"
    assert run(scene, images, out, "--model", "roughplastic", "--steps", "1") == 1
    message = capsys.readouterr().err
    assert message.startswith("error: unexpected KeyError: 'a key the estimate lost'\nhint: "), message
    assert "Traceback" not in message and not out.exists()

def test_analytic_recovery(setup, tmp_path):
    scene, images = setup
    out = tmp_path / "fit.json"
    assert run(scene, images, out, "--model", "roughplastic", "--steps", "40", "--spp", "4") == 0
    fitted = json.loads(out.read_text())
    assert fitted["type"] == "roughplastic"
    rgb = np.array(fitted["diffuse_reflectance"]["value"])
    start_error = np.abs(0.5 - np.array(TRUTH["diffuse_reflectance"])).sum() + abs(0.2 - TRUTH["alpha"])
    error = np.abs(rgb - TRUTH["diffuse_reflectance"]).sum() + abs(fitted["alpha"] - TRUTH["alpha"])
    assert error < 0.5 * start_error, (fitted, error, start_error)
    mi.load_dict(fitted)  # a dictionary Mitsuba loads


SHAPE = '<shape type="sphere"><ref id="mat"/></shape>'
#: A second, smaller sphere in front of the first, seen by both views.
SECOND_SHAPE = ('<shape type="sphere"><point name="center" x="0.6" y="-0.6" z="1.2"/>'
                '<float name="radius" value="0.25"/><ref id="mat"/></shape>')


def layout_scene(path: Path, layout: str) -> Path:
    """The tests' scene with its BSDF ``mat`` nested in the sphere (``nested``), inside a
    ``twosided`` nested in it (``twosided``), or declared at the top and referenced by two
    spheres (``shared``)."""
    text = write_scene(path).read_text()
    start, stop = text.index('<bsdf type="roughplastic"'), text.index("</bsdf>") + len("</bsdf>")
    bsdf, without = text[start:stop], text[:start] + text[stop:]
    if layout == "nested":
        text = without.replace(SHAPE, f'<shape type="sphere">{bsdf}</shape>')
    elif layout == "twosided":
        text = without.replace(SHAPE, f'<shape type="sphere"><bsdf type="twosided">{bsdf}</bsdf></shape>')
    else:
        text = text.replace(SHAPE, SHAPE + SECOND_SHAPE)
    assert text.count('<bsdf type="roughplastic" id="mat">') == 1 and text != path.read_text()
    path.write_text(text)
    return path


@pytest.mark.parametrize("layout", ["nested", "twosided", "shared"])
def test_the_bsdf_is_found_by_the_object_wherever_it_is_declared(llvm_variant, tmp_path, layout):
    """``mi.traverse`` names a BSDF nested in its shape (or in a ``twosided``) by its path in the
    scene, not by its id: the estimate finds the marked BSDF by the object. For an analytic model
    and for a network, the estimate moves every parameter from its start and writes a file Mitsuba
    loads; the analytic one equals the estimate of the same BSDF declared at the top of the scene
    (the same images, seeds and steps)."""
    from nbrdf_mitsuba.estimate.models import Analytic, common_initialisation

    scene = layout_scene(tmp_path / f"{layout}.xml", layout)
    images = render_views(scene, tmp_path, spp=32)
    common = ("--steps", "2", "--spp", "2", "--threads", "1")
    fitted = tmp_path / "principled.json"
    assert run(scene, images, fitted, "--model", "principled", *common) == 0
    bsdf = json.loads(fitted.read_text())
    for key, size, _, _, start in Analytic.PARAMETERS["principled"]:
        value = bsdf[key.split(".")[0]]
        values = np.array(value["value"] if size == 3 else [value])
        assert np.all(np.abs(values - start) > 1e-3), (key, values, start)
    mi.load_dict(bsdf)
    if layout != "shared":  # the same scene but for where the BSDF is declared
        reference = tmp_path / "top.json"
        assert run(write_scene(tmp_path / "top.xml"), images, reference, "--model", "principled", *common) == 0
        assert bsdf == json.loads(reference.read_text())
    network = tmp_path / "network.nbrdf.json"
    assert run(scene, images, network, "--model", "nbrdf-no-prior", *common) == 0
    layers = json.loads(network.read_text())["layers"]
    flat = np.concatenate([np.r_[layer["weights"], layer["bias"]] for layer in layers]).astype(np.float32)
    assert np.all(np.isfinite(flat)) and np.abs(flat - common_initialisation()).max() > 1e-3
    mi.load_dict({"type": "nbrdf", "filename": str(network)})

def novel_error(tmp_path, network: Path, reference: np.ndarray) -> float:
    scene = write_scene(tmp_path / "novel.xml", [NOVEL])
    text = scene.read_text()
    start, stop = text.index('<bsdf type="roughplastic"'), text.index("</bsdf>") + len("</bsdf>")
    scene.write_text(text[:start] + f'<bsdf type="nbrdf" id="mat"><string name="filename" value="{network}"/></bsdf>'
                     + text[stop:])
    image = np.array(mi.render(mi.load_file(str(scene)), spp=64, seed=5))
    return float(np.mean((np.log1p(np.maximum(image, 0)) - np.log1p(reference)) ** 2))


def test_network_recovery_with_the_prior(setup, tmp_path):
    """Images of a roughplastic sphere: the estimate's loss falls, the written network is finite
    and has fit-phong's sampling, and on a view it did not train on it is closer to the truth
    than its start (the estimate after one step)."""
    scene, images = setup
    truth = write_scene(tmp_path / "truth.xml", [NOVEL])
    reference = np.array(mi.render(mi.load_file(str(truth)), spp=64, seed=5))
    errors = {}
    for steps in (1, 16):
        out = tmp_path / f"steps{steps}.nbrdf.json"
        assert run(scene, images, out, "--steps", str(steps), "--spp", "4") == 0
        network = json.loads(out.read_text())
        flat = np.concatenate([np.r_[layer["weights"], layer["bias"]] for layer in network["layers"]])
        assert flat.size == 675 and np.all(np.isfinite(flat))
        assert "sampling" in network and len(network["provenance"]["code"]) == 32
        errors[steps] = novel_error(tmp_path, out, reference)
    assert errors[16] < 0.8 * errors[1], errors


def test_deterministic_for_a_seed(setup, tmp_path):
    scene, images = setup
    outs = []
    for k, seed in enumerate((3, 3, 4)):
        outs.append(tmp_path / f"run{k}.json")
        assert run(scene, images, outs[-1], "--model", "principled", "--steps", "3", "--spp", "2",
                   "--seed", str(seed), "--threads", "1") == 0
    assert outs[0].read_bytes() == outs[1].read_bytes()
    assert outs[0].read_bytes() != outs[2].read_bytes()


class SilentBar:
    """What ``Estimator.run`` asks of its progress bar, showing nothing."""

    def update(self, n):
        pass

    def set_postfix(self, **kw):
        pass


def roughconductor_phase(setup, tmp_path, steps, penalty):
    """An estimator of the test scene's roughconductor and its one phase of ``steps`` steps,
    ``penalty(theta)`` added to its loss (how a test makes a step diverge)."""
    from nbrdf_mitsuba import estimate as E

    scene, images = setup
    model = E.Analytic("roughconductor")
    est = E.Estimator(E.Scene(scene, "mat", {}), model, images, 2, 0, 3, tmp_path)
    (phase,) = model.phases(steps)
    phase.penalty = penalty
    return est, phase


def test_a_non_finite_loss_steps_back_and_halves_the_step(setup, tmp_path):
    calls = []

    def penalty(theta):
        calls.append(1)
        return (math.nan if len(calls) == 2 else 0.0), np.zeros_like(theta)

    est, phase = roughconductor_phase(setup, tmp_path, 4, penalty)
    theta = est.run(phase, SilentBar(), 0)
    assert est.halvings == 1 and len(est.history) == 4 and np.all(np.isfinite(theta))


def test_a_run_away_loss_steps_back_to_the_phases_best(setup, tmp_path):
    """A finite loss growing step after step (as at 2 spp on 128x128 images) is taken back to
    the state of the phase's lowest loss, with half the step, not written as the estimate."""
    seen = []

    def penalty(theta):
        # The third evaluation runs away (a thousand times any image loss here).
        seen.append(theta.copy())
        return (1e3 if len(seen) == 3 else 0.0), np.zeros_like(theta)

    est, phase = roughconductor_phase(setup, tmp_path, 6, penalty)
    est.run(phase, SilentBar(), 0)
    lowest = int(np.argmin(est.history[:2]))
    assert est.halvings == 1 and len(est.history) == 6 and max(est.history) < 1.0
    # The step after the run-away restarts from the best of the two states before it.
    np.testing.assert_array_equal(seen[3], seen[lowest])


def test_common_initialisation_is_the_trainers_seed_0_start():
    from nbrdf_mitsuba.estimate.models import common_initialisation
    from nbrdf_tools.common.compare_materials import splitmix_uniforms

    flat = common_initialisation()
    assert flat.size == 675 and flat.dtype == np.float32
    # paper_init draws 6*21 + 21*21 + 21*3 weights from one SplitMix64(0, Init = 3, 0) stream.
    u = splitmix_uniforms(0, 3, 0, (6 * 21 + 21 * 21 + 21 * 3 + 3) // 4).ravel().astype(np.float32)
    expected = np.float32(0.05) * (np.float32(2.0) * u - np.float32(1.0))
    weights = np.concatenate([flat[:126], flat[147:588], flat[609:672]])
    np.testing.assert_array_equal(weights, expected[: weights.size])
    assert not flat[126:147].any() and not flat[588:609].any() and not flat[672:].any()


def test_snapshots_of_a_long_run_are_the_shorter_runs(setup, tmp_path):
    """The convergence study's premise: for a one-phase model, the parameters ``on_step`` sees
    after 2 steps of a 4-step run are those a 2-step run writes (same seeds, same steps)."""
    from nbrdf_mitsuba import estimate as E

    scene, images = setup
    seen = []

    def argv(out, steps):
        return E.parser().parse_args([str(scene), "--images", *map(str, images), "--bsdf-id", "mat", "-o", str(out),
                                      "--model", "roughplastic", "--steps", str(steps), "--spp", "2", "--threads",
                                      "1", "-q"])

    E.estimate(argv(tmp_path / "long.json", 4), lambda kind, done, theta: seen.append((kind, done, theta.copy())))
    assert [(kind, done) for kind, done, _ in seen] == [("analytic", k) for k in (1, 2, 3, 4)]
    E.estimate(argv(tmp_path / "short.json", 2))
    short = json.loads((tmp_path / "short.json").read_text())
    assert E.Analytic("roughplastic").result(seen[1][2]) == short
    assert E.Analytic("roughplastic").result(seen[3][2]) == json.loads((tmp_path / "long.json").read_text())


def test_prior_schedule_holds_out_a_view_only_where_it_can():
    from nbrdf_mitsuba.estimate.plan import FALLBACK_PULL_STRENGTH, PULL_STRENGTHS, schedule

    plan = schedule(100, 3, None)
    assert (plan.code_steps, plan.weight_steps, plan.pull_strengths, plan.candidate_steps) == (40, 60, PULL_STRENGTHS, 30)
    assert schedule(100, 1, None).pull_strengths == (FALLBACK_PULL_STRENGTH,)  # nothing to hold out
    assert schedule(1, 3, None).pull_strengths == (FALLBACK_PULL_STRENGTH,)  # no weight step to judge
    fixed = schedule(100, 3, 0.5)
    assert fixed.pull_strengths == (0.5,) and fixed.candidate_steps == 0


def test_the_analytic_candidates_are_fitted_wherever_the_held_out_view_chooses():
    """Each analytic model is fitted for a share of the estimate's steps as a candidate of the
    held-out choice, and the chosen one goes on for another share; with a fixed pull, one image or
    no weight step nothing is chosen and none is fitted."""
    from nbrdf_mitsuba.estimate.plan import ANALYTIC_MODELS, ANALYTIC_REFIT_SHARE, ANALYTIC_STEP_SHARE, schedule

    plan = schedule(100, 3, None)
    assert plan.analytic_models == ANALYTIC_MODELS == ("principled", "roughconductor", "roughplastic")
    assert (plan.analytic_steps, plan.analytic_refit_steps) == (round(100 * ANALYTIC_STEP_SHARE),
                                                                round(100 * ANALYTIC_REFIT_SHARE))
    assert plan.total_steps() == len(ANALYTIC_MODELS) * plan.analytic_steps + plan.attempt_steps()
    assert plan.attempt_steps() == len(plan.code_strengths) * 40 + 60 + (len(plan.pull_strengths) - 1) * 30
    for off in (schedule(100, 3, 0.5), schedule(100, 1, None), schedule(1, 3, None)):
        assert (off.analytic_steps, off.analytic_models, off.analytic_refit_steps) == (0, (), 0)
        assert off.total_steps() == off.attempt_steps()


def spy_on_views(monkeypatch, estimate_module, judge=None):
    """Records the views each step or screening renders (each takes their seeds once) and the views
    held_out_loss judges; ``judge(call_index, loss)`` may replace the held-out losses."""
    E = estimate_module
    rendered, judged = [], []
    seeds, held_out_loss = E.Estimator.seeds, E.Estimator.held_out_loss

    def spy_render(self, step):
        rendered.append(tuple(self.views))
        return seeds(self, step)

    def spy_judge(self, theta, view, *apply):
        judged.append(view)
        loss = held_out_loss(self, theta, view, *apply)
        return loss if judge is None else judge(len(judged) - 1, loss)

    monkeypatch.setattr(E.Estimator, "seeds", spy_render)
    monkeypatch.setattr(E.Estimator, "held_out_loss", spy_judge)
    return rendered, judged


def test_pull_strength_is_chosen_by_the_held_out_training_view(setup, tmp_path, monkeypatch, capsys):
    """The analytic candidates are fitted first; the code sees every training view; the network
    candidates (each pull strength from the decoded start) and the analytic ones see all but the
    last, the last alone judges them, the lowest held-out loss wins (here a network's: the
    analytic candidates' losses are made the worst), its fit goes on over every view for the rest
    of the weight phase, and a seed repeats it (the code penalty fixed at 0)."""
    from nbrdf_mitsuba import estimate as E
    from nbrdf_mitsuba.estimate import plan, priors

    scene, images = setup
    analytic = len(plan.ANALYTIC_MODELS)
    rendered, judged = spy_on_views(monkeypatch, E, judge=lambda call, loss: 1.0 if call % (analytic + 2) < analytic
                                    else loss)
    runs, run_phase = [], E.Estimator.run

    def spy_run(self, phase, bar, first_step):
        runs.append((phase.kind, phase.theta.copy(), run_phase(self, phase, bar, first_step)))
        return runs[-1][2]

    monkeypatch.setattr(E.Estimator, "run", spy_run)
    outs = [tmp_path / f"prior{k}.nbrdf.json" for k in range(2)]
    for out in outs:
        rendered.clear()
        runs.clear()
        assert run(scene, images, out, "--steps", "6", "--spp", "2", "--threads", "1", "--code-strength", "0") == 0
    provenance = json.loads(outs[0].read_text())["provenance"]
    losses = provenance["held_out_losses"]
    names = [str(s) for s in plan.PULL_STRENGTHS]
    assert set(losses) == set(names) | set(plan.ANALYTIC_MODELS)
    assert all(math.isfinite(v) for v in losses.values())
    # The first step from the decoded weights is the same for every strength (no pull there yet):
    # two candidate steps make them differ; ties would go to the first, the tightest.
    assert len({losses[k] for k in names}) > 1, losses
    best = min(names, key=losses.get)
    assert provenance["start"] == "decoded" and provenance["pull_strength"] == float(best)
    assert "analytic" not in provenance and "chose the" not in capsys.readouterr().out
    assert "albedo_rejected" not in provenance and 0 < provenance["albedo_max"] < priors.ALBEDO_BOUND
    assert judged == [1] * 2 * (analytic + len(names))  # the last training view, once per candidate and run
    # The analytic fits (3 steps each), the screening (49 starts) and code (2 steps) on both views;
    # the analytic fits and the network candidates (2 steps each) on view 0; the chosen one's fit
    # on both (the weight phase's other 2).
    assert rendered == [(0,)] * (3 * analytic) + [(0, 1)] * (49 + 2) + [(0,)] * (2 * len(names)) + \
        [(0, 1)] * 2, rendered
    # The runs: analytic fits, code, candidates, final; the last starts where the chosen
    # candidate's fit ended, every candidate from the decoded start.
    assert [kind for kind, _, _ in runs] == ["analytic"] * analytic + ["code"] + ["weights"] * (len(names) + 1)
    candidates = runs[analytic + 1:-1]
    np.testing.assert_array_equal(runs[-1][1], candidates[names.index(best)][2])
    assert all(np.array_equal(candidates[0][1], start) for _, start, _ in candidates)
    first, second = (json.loads(out.read_text()) for out in outs)
    assert first["layers"] == second["layers"] and provenance["held_out_losses"] == \
        second["provenance"]["held_out_losses"]


def test_an_analytic_candidate_that_wins_the_held_out_view_is_refitted_and_written_as_the_base(
        setup, tmp_path, monkeypatch, capsys):
    """Where an analytic fit (here roughplastic, made to) has the lowest held-out loss, its fit goes
    on over every view from where the candidate's ended, is recorded in the provenance, and the
    written network is a zero residual on it (file field ``base``): the written material renders
    as the fit itself, in BRDF space too; no pull or code strength is recorded; the command says
    which fit it chose."""
    from nbrdf_mitsuba import estimate as E
    from nbrdf_mitsuba.estimate import plan
    from nbrdf_tools.common.compare_materials import log_error

    scene, images = setup
    runs, run_phase = [], E.Estimator.run

    def spy_run(self, phase, bar, first_step):
        runs.append((phase.kind, phase.theta.copy(), run_phase(self, phase, bar, first_step)))
        return runs[-1][2]

    monkeypatch.setattr(E.Estimator, "run", spy_run)
    chosen = plan.ANALYTIC_MODELS.index("roughplastic")
    rendered, _ = spy_on_views(monkeypatch, E, judge=lambda call, loss: -1.0 if call == chosen else loss)
    out = tmp_path / "prior.nbrdf.json"
    assert run(scene, images, out, "--steps", "6", "--spp", "2", "--threads", "1", "--seed", "2") == 0
    assert "the held-out view chose the roughplastic fit" in capsys.readouterr().out
    document = json.loads(out.read_text())
    provenance = document["provenance"]
    assert provenance["start"] == "analytic" and provenance["analytic"]["type"] == "roughplastic"
    assert provenance["pull_strength"] is None and provenance["code_strength"] is None
    assert set(provenance["held_out_losses"]) == {str(s) for s in plan.PULL_STRENGTHS} | set(plan.ANALYTIC_MODELS)
    # The refit: on both views, from the roughplastic candidate's fitted parameters.
    assert runs[-1][0] == "analytic" and rendered[-1] == (0, 1)
    np.testing.assert_array_equal(runs[-1][1], runs[chosen][2])
    assert document["base"] == provenance["analytic"]
    assert all(not any(layer["weights"]) and not any(layer["bias"]) for layer in document["layers"])
    assert "sampling" not in document  # the base samples itself
    estimate = mi.load_dict({"type": "nbrdf", "filename": str(out)})
    assert log_error(mi.load_dict(document["base"]), estimate, "uniform", 4000) < 1e-6


def test_an_analytic_candidate_wins_unless_a_network_is_lower_by_more_than_the_margin():
    """The rule at its boundary: the network candidate's held-out loss times ``ANALYTIC_MARGIN``
    against the analytic one's; a tie goes to the analytic fit."""
    from nbrdf_mitsuba.estimate import estimator

    margin = estimator.ANALYTIC_MARGIN
    assert 1.0 < margin < 1.5
    assert estimator.analytic_wins(1.0, 1.0) and estimator.analytic_wins(0.9, 1.0)
    assert estimator.analytic_wins(margin * 0.999, 1.0) and estimator.analytic_wins(margin, 1.0)
    assert not estimator.analytic_wins(margin * 1.001, 1.0) and not estimator.analytic_wins(2.0, 1.0)


@pytest.mark.parametrize("analytic_ratio, start", [(1.03, "analytic"), (1.3, "decoded")])
def test_a_network_candidate_lower_within_the_margin_leaves_the_analytic_fit_chosen(setup, tmp_path, monkeypatch,
                                                                                   analytic_ratio, start):
    """The held-out losses made so that the best network candidate is lower than the best analytic
    one (roughconductor) by ``analytic_ratio``: within the margin the analytic fit is written, beyond
    it the network; the provenance keeps the losses the choice was made on."""
    from nbrdf_mitsuba import estimate as E
    from nbrdf_mitsuba.estimate import plan

    analytic = len(plan.ANALYTIC_MODELS)
    losses = {i: 10.0 for i in range(analytic)}
    losses[plan.ANALYTIC_MODELS.index("roughconductor")] = analytic_ratio
    losses[analytic] = 1.0  # the first network candidate; the second keeps its real (higher) loss
    spy_on_views(monkeypatch, E, judge=lambda call, loss: losses.get(call, max(loss, 5.0)))
    scene, images = setup
    out = tmp_path / "prior.nbrdf.json"
    assert run(scene, images, out, "--steps", "6", "--spp", "2", "--threads", "1") == 0
    provenance = json.loads(out.read_text())["provenance"]
    held_out = provenance["held_out_losses"]
    assert held_out["roughconductor"] == analytic_ratio and held_out[str(plan.PULL_STRENGTHS[0])] == 1.0
    assert provenance["start"] == start
    if start == "analytic":
        assert provenance["analytic"]["type"] == "roughconductor"
    else:
        assert provenance["pull_strength"] == plan.PULL_STRENGTHS[0] and "analytic" not in provenance


def test_image_loss_is_linear_in_the_render(llvm_variant):
    """``image_loss`` against a float64 oracle (two views), and the property it is chosen for: its
    gradient with respect to a render is linear in the render, so the mean of its gradients at
    noisy renders is its gradient at their mean render (a decorrelated primal pass then settles
    where the mean render is the reference). Under noise like a sub-pixel highlight's (most
    samples miss, a few are bright) the squared error of ``ln(1 + x)`` has no such property."""
    import drjit as dr

    from nbrdf_mitsuba.estimate.renders import image_loss

    rng = np.random.default_rng(3)
    references = [rng.uniform(0.0, 4.0, (4, 5, 3)) for _ in range(2)]
    images = [r * rng.uniform(0.5, 1.5, r.shape) for r in references]
    oracle = np.mean([np.mean(((x - r) / (1 + r)) ** 2) for x, r in zip(images, references)])
    value = image_loss([mi.TensorXf(x) for x in images], [mi.TensorXf(r) for r in references])
    assert float(np.asarray(value.numpy()).reshape(-1)[0]) == pytest.approx(oracle, rel=1e-5)

    def gradient(loss, x, reference):
        image = mi.TensorXf(x)
        dr.enable_grad(image)
        dr.backward(loss([image], [mi.TensorXf(reference)]))
        return np.asarray(dr.grad(image).numpy(), np.float64)

    def log_loss(images, references):  # the squared error of ln(1 + x), of which image_loss is the first-order twin
        d = dr.log(1.0 + images[0]) - dr.log(1.0 + references[0])
        return dr.mean(dr.square(d), axis=None)

    reference = references[0]
    renders = [reference * np.where(rng.random(reference.shape) < 0.125, 6.6, 0.2) for _ in range(64)]
    mean = np.mean(renders, axis=0)
    for loss, linear in ((image_loss, True), (log_loss, False)):
        at_mean = gradient(loss, mean, reference)
        mean_of = np.mean([gradient(loss, x, reference) for x in renders], axis=0)
        close = np.allclose(mean_of, at_mean, rtol=1e-4, atol=1e-6 * np.abs(at_mean).max())
        assert close == linear, (loss, np.abs(mean_of - at_mean).max(), np.abs(at_mean).max())


def test_code_penalty_and_its_gradient_against_a_float64_oracle():
    """The code phase's penalty, ``s mean(((z - m) / sd)^2)`` with ``m``, ``sd`` the training
    codes' mean and spread, equals a NumPy float64 oracle from the autoencoder file's anchors,
    and its gradient equals central differences of that oracle."""
    from nbrdf_mitsuba.estimate.priors import code_penalty
    from nbrdf_mitsuba.latent import Decoder

    anchors = np.asarray(json.loads(AE_FILE.read_text())["anchors"], dtype=np.float64)
    m, sd = anchors.mean(axis=0), anchors.std(axis=0)
    strength = 1e-3

    def oracle(z):
        return strength * np.mean(((z - m) / sd) ** 2)

    penalty = code_penalty(*Decoder(AE_FILE).code_distribution(), strength)
    rng = np.random.default_rng(7)
    for z in (m + 2.5 * sd * rng.standard_normal(m.size), anchors[3] + 0.1):
        value, grad = penalty(z)
        # The decoder holds its anchors in float32 (the oracle reads the file's float64 text).
        assert value == pytest.approx(oracle(z), rel=1e-7)
        h = 1e-5
        for f in (oracle, lambda x: penalty(x)[0]):
            numeric = np.array([(f(z + h * e) - f(z - h * e)) / (2 * h) for e in np.eye(z.size)])
            assert np.abs(grad).max() > 0
            np.testing.assert_allclose(grad, numeric, rtol=1e-6, atol=1e-9 * np.abs(numeric).max())
    assert code_penalty(m, sd * sd, 0.0) is None  # strength 0: no penalty at all, not a zero one


def test_pull_penalty_against_a_float64_oracle(llvm_variant):
    """The weight phase's pull, ``s mean((z(x) - z(c))^2)`` over the pull's direction pairs and the
    three channels, ``z = ln(1 + f)`` of the network: its value equals an oracle built from
    ``nbrdf_tools.common.network`` (the float64 forward pass and network input, at the same uniform
    hemisphere warp in NumPy), and its hand-written gradient equals central differences."""
    from nbrdf_mitsuba.estimate import priors
    from nbrdf_tools.common import network as N

    rng = np.random.default_rng(3)
    center = 0.3 * rng.standard_normal(675)
    center[-3:] += 3.0  # every output positive, so that ln(1 + f) is the output layer's value
    strength = 0.1
    u = np.random.default_rng(priors.PULL_SEED).random((4, priors.PULL_PAIRS)).astype(np.float32).astype(np.float64)

    def hemisphere(u1, u2):
        r = np.sqrt(1 - u1 * u1)
        return np.stack([r * np.cos(2 * np.pi * u2), r * np.sin(2 * np.pi * u2), u1], axis=1)

    inputs = N.network_input(hemisphere(u[0], u[1]), hemisphere(u[2], u[3]))
    np.testing.assert_allclose(priors._pull_inputs(), inputs, atol=2e-5)

    def layers(flat):  # docs/design.md section 4: per layer W (inputs x outputs, row-major), then b
        out, at = [], 0
        for n_in, n_out in ((6, 21), (21, 21), (21, 3)):
            out.append((flat[at:at + n_in * n_out].reshape(n_in, n_out), flat[at + n_in * n_out:at + n_in * n_out + n_out]))
            at += n_in * n_out + n_out
        return out

    def oracle(x):
        z, z_center = (np.log1p(N.forward(layers(w), inputs)) for w in (x, center))
        return strength * np.mean((z - z_center) ** 2)

    pull = priors.pull_penalty(center, strength)
    x = center + 0.05 * rng.standard_normal(675)
    value, grad = pull(x)
    assert value > 0 and value == pytest.approx(oracle(x), rel=1e-3)  # float32 directions in the pull
    assert pull(center)[0] == 0 and not np.any(pull(center)[1])
    h = 1e-6
    picks = rng.choice(675, 40, replace=False)
    numeric = np.array([(pull(x + h * e)[0] - pull(x - h * e)[0]) / (2 * h) for e in np.eye(675)[picks]])
    assert np.abs(grad[picks]).max() > 0
    np.testing.assert_allclose(grad[picks], numeric, rtol=1e-5, atol=1e-7 * np.abs(numeric).max())
    assert priors.pull_penalty(center, 0.0) is None  # strength 0: no pull at all, not a zero one


def test_code_strength_schedule():
    from nbrdf_mitsuba.estimate.plan import CODE_STRENGTHS, FALLBACK_CODE_STRENGTH, schedule

    assert CODE_STRENGTHS == (FALLBACK_CODE_STRENGTH,)  # one code phase (docs/experiments.md)
    plan = schedule(100, 3, None)
    assert plan.code_strengths == CODE_STRENGTHS and plan.candidate_steps == 30
    assert schedule(100, 3, None, 0.0).code_strengths == (0.0,)
    assert schedule(100, 1, None).code_strengths == (FALLBACK_CODE_STRENGTH,)  # nothing to hold out
    assert schedule(100, 3, 0.5).code_strengths == (FALLBACK_CODE_STRENGTH,)  # a fixed pull fixes both
    assert schedule(100, 3, None, 1e-3).code_strengths == (1e-3,)
    both = schedule(100, 3, 0.5, 0.25)
    assert both.code_strengths == (0.25,) and both.candidate_steps == 0


def test_code_strength_is_chosen_by_the_held_out_view_before_the_candidates(setup, tmp_path, monkeypatch):
    """With several code strengths each gets its own code phase (on every training view); the
    held-out view judges their decoded networks, and only the best code's start runs the pull's
    candidates (on all views but the last, as the analytic fits), which the same view judges; the
    code strength is recorded with both codes' held-out losses, and a seed repeats it."""
    from nbrdf_mitsuba import estimate as E
    from nbrdf_mitsuba.estimate import plan

    monkeypatch.setattr(plan, "CODE_STRENGTHS", (0.0, 1e-3))
    names = [str(w) for w in plan.PULL_STRENGTHS] + list(plan.ANALYTIC_MODELS)
    analytic = len(plan.ANALYTIC_MODELS)
    judged_per_run = len(plan.CODE_STRENGTHS) + len(names)
    scene, images = setup
    # The analytic fits (judged first) made the worst candidates here, so that a decoded one (and its
    # code) is chosen.
    rendered, judged = spy_on_views(monkeypatch, E, judge=lambda call, loss: 1.0 if call % judged_per_run < analytic
                                    else loss)
    outs = [tmp_path / f"code{k}.nbrdf.json" for k in range(2)]
    for out in outs:
        rendered.clear()
        assert run(scene, images, out, "--steps", "6", "--spp", "2", "--threads", "1") == 0
    provenance = json.loads(outs[0].read_text())["provenance"]
    codes, losses = provenance["code_held_out_losses"], provenance["held_out_losses"]
    assert set(codes) == {str(c) for c in plan.CODE_STRENGTHS} and set(losses) == set(names)
    assert all(math.isfinite(v) for v in [*codes.values(), *losses.values()]) and len(set(codes.values())) > 1
    best = min(plan.CODE_STRENGTHS, key=lambda c: codes[str(c)])
    assert (provenance["start"], provenance["code_strength"]) == ("decoded", best)
    assert judged == [1] * (2 * judged_per_run)  # the last training view: each code, then each candidate
    # The analytic fits (3 steps each) on view 0; screening (49) and a code phase per strength (2
    # steps each) on both views, the network candidates (2 steps each) on view 0; the chosen one's
    # fit on both views (2 more steps).
    network = len(plan.PULL_STRENGTHS)
    assert rendered == [(0,)] * (3 * analytic) + [(0, 1)] * (49 + 2 * len(plan.CODE_STRENGTHS)) + \
        [(0,)] * (2 * network) + [(0, 1)] * 2
    first, second = (json.loads(out.read_text()) for out in outs)
    assert first["layers"] == second["layers"] and losses == second["provenance"]["held_out_losses"]


def test_code_strength_0_is_the_estimate_without_the_code_penalty(setup, tmp_path, monkeypatch):
    """With code strengths 0 and 1e-3, where the held-out view picks 0 the estimate is the one of
    ``--code-strength 0`` (one code phase, without the penalty) weight for weight, its candidates'
    held-out losses that run's bit for bit; the other code was judged too."""
    from nbrdf_mitsuba import estimate as E
    from nbrdf_mitsuba.estimate import plan

    monkeypatch.setattr(plan, "CODE_STRENGTHS", (0.0, 1e-3))
    forced = {}  # judge call -> loss, per run: code 0 and the first candidate win
    _, judged = spy_on_views(monkeypatch, E, judge=lambda call, loss: forced.get(call, loss))
    scene, images = setup
    nets = {}
    first = len(plan.ANALYTIC_MODELS)  # the analytic fits are judged first
    for name, extra, force in (("fixed", ("--code-strength", "0"), {first: -1.0}),
                               ("chosen", (), {first: -1.0, first + len(plan.CODE_STRENGTHS): -1.0})):
        judged.clear()
        forced.clear()
        forced.update(force)
        nets[name] = tmp_path / f"{name}.nbrdf.json"
        assert run(scene, images, nets[name], "--steps", "6", "--spp", "2", "--threads", "1", *extra) == 0
    fixed, chosen = (json.loads(nets[k].read_text()) for k in ("fixed", "chosen"))
    assert chosen["provenance"]["code_strength"] == fixed["provenance"]["code_strength"] == 0.0
    assert chosen["provenance"]["pull_strength"] == fixed["provenance"]["pull_strength"] == plan.PULL_STRENGTHS[0]
    assert chosen["layers"] == fixed["layers"] and chosen["provenance"]["code"] == fixed["provenance"]["code"]
    assert chosen["provenance"]["held_out_losses"] == fixed["provenance"]["held_out_losses"]
    codes = chosen["provenance"]["code_held_out_losses"]
    assert set(codes) == {str(c) for c in plan.CODE_STRENGTHS} and "code_held_out_losses" not in fixed["provenance"]
    assert all(math.isfinite(v) and v > 0 for k, v in codes.items() if k != "0.0")


def test_code_strength_must_be_finite_and_non_negative(setup, tmp_path, capsys):
    scene, images = setup
    out = tmp_path / "out.nbrdf.json"
    for value in ("-1", "nan"):
        expect_error(capsys, run(scene, images, out, "--code-strength", value), out, "--code-strength must be")


def test_former_flag_names_still_work_with_a_note_and_are_not_listed(capsys):
    """``--prior-weight`` and ``--code-prior`` set the pull strength and the code strength as
    ``--pull-strength`` and ``--code-strength`` do, with a note on stderr naming the new flag;
    ``--help`` lists only the new names."""
    from nbrdf_mitsuba.estimate.cli import parser

    base = ["scene.xml", "--images", "a.exr", "--bsdf-id", "mat", "-o", "out.nbrdf.json"]
    former = parser().parse_args([*base, "--prior-weight", "0.25", "--code-prior", "0.5"])
    notes = capsys.readouterr().err
    current = parser().parse_args([*base, "--pull-strength", "0.25", "--code-strength", "0.5"])
    assert vars(former) == vars(current) and (current.pull_strength, current.code_strength) == (0.25, 0.5)
    assert "--prior-weight is deprecated: use --pull-strength" in notes
    assert "--code-prior is deprecated: use --code-strength" in notes
    assert capsys.readouterr().err == ""  # the new names: no note
    with pytest.raises(SystemExit):
        parser().parse_args(["--help"])
    usage = capsys.readouterr().out
    assert "--pull-strength" in usage and "--code-strength" in usage
    assert "--prior-weight" not in usage and "--code-prior" not in usage

def constant_network(value: float) -> np.ndarray:
    """Flat width-21 weights of ``f = value`` everywhere (every weight 0, the output bias ln(1 + f))."""
    flat = np.zeros(675)
    flat[-3:] = np.log1p(value)
    return flat


def test_directional_albedo_against_closed_form_and_a_direct_integral(llvm_variant):
    """The albedo check's half-vector quadrature: a constant ``f = c`` reflects ``pi c`` at every
    incidence angle; a network with a narrow peak at the half vector, ``f = e^(k max(cos th_h - t,
    0)) - 1``, matches a direct float64 integral over the view directions (``nbrdf_tools.common.network``'s
    forward pass and input, a fine grid in ``cos theta_v`` and ``phi_v``)."""
    from nbrdf_mitsuba.estimate import priors
    from nbrdf_tools.common import network as N

    albedo = priors.directional_albedo(constant_network(0.2))
    np.testing.assert_allclose(albedo, np.pi * 0.2, rtol=2e-4)

    k, t = 60.0, 0.95  # 18 degrees wide in theta_h at its base, f = e^3 - 1 at its top
    W1, b1 = np.zeros((6, 21)), np.zeros(21)
    W1[2, 0], b1[0] = 1.0, -t  # hidden unit 0: cos theta_h - t
    W2, W3 = np.zeros((21, 21)), np.zeros((21, 3))
    W2[0, 0] = 1.0
    W3[0] = k * np.array([1.0, 0.5, 0.2])
    peaked = np.concatenate([W1.ravel(), b1, W2.ravel(), np.zeros(21), W3.ravel(), np.zeros(3)])
    albedo = priors.directional_albedo(peaked)

    n = 500
    mu = (np.arange(n) + 0.5) / n  # cos theta_v, so that d v = d mu d phi
    phi = 2 * np.pi * (np.arange(2 * n) + 0.5) / (2 * n)
    mu, phi = (a.ravel() for a in np.meshgrid(mu, phi, indexing="ij"))
    r = np.sqrt(1 - mu * mu)
    view = np.stack([r * np.cos(phi), r * np.sin(phi), mu], axis=1)
    layers = [(W1, b1), (W2, np.zeros(21)), (W3, np.zeros(3))]
    for row, degrees in enumerate(priors.ALBEDO_INCIDENCE):
        a = np.radians(degrees)
        light = np.tile([np.sin(a), 0.0, np.cos(a)], (len(mu), 1))
        f = N.forward(layers, N.network_input(view, light))
        direct = (f * mu[:, None]).sum(axis=0) * (1.0 / n) * (2 * np.pi / (2 * n))
        np.testing.assert_allclose(albedo[row], direct, rtol=2e-3, err_msg=f"{degrees} degrees")
    assert albedo[0, 0] > priors.ALBEDO_BOUND  # the peak is bright enough to matter for the bound


def test_the_albedo_bound_allows_above_one_only_what_the_lit_angles_show(llvm_variant):
    """The bound is 1, or the albedo up to ``ALBEDO_LIT_INCIDENCE`` where higher, plus the margin,
    never above ``ALBEDO_BOUND``: a uniformly bright network passes where a dim one with a bright
    grazing lobe (light where no training light falls square) does not. Constant networks reflect
    ``pi c`` at every angle (closed form), so the check's verdict follows from the bound alone."""
    from nbrdf_mitsuba.estimate import priors

    angles = np.asarray(priors.ALBEDO_INCIDENCE)
    lit = angles <= priors.ALBEDO_LIT_INCIDENCE
    assert lit.any() and not lit.all()

    def profile(square: float, grazing: float) -> np.ndarray:
        return np.where(lit, square, grazing)[:, None] * np.array([1.0, 0.5, 0.25])

    margin = 1 + priors.ALBEDO_MARGIN
    assert priors.albedo_bound(profile(0.4, 0.6)) == pytest.approx(margin)  # under 1: energy conservation
    assert priors.albedo_bound(profile(1.14, 1.2)) == pytest.approx(1.14 * margin)  # the images ask for it
    assert priors.albedo_bound(profile(0.46, 1.42)) == pytest.approx(margin)  # a bright grazing lobe alone: over it
    assert priors.albedo_bound(profile(2.0, 2.0)) == priors.ALBEDO_BOUND

    for c, passes in [(0.3, True), (1.2, True), (priors.ALBEDO_BOUND * 1.05, False)]:
        albedo, material = priors.albedo_check(constant_network(c / np.pi))
        assert albedo == pytest.approx(c, rel=1e-3) and material == passes, c


def test_a_decoded_candidate_that_reflects_more_than_it_receives_is_not_chosen(setup, tmp_path, monkeypatch):
    """With the bound below every network's albedo (0), no network candidate is chosen even where
    the held-out view prefers it: after every attempt of the prior the estimate is the best
    analytic candidate (the base of a zero network), and the provenance names the rejected candidates with their
    albedo (without analytic candidates, the common start:
    test_a_final_network_over_the_bound_falls_back_to_the_common_start)."""
    from nbrdf_mitsuba import estimate as E
    from nbrdf_mitsuba.estimate import estimator, plan, priors

    scene, images = setup
    # The held-out view prefers the first decoded candidate by far.
    first = len(plan.ANALYTIC_MODELS)
    spy_on_views(monkeypatch, E, judge=lambda call, loss: -1.0 if call == first else loss)
    monkeypatch.setattr(priors, "ALBEDO_BOUND", 0.0)
    prior = tmp_path / "prior.nbrdf.json"
    assert run(scene, images, prior, "--steps", "6", "--spp", "2", "--threads", "1", "--code-strength", "0") == 0
    provenance = json.loads(prior.read_text())["provenance"]
    losses = provenance["held_out_losses"]  # the last attempt's
    names = {str(s) for s in plan.PULL_STRENGTHS}
    assert set(losses) == names | set(plan.ANALYTIC_MODELS)
    best = min(plan.ANALYTIC_MODELS, key=losses.get)
    assert provenance["start"] == "analytic" and provenance["analytic"]["type"] == best
    assert provenance["pull_strength"] is None
    # Every attempt's candidates rejected, each attempt with its own seeds.
    prefixes = ["", "attempt 1: ", "attempt 2: "][:estimator.PRIOR_ATTEMPTS]
    assert set(provenance["albedo_rejected"]) == {f"{p}{s}" for p in prefixes for s in names}
    assert all(v > 0 for v in provenance["albedo_rejected"].values())
    assert provenance["attempts"] == estimator.PRIOR_ATTEMPTS


def test_every_network_estimate_records_its_albedo_and_warns_over_the_bound(setup, tmp_path, monkeypatch, capsys):
    """The written network's largest directional albedo is in its provenance; over the bound (here
    0, so any network) the estimate still writes it, with a warning on stderr."""
    from nbrdf_mitsuba.estimate import priors

    scene, images = setup
    out = tmp_path / "no-prior.nbrdf.json"
    assert run(scene, images, out, "--model", "nbrdf-no-prior", "--steps", "3", "--spp", "2") == 0
    albedo = json.loads(out.read_text())["provenance"]["albedo_max"]
    assert 0 < albedo < priors.ALBEDO_BOUND and "warning: the estimated network" not in capsys.readouterr().err
    monkeypatch.setattr(priors, "ALBEDO_BOUND", 0.0)
    assert run(scene, images, out, "--model", "nbrdf-no-prior", "--steps", "3", "--spp", "2") == 0
    assert "reflects up to" in capsys.readouterr().err and out.is_file()


def test_a_final_network_over_the_bound_falls_back_to_the_common_start(setup, tmp_path, monkeypatch):
    """Without a held-out choice (a fixed ``--pull-strength``) the decoded start's final network is
    checked too: over the bound, the written network is the nbrdf-no-prior estimate."""
    from nbrdf_mitsuba.estimate import estimator, priors

    scene, images = setup
    monkeypatch.setattr(priors, "ALBEDO_BOUND", 0.0)
    prior, no_prior = tmp_path / "prior.nbrdf.json", tmp_path / "no-prior.nbrdf.json"
    assert run(scene, images, prior, "--steps", "6", "--spp", "2", "--threads", "1", "--pull-strength", "0.1") == 0
    provenance = json.loads(prior.read_text())["provenance"]
    assert provenance["start"] == estimator.COMMON_START
    attempts = range(1, estimator.PRIOR_ATTEMPTS)
    assert set(provenance["albedo_rejected"]) == {"final"} | {f"attempt {k}: final" for k in attempts}
    assert "held_out_losses" not in provenance
    assert run(scene, images, no_prior, "--model", "nbrdf-no-prior", "--steps", "6", "--spp", "2",
               "--threads", "1") == 0
    assert json.loads(prior.read_text())["layers"] == json.loads(no_prior.read_text())["layers"]


def test_a_rejected_attempt_of_the_prior_is_tried_again_with_other_seeds(setup, tmp_path, monkeypatch):
    """Where the albedo check rejects the first attempt's networks (made to, here), the prior is
    tried again with other render seeds, and a network that passes is the estimate (``attempts``
    2); the first attempt's rejections are recorded, and a seed repeats it all."""
    from nbrdf_mitsuba.estimate import estimator, plan, priors

    scene, images = setup
    seeds, albedo = [], priors.directional_albedo

    def spy_albedo(flat):  # over the bound while the first attempt's seed is in use
        return albedo(flat) + (10.0 if seeds[-1] == 0 else 0.0)

    fit_codes = estimator.fit_codes

    def spy_fit_codes(est, decoder, plan, bar):
        seeds.append(est.seed)
        return fit_codes(est, decoder, plan, bar)

    monkeypatch.setattr(priors, "directional_albedo", spy_albedo)
    monkeypatch.setattr(estimator, "fit_codes", spy_fit_codes)
    outs = [tmp_path / f"retry{k}.nbrdf.json" for k in range(2)]
    for out in outs:
        assert run(scene, images, out, "--steps", "6", "--spp", "2", "--threads", "1", "--seed", "0") == 0
    assert seeds == [0, estimator.ATTEMPT_SEED_STRIDE] * 2
    provenance = json.loads(outs[0].read_text())["provenance"]
    assert provenance["start"] in ("decoded", "analytic") and provenance["attempts"] == 2
    assert set(provenance["albedo_rejected"]) == {str(w) for w in plan.PULL_STRENGTHS}
    assert json.loads(outs[0].read_text())["layers"] == json.loads(outs[1].read_text())["layers"]
