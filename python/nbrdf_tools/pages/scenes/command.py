"""``python -m nbrdf_tools scenes``: the options, the checks before any work, the run and
its files."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import nbrdf_mitsuba  # first: finds a libLLVM for Dr.Jit before Mitsuba starts its JIT
import mitsuba as mi

from nbrdf_tools.common import cli, progress
from nbrdf_tools.pages.scenes.page import files_of_run, write_measured, write_stored
from nbrdf_tools.pages.scenes.report import markdown, replot, write_csv
from nbrdf_tools.pages.scenes.run import QUICK_TRAIN_ARGS, KitchenSetup, VeachSetup, material_specs, run_kitchen, run_veach
from nbrdf_tools.pages.scenes.strategies import DEFAULT_STRATEGIES, STRATEGIES, kitchen_skip_reason
from nbrdf_tools.common.ground_truth import RenderCache
from nbrdf_tools.common.materials import VEACH_MERL, VEACH_RGL, Artefacts
from nbrdf_tools.common.paths import SCENES, MissingDataError, default_cli, default_out, shared_path
from nbrdf_tools.common.progress import log


def parser() -> argparse.ArgumentParser:
    from nbrdf_tools.pages import scenes as convergence

    parser = argparse.ArgumentParser(prog="python -m nbrdf_tools scenes", description=convergence.__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", choices=["veach", "kitchen"], default="veach")
    parser.add_argument("--materials", default=",".join(VEACH_MERL),
                        help="comma-separated MERL materials for the Veach scene (default: %(default)s)")
    parser.add_argument("--rgl", default=None,
                        help="comma-separated RGL materials for the Veach scene: paths of .bsdf measurements or "
                             "names in the shared data (SHARED/data/rgl/NAME.bsdf); empty for none (default: "
                             f"{','.join(VEACH_RGL)} when the shared data holds them, else none)")
    parser.add_argument("--integrator", choices=["bsdf", "mis"], default="bsdf",
                        help="Veach: bsdf = pure BSDF sampling (direct, emitter_samples = 0), mis = MIS")
    parser.add_argument("--width", type=int, help="image width (Veach: 384, kitchen: from kitchen_materials.json)")
    parser.add_argument("--height", type=int, help="image height (default: 2/3 of the width, kitchen 9/16)")
    parser.add_argument("--max-spp", type=int, default=128, help="highest spp of the series 1, 2, 4, ...")
    parser.add_argument("--strategies", default=",".join(DEFAULT_STRATEGIES),
                        help="comma-separated strategies to render, of those available per material, "
                             f"of {', '.join(STRATEGIES)}; the kitchen skips measured and phong-predicted with a "
                             "note (default: %(default)s)")
    parser.add_argument("--seeds", type=int, default=1,
                        help="independent renders per strategy and spp; the plots show their median and range "
                             "(default: %(default)s)")
    parser.add_argument("--gt-spp", type=int, default=1024, help="spp of the ground truths and references")
    parser.add_argument("--spp-per-pass", type=int, default=64, help="spp per pass of the reference renders")
    parser.add_argument("--max-depth", type=int, help="kitchen: path length (default from kitchen_materials.json)")
    parser.add_argument("--kitchen", help="kitchen scene.xml or its folder (default ../shared/scenes/kitchen)")
    parser.add_argument("--kitchen-materials", default=str(SCENES / "kitchen_materials.json"),
                        help="the override description")
    parser.add_argument("--train-args", default="", help="extra arguments of `nbrdf train`, e.g. '--epochs 30'")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--quick", action="store_true",
                        help="tiny images, few samples, one material, briefly trained networks, each render "
                             "timed once (CI, checks)")
    parser.add_argument("--json", type=Path, help="write the results as JSON here as well")
    parser.add_argument("--out", type=Path,
                        help="output folder of everything, caches included (default: out/convergence with the "
                             "materials and references cached in out/; quick: out/convergence-quick)")
    parser.add_argument("--stored-only", action="store_true",
                        help="measure nothing: write docs/results/scenes.md (or --out, here the page) from its stored "
                             "data, docs/results/data/scenes.json")
    parser.add_argument("--data", type=Path,
                        help="the page's data a measuring run updates, its page written beside it (default: "
                             "docs/results/data/scenes.json and docs/results/scenes.md for a full run with the "
                             "default --out, else OUT/scenes.json and OUT/scenes.md)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars (for logs)")
    parser.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf command-line tool")
    parser.add_argument("--force", action="store_true", help="re-render cached references")
    parser.add_argument("--ae", type=Path, help="autoencoder (nbrdf ae train) for the phong-predicted strategy")
    parser.add_argument("--predictor", type=Path,
                        help="Phong-parameter predictor (nbrdf predictor train) for the phong-predicted strategy")
    parser.add_argument("--replot", action="store_true",
                        help="only redraw the plots and the summary of the last run's JSON (same --scene, --out, "
                             "--integrator)")
    return parser


def _strategies(args, parser: argparse.ArgumentParser) -> None:
    """``--strategies`` as a list, refused when it names none the scene renders."""
    args.strategies = [s for s in args.strategies.split(",") if s]
    unknown = [s for s in args.strategies if s not in STRATEGIES]
    if unknown or not args.strategies:
        parser.error(f"--strategies: unknown {', '.join(unknown) or '(none given)'}; choose from {', '.join(STRATEGIES)}")
    if args.scene == "kitchen" and all(kitchen_skip_reason(s, True, True) for s in args.strategies):
        parser.error(f"--strategies: the kitchen renders none of {', '.join(args.strategies)}; choose from "
                     f"{', '.join(s for s in STRATEGIES if not kitchen_skip_reason(s, True, True))}")


def _default_rgl(args, notes: list[str]) -> None:
    """``--rgl`` unless given: the default RGL pair where the shared data holds it (none when quick)."""
    if args.rgl is not None:
        return
    shared_rgl = [m for m in VEACH_RGL if shared_path("data", "rgl", f"{m}.bsdf").is_file()]
    args.rgl = "" if args.quick else ",".join(shared_rgl)
    if not args.quick and len(shared_rgl) < len(VEACH_RGL):
        message = (f"RGL materials {', '.join(m for m in VEACH_RGL if m not in shared_rgl)} left out: not in "
                   f"{shared_path('data', 'rgl')} (set NBRDF_SHARED, or pass --rgl PATH.bsdf,...)")
        print(f"note: {message}")
        notes.append(message)


def _sizes(args, train_args: list[str]) -> list[str]:
    """Image sizes and sample counts (``--quick``: tiny ones); the training arguments to use."""
    if args.quick:
        args.max_spp = min(args.max_spp, 4)
        args.gt_spp = min(args.gt_spp, 32)
        if args.scene == "veach":
            args.width = args.width or 64
            args.height = args.height or 43
            args.materials = args.materials if args.materials != ",".join(VEACH_MERL) else "blue-metallic-paint"
        else:
            args.width = args.width or 48
            args.height = args.height or 27
            args.max_spp = min(args.max_spp, 2)
            args.gt_spp = min(args.gt_spp, 8)
            args.max_depth = args.max_depth or 3
        train_args = train_args or QUICK_TRAIN_ARGS
    if args.scene == "veach":
        args.width = args.width or 384
    return train_args


def _missing_inputs(args, artefacts: Artefacts) -> list[str]:
    """Everything the run needs that is not there, found before any work starts."""
    try:
        if args.scene == "kitchen":
            KitchenSetup(args)
            problems = artefacts.missing(sorted(set(json.loads(Path(args.kitchen_materials).read_text())
                                                    ["overrides"].values())))
        else:
            problems = artefacts.missing(material_specs(args))
        if args.ae and args.predictor and args.scene == "veach":
            problems += [f"{path}: no such file" for path in (args.ae, args.predictor) if not path.is_file()]
    except (MissingDataError, cli.CommandError) as error:
        problems = [str(error)]
    return problems


def _method_notes(args, artefacts: Artefacts, train_args: list[str], notes: list[str]) -> None:
    """Where the networks and lobes come from, and what is skipped for want of a tool or a file."""
    if artefacts.can_train():
        notes.append(f"NBRDFs trained with `nbrdf train` on the MERL tables and on the RGL measurements themselves "
                     f"({' '.join(train_args) or 'default recipe'})")
    else:
        notes.append("NBRDFs imported from the authors' Keras networks (`nbrdf train` is not available)")
    if not artefacts.can_fit_phong():
        notes.append("Blinn-Phong lobes: `nbrdf fit-phong` is not available, phong-fit and two-lobe-fit skipped")
    if not (args.ae and args.predictor) and args.scene == "veach":
        message = "phong-predicted skipped: pass --ae AE.json --predictor P.json (nbrdf ae train, nbrdf predictor train)"
        print(f"note: {message}")
        notes.append(message)


def _run_scene(args, artefacts: Artefacts, cache: RenderCache, scene_out: Path, notes: list[str]):
    """(report, resolution, integrator label) of the scene's run."""
    if args.scene == "veach":
        report = run_veach(args, artefacts, cache, scene_out, notes)
        return report, VeachSetup(args).resolution, "pure BSDF sampling" if args.integrator == "bsdf" else "MIS"
    report = run_kitchen(args, artefacts, cache, scene_out, notes)
    return report, KitchenSetup(args).resolution, "path tracing"


def _settings(args, resolution, integrator_label: str, train_args: list[str], seconds: float,
              cache: RenderCache) -> dict:
    return {"scene": args.scene, "resolution": list(resolution), "max_spp": args.max_spp,
            "gt_spp": args.gt_spp, "seeds": args.seeds,
            "integrator": args.integrator if args.scene == "veach" else "path",
            "integrator_label": integrator_label, "variant": args.variant, "quick": args.quick,
            "train_args": train_args, "seconds": round(seconds, 1),
            "metrics": "MAE, RMSE, relMSE (eps 0.01), MAPE (eps 0.01), PSNR (peak 1) on linear RGB; "
                       "representation also SSIM (scikit-image, tone-mapped) and HDR-FLIP, whole image",
            "cache": {"hits": cache.hits, "misses": cache.misses}}


def _write(report: dict, args, scene_out: Path, suffix: str) -> None:
    """The CSV, the JSON (also at ``--json``) and the Markdown summary, printed too."""
    write_csv(scene_out / f"convergence{suffix}.csv", report["results"])
    (scene_out / f"convergence{suffix}.json").write_text(json.dumps(report, indent=2) + "\n")
    text = markdown(report)
    (scene_out / f"summary{suffix}.md").write_text(text)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    print()
    print(text)
    print(f"wrote {scene_out}/convergence{suffix}.csv, .json, summary{suffix}.md, plots/ and renders/ "
          f"in {report['settings']['seconds']:.0f} s")
    if args.json:
        print(f"wrote {args.json}")


def _replot(scene_out: Path, suffix: str) -> int:
    report = json.loads((scene_out / f"convergence{suffix}.json").read_text())
    replot(report, scene_out)
    (scene_out / f"summary{suffix}.md").write_text(markdown(report))
    print(markdown(report))
    return 0


def main(argv: list[str] | None = None) -> int:
    options = parser()
    args = options.parse_args(argv)
    if args.stored_only:
        write_stored(args.out, args.data)
        return 0
    train_args = args.train_args.split()
    progress.set_enabled(not args.no_progress)
    _strategies(args, options)
    notes = []
    _default_rgl(args, notes)
    train_args = _sizes(args, train_args)
    out = args.out or default_out("convergence-quick" if args.quick else "convergence")
    # Materials and references are shared between runs in out/ unless --out (or --quick) says where.
    cache_root = out if (args.out or args.quick) else default_out()
    scene_out = out / args.scene
    suffix = "" if args.scene == "kitchen" or args.integrator == "bsdf" else "-mis"
    if args.replot:
        return _replot(scene_out, suffix)

    artefacts = Artefacts(cache_root, args.cli, train_args=train_args, log=log)
    problems = _missing_inputs(args, artefacts)
    if problems:
        print("error: missing inputs, nothing done:\n  " + "\n  ".join(problems), file=sys.stderr)
        return 2
    scene_out.mkdir(parents=True, exist_ok=True)
    mi.set_variant(args.variant)
    nbrdf_mitsuba.register()
    cache = RenderCache(cache_root / "references", force=args.force)
    _method_notes(args, artefacts, train_args, notes)

    start = time.perf_counter()
    try:
        report, resolution, integrator_label = _run_scene(args, artefacts, cache, scene_out, notes)
    except (MissingDataError, cli.CommandError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    report["notes"] = notes
    report["settings"] = _settings(args, resolution, integrator_label, train_args, time.perf_counter() - start, cache)
    _write(report, args, scene_out, suffix)
    write_measured(report, *files_of_run(args, out))
    bad = sum(r["nonfinite"] for r in report["results"])
    if bad:
        print(f"error: {bad} non-finite pixel values in the renders", file=sys.stderr)
        return 1
    return 0
