"""Material estimation from images, measured.

    python -m nbrdf_tools estimation [--work out/estimation] [--out WORK/estimation.md]
                                     [--materials A,B] [--models A,B] [--steps N] [--seed S] [--quick]
    python -m nbrdf_tools estimation --stored-only [--out docs/results/estimation.md]

For each ground-truth material (the four shared RGL measurements through Mitsuba's ``measured``,
two MERL tables made by ``nbrdf synth`` through the ``merl`` plugin, one Mitsuba BSDF) it renders
the training images of a sphere itself (``--views`` sensors around it, two point lights and a dim
constant environment), runs ``python -m nbrdf_mitsuba.estimate`` with every model on the same
images, and measures each estimate on novel views under novel lights (three pairs, the means of
tone-mapped RMSE, SSIM, HDR-FLIP of :mod:`nbrdf_tools.common.metrics`) and in BRDF space against the
truth (the mean log error of :func:`nbrdf_tools.common.compare_materials.log_error`, uniform
directions). Each (material, model) is stored in ``WORK/MATERIAL/MODEL.result.json`` as it
finishes; a rerun skips those done (resumable; ``--stored-only --work WORK`` tabulates the stored
results alone and lists the cases not run), and refuses a work folder whose results were estimated
with other views, steps, samples or seed.
Writes the run's page: the Markdown table per material and model, the seconds of each estimate,
the candidate each ``nbrdf`` estimate chose by its held-out training view, and a figure (truth and
every estimate at the first novel pair). A stored estimate whose novel pairs were not today's is
measured again, not estimated again.

``--stored-only`` without ``--work`` writes the results page, docs/results/estimation.md, whole
from the figures checked in beside it (:mod:`nbrdf_tools.pages.estimation.page`).

Beside the estimates, each material gets the network's ceiling, ``nbrdf-from-truth``: the same
675-weight network distilled from the truth's BRDF itself (``python -m nbrdf_mitsuba.distill``,
isotropic, the trainer's defaults), not from images, measured the same way. It is no competitor
(it never counts as a material's lowest): it says how much of an estimate's error is the
network's form and how much the few images (``--no-ceiling`` leaves it out).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from nbrdf_tools.common.paths import REPO, default_out
from nbrdf_tools.pages.estimation import run_page, truths
from nbrdf_tools.pages.estimation.run_page import CEILING, chosen_strengths, summary
from nbrdf_tools.pages.estimation.truths import MERL, MITSUBA_TRUTH, RGL, dict_to_xml, file_bsdf

MODELS = ("nbrdf", "nbrdf-no-prior", "principled", "roughconductor", "roughplastic")
#: Training sensors (origins looking at the sphere) and lights; the novel ones differ from all.
#: The first ``--views`` are used; the later ones add directions no earlier view covers (the
#: right side grazed by the first light, the top) and stay away from the novel view.
VIEWS = ["0, 0, 4", "3, 1, 2.5", "-2.5, 2, 2.5", "0.5, -1.5, 3.6", "3.5, -1, -1.5", "-1.5, 3.5, 1.5"]
LIGHTS = [("3, 3, 4", 40.0), ("-4, 2, 1", 25.0)]
NOVEL_VIEW, NOVEL_LIGHT = "-3, -0.5, 2.8", ("1, 4, 2", 40.0)
#: Novel (view, light) pairs, each image lit by its light alone; the first keeps the file names it
#: had when it was measured alone. The others put the light where no training light was (below
#: left, low on the right) and look from where no training view did, so a score is not one
#: highlight's.
NOVEL_PAIRS = [(NOVEL_VIEW, NOVEL_LIGHT), ("1.5, 3, 2.5", ("-2, -3, 3", 30.0)),
               ("-0.5, -3.5, 2", ("4, 0, 1.5", 30.0))]
#: 200 steps: at 100 the analytic baselines were still falling on the MERL truths, and an estimate
#: of the prior stays within a few minutes on two cores (docs/estimation.md, "Defaults, and why").
#: The estimates' novel renders take ``measure_spp`` (the truth's more, below): at the training
#: references' 128 spp the renders' noise was most of the ceiling's error on the MERL truths
#: (docs/results/estimation.md, "Setup").
FULL = {"resolution": 64, "views": 3, "reference_spp": 128, "measure_spp": 4096, "spp": 8, "steps": 200,
        "ceiling_training": []}
#: The ceiling's distillation is cut to a few thousand pairs and epochs in the quick run (a test).
#: The truth's novel renders take this many times ``measure_spp``: the measured truths' own
#: sampling (``merl``'s, ``measured``'s) is the noisiest of the renders compared.
TRUTH_SPP_FACTOR = 4
QUICK = {"resolution": 16, "views": 2, "reference_spp": 16, "measure_spp": 16, "spp": 2, "steps": 3,
         "ceiling_training": ["--samples", "4000", "--epochs", "2"]}


def sensor(origin: str, resolution: int, fov: str = "30") -> str:
    return f"""
    <sensor type="perspective">
        <float name="fov" value="{fov}"/>
        <transform name="to_world"><lookat origin="{origin}" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="16"/></sampler>
        <film type="hdrfilm"><integer name="width" value="{resolution}"/><integer name="height" value="{resolution}"/>
            <rfilter type="box"/></film>
    </sensor>"""


def scene_xml(bsdf: str, views: list[str], lights, resolution: int) -> str:
    """A sphere with BSDF ``mat``, a sensor per view, a point light per light, a dim sky."""
    return _scene(sensors="".join(sensor(v, resolution) for v in views), objects=f"{bsdf}\n"
                  '    <shape type="sphere"><ref id="mat"/></shape>', lights=lights)


def _scene(sensors: str, objects: str, lights) -> str:
    emitters = "".join(f'\n    <emitter type="point"><point name="position" value="{p}"/>'
                       f'<rgb name="intensity" value="{i}"/></emitter>' for p, i in lights)
    return (f'<scene version="3.0.0">\n    <integrator type="path"><integer name="max_depth" value="3"/></integrator>'
            f'{sensors}\n    {objects}{emitters}\n'
            f'    <emitter type="constant"><rgb name="radiance" value="0.05"/></emitter>\n</scene>\n')


#: The training scenes' ``-D`` parameter: the sensors' field of view has no default in the file.
TRAINING_DEFINES = {"fov": "30"}


def training_defines() -> list[str]:
    """The estimate command's ``-D`` arguments for a training scene (:data:`TRAINING_DEFINES`)."""
    return [arg for key, value in TRAINING_DEFINES.items() for arg in ("-D", f"{key}={value}")]


def training_scene_xml(bsdf: str, form: str, views: list[str], lights, resolution: int) -> str:
    """The scene of :func:`scene_xml` with its BSDF ``mat`` where ``form`` puts it
    (:data:`truths.FORMS`) and its field of view a ``-D`` parameter (:data:`TRAINING_DEFINES`);
    the images are the plain scene's: the ``shared`` form's second sphere lies inside the first."""
    objects = {
        "nested": f'<shape type="sphere">{bsdf}</shape>',
        "twosided": f'<bsdf type="twosided" id="surface">{bsdf}</bsdf>\n'
                    '    <shape type="sphere"><ref id="surface"/></shape>',
        "shared": f'{bsdf}\n    <shape type="sphere"><ref id="mat"/></shape>\n'
                  '    <shape type="sphere"><float name="radius" value="0.5"/><ref id="mat"/></shape>',
    }
    if form not in objects:
        raise ValueError(f"unknown scene form {form!r} (these are: {', '.join(objects)})")
    return _scene(sensors="".join(sensor(v, resolution, "$fov") for v in views), objects=objects[form],
                  lights=lights)


def materials(work: Path, quick: bool, names: list[str] | None, which: str = "test",
              rgl_files: list[Path] = ()) -> dict[str, dict]:
    """name -> its truth (:func:`truths.truth`): ``names`` from any set, else the set ``which``
    (``--quick``: its first Mitsuba truth alone). A shared RGL file that is absent is skipped."""
    truths.check_rgl_files(list(rgl_files))
    known = truths.names("all", rgl_files)
    if names:
        unknown = [n for n in names if n not in known]
        if unknown:
            raise SystemExit(f"unknown materials: {', '.join(unknown)} (these are: {', '.join(known)})")
        chosen = list(names)
    else:
        chosen = truths.names(which, rgl_files)
        if quick:
            chosen = [next(n for n in chosen if n.startswith("mitsuba-"))]
    found = {name: truths.truth(name, work, rgl_files) for name in chosen}
    missing = [name for name, material in found.items() if material is None]
    if names and missing:
        raise SystemExit(f"unavailable materials: {', '.join(missing)}")
    return {name: material for name, material in found.items() if material is not None}


def render_scene(text: str, path: Path, spp: int, prefix: Path, defines: dict | None = None) -> list[Path]:
    import mitsuba as mi

    path.write_text(text)
    scene = mi.load_file(str(path), **(defines or {}))
    outs = []
    for i in range(len(scene.sensors())):
        image = mi.render(scene, sensor=i, spp=spp, seed=1000 + i)
        outs.append(Path(f"{prefix}{i}.exr"))
        mi.Bitmap(image).write(str(outs[-1]))
    return outs


def estimate_bsdf_xml(model: str, result: Path) -> str:
    if model.startswith("nbrdf"):
        return file_bsdf("nbrdf", result)
    return dict_to_xml(json.loads(result.read_text()))


def estimate_bsdf_dict(model: str, result: Path) -> dict:
    if model.startswith("nbrdf"):
        return {"type": "nbrdf", "filename": str(result)}
    return json.loads(result.read_text())


def read_exr(path: Path) -> np.ndarray:
    import mitsuba as mi

    bitmap = mi.Bitmap(str(path)).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
    return np.array(bitmap, dtype=np.float64)


def novel_prefix(pair: int) -> str:
    """File names of novel pair ``pair``: the first keeps the ``novel-*`` names it had alone."""
    return "novel" if pair == 0 else f"novel{pair}"


def novel_spp(settings: dict, who: str) -> int:
    return settings["measure_spp"] * (TRUTH_SPP_FACTOR if who == "truth" else 1)


def novel_images(bsdf_xml: str, folder: Path, who: str, settings: dict) -> list[Path]:
    """``who``'s render of every novel pair (``who``: ``truth`` or a model)."""
    paths = []
    for pair, (view, light) in enumerate(novel_pairs(settings)):
        prefix = folder / f"{novel_prefix(pair)}-{who}"
        (path,) = render_scene(scene_xml(bsdf_xml, [view], [light], settings["resolution"]),
                               prefix.with_name(prefix.name + ".xml"), novel_spp(settings, who),
                               prefix.with_name(prefix.name + "-"))
        paths.append(path)
    return paths


def measure_estimate(folder: Path, model: str, estimate: Path, settings: dict) -> dict:
    """The stored ``estimate`` of ``model`` rendered at every novel pair; per pair its image
    metrics against the truth's, and their means (the table's figures)."""
    from nbrdf_tools.common import metrics

    per_pair = []
    for pair, path in enumerate(novel_images(estimate_bsdf_xml(model, estimate), folder, model, settings)):
        reference, image = read_exr(folder / f"{novel_prefix(pair)}-truth-0.exr"), read_exr(path)
        per_pair.append({"rmse_tonemapped": metrics.rmse_tonemapped(reference, image),
                         "ssim": metrics.ssim(reference, image), "flip_hdr": metrics.flip_hdr(reference, image)})
    means = {key: float(np.mean([m[key] for m in per_pair])) for key in per_pair[0]}
    return {**means, "novel": per_pair, **novel_record(settings)}


def novel_pairs(settings: dict | None = None) -> list:
    """The first ``settings["pairs"]`` of :data:`NOVEL_PAIRS` (``--novel-pairs``; all by default)."""
    return NOVEL_PAIRS[: (settings or {}).get("pairs") or len(NOVEL_PAIRS)]


def novel_setup(settings: dict | None = None) -> list:
    """What a stored result's novel metrics were measured on (remeasured where it changed)."""
    return [[view, light, intensity] for view, (light, intensity) in novel_pairs(settings)]


def novel_record(settings: dict) -> dict:
    """What the novel renders were: the pairs, the estimates' and the truth's samples."""
    return {"novel_pairs": novel_setup(settings), "novel_spp": novel_spp(settings, "estimate"),
            "truth_spp": novel_spp(settings, "truth")}


def measured_as_today(result: dict, settings: dict) -> bool:
    """Whether ``result`` (a stored result, or the truth's novel images' record) was measured as
    today's settings would (results from before the samples were recorded had 128 on both sides)."""
    record = novel_record(settings)
    return all(result.get(key) == value for key, value in record.items())


def refuse_other_folder(folder: Path, settings: dict) -> None:
    """Stops before anything in ``folder`` is rendered again or re-measured where one of its
    estimates, of any model, was made with other settings: its training images must stay the ones
    it was fitted to. (The ceiling, distilled rather than estimated, records none and passes.)"""
    asked = estimate_settings(settings)
    for stored in sorted(folder.glob("*.result.json")):
        earlier = json.loads(stored.read_text()).get("settings", asked)
        if earlier != asked:
            raise SystemExit(f"{stored} was estimated with {earlier}, this run asks for {asked}: "
                             "give it another --work")


def stored_result(stored: Path, folder: Path, model: str, out: Path, settings: dict) -> dict | None:
    """The result stored in ``stored``, measured again from its stored ``out`` where its novel
    pairs are not today's; None where nothing is stored. Its settings were checked by
    :func:`refuse_other_folder` before the folder was prepared."""
    if not stored.is_file():
        return None
    result = json.loads(stored.read_text())
    if not measured_as_today(result, settings) and out.is_file():
        result.update(measure_estimate(folder, model, out, settings))
        stored.write_text(json.dumps(result, indent=2) + "\n")
    return result


def store_result(stored: Path, material: dict, model: str, out: Path, settings: dict, seconds: float,
                 cpu_seconds: float, extra: dict) -> dict:
    """``out`` measured at the novel pairs and in BRDF space against the truth, stored."""
    import mitsuba as mi

    from nbrdf_tools.common.compare_materials import log_error

    folder = stored.parent
    # The set and the form are the truth's; the cores, what the seconds were measured on.
    result = {"material": folder.name, "model": model, "set": material.get("set", truths.set_of(folder.name)),
              "scene_form": material.get("form"), **extra, "seconds": seconds, "cpu_seconds": cpu_seconds,
              "cores": os.cpu_count(),
              **measure_estimate(folder, model, out, settings),
              "log_error": log_error(mi.load_dict(material["dict"]), mi.load_dict(estimate_bsdf_dict(model, out)),
                                     "uniform", settings["log_samples"])}
    stored.write_text(json.dumps(result, indent=2) + "\n")
    return result


def run_case(name: str, material: dict, model: str, settings: dict, work: Path) -> dict:
    """One (material, model): estimate, novel renders, metrics; stored as MODEL.result.json. A
    stored result is reused; if its novel pairs are not today's, the stored estimate is measured
    again (not estimated again)."""
    from nbrdf_mitsuba import estimate

    folder = work / name
    stored = folder / f"{model}.result.json"
    out = folder / (f"{model}.nbrdf.json" if model.startswith("nbrdf") else f"{model}.json")
    result = stored_result(stored, folder, model, out, settings)
    if result is not None:
        return result
    images = training_images(folder, settings["views"])
    argv = [str(folder / "train.xml"), "--images", *map(str, images), "--bsdf-id", "mat", "-o", str(out),
            *training_defines(),
            "--model", model, "--steps", str(settings["steps"]), "--spp", str(settings["spp"]),
            "--seed", str(settings["seed"]), "-q",
            *(["--threads", str(settings["threads"])] if settings.get("threads") else [])]
    start, cpu = time.perf_counter(), time.process_time()
    status = estimate.main(argv)
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
    if status != 0:
        raise SystemExit(f"{name} {model}: the estimate failed (status {status})")
    return store_result(stored, material, model, out, settings, seconds, cpu_seconds,
                        {"settings": estimate_settings(settings)})


def run_ceiling(name: str, material: dict, settings: dict, work: Path) -> dict:
    """The network distilled from the truth's BRDF (:data:`CEILING`), with the estimates' fitted
    sampling, measured as an estimate is; stored as ``CEILING.result.json`` (re-measured, not
    distilled again, where the novel pairs changed)."""
    from nbrdf_mitsuba import distill, estimate

    folder = work / name
    stored, out = folder / f"{CEILING}.result.json", folder / f"{CEILING}.nbrdf.json"
    result = stored_result(stored, folder, CEILING, out, settings)
    if result is not None:
        return result
    source = folder / "truth.json"
    source.write_text(json.dumps(material["dict"]))
    start, cpu = time.perf_counter(), time.process_time()
    # Isotropic: the estimates are isotropic 675-weight networks, and so is their ceiling.
    status = distill.main([str(source), "-o", str(out), "--anisotropy", "off", "-q", *settings["ceiling_training"]])
    if status != 0:
        raise SystemExit(f"{name} {CEILING}: the distillation failed (status {status})")
    estimate.fit_sampling(out)
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
    return store_result(stored, material, CEILING, out, settings, seconds, cpu_seconds, {})


def estimate_settings(settings: dict) -> dict:
    """What an estimate depends on besides its material and model (results stored before this
    was recorded carry none and are taken as they are; the training images' side only where it is
    not the novel views', so that results from before it could differ still match)."""
    asked = {key: settings[key] for key in ("views", "steps", "spp", "seed")}
    if train_resolution(settings) != settings["resolution"]:
        asked["train_resolution"] = train_resolution(settings)
    return asked


def training_images(folder: Path, views: int) -> list[Path]:
    return [folder / f"train{i}.exr" for i in range(views)]


def train_resolution(settings: dict) -> int:
    """The training images' side in pixels: ``--train-resolution``, else the novel views'."""
    return settings.get("train_resolution") or settings["resolution"]


def image_side(path: Path) -> int:
    import mitsuba as mi

    return int(mi.Bitmap(str(path)).size()[0])


def prepare(name: str, material: dict, settings: dict, work: Path) -> None:
    """The truth's training images, through the truth's scene form, and its novel images, through
    the plain scene (once per material; view i's image does not depend on how many views there
    are, nor on the form)."""
    folder = work / name
    folder.mkdir(parents=True, exist_ok=True)
    side = train_resolution(settings)
    form = material.get("form", truths.FORMS[0])
    views = VIEWS[: settings["views"]]
    images = training_images(folder, settings["views"])
    if not all(p.is_file() and image_side(p) == side for p in images):
        render_scene(training_scene_xml(material["xml"], form, views, LIGHTS, side), folder / "truth.xml",
                     settings["reference_spp"], folder / "train", TRAINING_DEFINES)
    record = folder / "novel-truth.json"
    rendered = json.loads(record.read_text()) if record.is_file() else {}
    if not (measured_as_today(rendered, settings)
            and all((folder / f"{novel_prefix(pair)}-truth-0.exr").is_file() for pair in range(len(novel_pairs(settings))))):
        novel_images(material["xml"], folder, "truth", settings)
        record.write_text(json.dumps(novel_record(settings)) + "\n")
    # The estimate's scene: the same as the truth's, its BSDF a placeholder the estimate replaces.
    placeholder = dict_to_xml({"type": "diffuse"})
    (folder / "train.xml").write_text(training_scene_xml(placeholder, form, views, LIGHTS, side))


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m nbrdf_tools estimation", description=__doc__.split("\n")[0])
    p.add_argument("--out", type=Path,
                   help="the Markdown page (default: WORK/estimation.md; with --stored-only alone: "
                        "docs/results/estimation.md)")
    p.add_argument("--work", type=Path, help=f"working folder (resumable; default: {default_out('estimation')})")
    p.add_argument("--set", dest="which", choices=(*truths.SETS, "all"), default="test",
                   help="the truths: test (default; nothing is chosen on them), tuning (the defaults were chosen "
                        "on them) or all")
    p.add_argument("--materials", help="comma-separated materials, of any set (default: every truth of --set)")
    p.add_argument("--rgl", type=Path, nargs="+", default=[], metavar="FILE",
                   help="RGL measurements (*_rgb.bsdf) added to the test set as rgl-NAME; none the tuning set holds")
    p.add_argument("--models", default=",".join(MODELS),
                   help=f"comma-separated models (default: {','.join(MODELS)}); with --no-ceiling, an empty list "
                        "(`--models ,`) renders the truths' images alone")
    p.add_argument("--steps", type=int, help=f"optimisation steps (default: {FULL['steps']})")
    p.add_argument("--spp", type=int, help=f"samples per pixel of each optimisation render (default: {FULL['spp']})")
    p.add_argument("--measure-spp", type=int,
                   help=f"samples per pixel of the estimates' novel renders (the truth's: {TRUTH_SPP_FACTOR}x; "
                        f"default: {FULL['measure_spp']})")
    p.add_argument("--novel-pairs", type=int, choices=range(1, len(NOVEL_PAIRS) + 1),
                   metavar=f"1..{len(NOVEL_PAIRS)}", help=f"the first N novel pairs (default: all {len(NOVEL_PAIRS)})")
    p.add_argument("--views", type=int, choices=range(2, len(VIEWS) + 1), metavar=f"2..{len(VIEWS)}",
                   help=f"training views, each an image under both lights (default: {FULL['views']})")
    p.add_argument("--train-resolution", type=int, metavar="N",
                   help=f"side of the training images in pixels (default: the novel views' {FULL['resolution']}); "
                        "at 64 a sharp highlight is one pixel wide, at 128 it is resolved, at about 3x the time of "
                        "a network's estimate")
    p.add_argument("--seed", type=int, default=0,
                   help="the estimates' seed (default: 0); the training and novel images do not depend on it")
    p.add_argument("--threads", type=int,
                   help="the estimates' Dr.Jit worker threads (default: one per core; 1 makes a rerun bit-identical, "
                        "which comparisons of two estimators need)")
    p.add_argument("--no-ceiling", action="store_true",
                   help=f"leave out {CEILING}, the network distilled from the truth's BRDF (the estimates' ceiling)")
    p.add_argument("--quick", action="store_true",
                   help="a tiny run for tests (16x16, 3 steps, the set's first Mitsuba truth)")
    p.add_argument("--stored-only", action="store_true",
                   help="estimate nothing: without --work, write the results page from the stored figures "
                        "(--stored); with --work, tabulate the results stored there and list the cases missing")
    p.add_argument("--stored", type=Path, metavar="FILE",
                   help="with --stored-only: the stored figures the results page is written from (default: "
                        "docs/results/estimation/stored.json; python -m nbrdf_tools estimation-seeds --stored "
                        "writes one)")
    return p


def given_counts(args: argparse.Namespace, keys: tuple[str, ...]) -> dict:
    """The counts among ``keys`` given on the command line; one below 1 is refused."""
    given = {key: getattr(args, key) for key in keys if getattr(args, key) is not None}
    for key, value in given.items():
        if value < 1:
            raise SystemExit(f"--{key.replace('_', '-')} must be at least 1")
    return given


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if args.stored is not None and (not args.stored_only or args.work is not None):
        raise SystemExit("--stored goes with --stored-only and without --work (the figures come from one of them)")
    if args.stored_only and args.work is None:
        from nbrdf_tools.pages.estimation import page

        return page.write(args.stored or page.default_stored(), args.out or REPO / page.PAGE,
                          None if args.stored is None else str(args.stored))
    import nbrdf_mitsuba  # noqa: F401  (first: registers the plugins, finds a libLLVM)
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    settings = dict(QUICK if args.quick else FULL)
    settings["log_samples"] = 2000 if args.quick else 50000
    settings.update(given_counts(args, ("steps", "spp", "measure_spp", "train_resolution", "threads")))
    if args.views:
        settings["views"] = args.views
    if args.novel_pairs:
        settings["pairs"] = args.novel_pairs
    settings["seed"] = args.seed
    models = [m for m in args.models.split(",") if m]
    bad = set(models) - set(MODELS)
    if bad:
        raise SystemExit(f"unknown models: {', '.join(sorted(bad))} (these are: {', '.join(MODELS)})")
    work = args.work or default_out("estimation")
    work.mkdir(parents=True, exist_ok=True)
    chosen = materials(work, args.quick, args.materials.split(",") if args.materials else None, args.which,
                       args.rgl)
    results, missing = [], []
    columns = models + ([] if args.no_ceiling else [CEILING])
    for name, material in chosen.items():
        refuse_other_folder(work / name, settings)
        prepare(name, material, settings, work)
        for model in columns:
            if args.stored_only and not (work / name / f"{model}.result.json").is_file():
                missing.append(f"{name} {model}")
                continue
            result = (run_ceiling(name, material, settings, work) if model == CEILING
                      else run_case(name, material, model, settings, work))
            result.setdefault("set", material["set"])  # stored before results recorded it
            print(f"{name} {model}: novel RMSE {result['rmse_tonemapped']:.4f}, log error {result['log_error']:.4f}, "
                  f"{result['seconds']:.0f} s", flush=True)
            results.append(result)
    if not columns:  # `--models , --no-ceiling`: the truths' images alone, ahead of timed estimates
        print(f"rendered the truths of {len(chosen)} materials under {work}")
        return 0
    out = args.out or work / "estimation.md"
    command = "python -m nbrdf_tools estimation " + " ".join(argv if argv is not None else sys.argv[1:])
    image = run_page.write(out, command.strip(), results, work, settings, models, chosen, missing,
                           ceiling=not args.no_ceiling)
    print(f"wrote {out} and {image}")
    return 0


__all__ = ["main", "MODELS", "CEILING", "chosen_strengths", "summary", "REPO",
           "MERL", "MITSUBA_TRUTH", "RGL", "dict_to_xml", "file_bsdf"]
