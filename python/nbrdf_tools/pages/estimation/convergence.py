"""Novel-view error against the number of steps (the check of the step budget).

    python -m nbrdf_tools estimation-convergence --work out/estimation --materials A,B
        [--models nbrdf,nbrdf-no-prior,principled] [--steps 60] [--checkpoints 10,20,30,45,60]

One estimate of ``--steps`` steps per (material, model) on the report's training images (same
images, same settings as :mod:`nbrdf_tools.pages.estimation`), its parameters saved after each
checkpoint and rendered at the report's novel view and light. For a one-phase model (the network
without the prior, an analytic BSDF) the parameters after ``N`` steps of the long run are exactly
those of an ``N``-step run (the same per-step render seeds, the same Adam steps). For ``nbrdf``
the split between the code and the weight phases scales with the total, so its snapshots are
points of the ``--steps`` schedule (a snapshot in the code phase is the decoded code; where
several strengths of the code penalty are candidates, the last one's code), not shorter runs.
Snapshots have no fitted sampling (cosine-lobe sampling: unbiased, noisier).
Results are stored in ``WORK/MATERIAL/convergence-MODEL-STEPS.json`` (resumable).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from nbrdf_tools.pages import estimation as report


def snapshot_file(folder: Path, model: str, steps: int, done: int) -> Path:
    suffix = ".nbrdf.json" if model.startswith("nbrdf") else ".json"
    return folder / f"convergence-{model}-{steps}-at{done}{suffix}"


def write_snapshot(path: Path, model: str, kind: str, theta, decoder) -> None:
    from nbrdf_mitsuba import estimate

    if kind == "code":
        estimate.write_network(path, decoder.decode_numpy(theta), path.stem, {"snapshot_of": "code"})
    elif kind == "weights":
        estimate.write_network(path, theta, path.stem, {"snapshot_of": "weights"})
    else:
        path.write_text(json.dumps(estimate.Analytic(model).result(theta)))


def run_curve(name: str, model: str, settings: dict, checkpoints: list[int], work: Path) -> dict:
    """The novel-view RMSE of ``model`` after each checkpoint of one ``settings['steps']``-step run
    (the report's first novel pair: a curve needs one render per checkpoint, not a table's three)."""
    from nbrdf_mitsuba import estimate
    from nbrdf_mitsuba.latent import Decoder

    folder, steps = work / name, settings["steps"]
    stored = folder / f"convergence-{model}-{steps}.json"
    if stored.is_file():
        result = json.loads(stored.read_text())
        if report.measured_as_today(result, settings):
            return result
        phases = {row["steps"]: row["phase"] for row in result["curve"]}
        if all(snapshot_file(folder, model, steps, done).is_file() for done in phases):
            # Measured at other samples than the truth's novel render now has: measured again
            # from the stored snapshots (without them, estimated again below).
            result.update(curve=measure_curve(folder, model, steps, phases, settings), **report.novel_record(settings))
            stored.write_text(json.dumps(result, indent=2) + "\n")
            return result
    decoder = Decoder() if model == "nbrdf" else None
    kinds: dict[int, str] = {}

    def on_step(kind, done, theta):
        if done in checkpoints:
            kinds[done] = kind
            write_snapshot(snapshot_file(folder, model, steps, done), model, kind, theta, decoder)

    out = folder / f"convergence-{model}-{steps}{'.nbrdf.json' if model.startswith('nbrdf') else '.json'}"
    argv = [str(folder / "train.xml"), "--images", *map(str, report.training_images(folder, settings["views"])),
            "--bsdf-id", "mat", "-o", str(out), *report.training_defines(), "--model", model, "--steps", str(steps),
            "--spp", str(settings["spp"]), "-q"]
    start, cpu = time.perf_counter(), time.process_time()
    estimate.estimate(estimate.parser().parse_args(argv), on_step)
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
    result = {"material": name, "model": model, "steps": steps, "seconds": seconds, "cpu_seconds": cpu_seconds,
              "curve": measure_curve(folder, model, steps, kinds, settings), **report.novel_record(settings)}
    stored.write_text(json.dumps(result, indent=2) + "\n")
    return result


def measure_curve(folder: Path, model: str, steps: int, kinds: dict, settings: dict) -> list[dict]:
    """Each snapshot (steps done -> phase ``kinds``) rendered at the first novel pair; its RMSE."""
    from nbrdf_tools.common import metrics

    reference = report.read_exr(folder / "novel-truth-0.exr")
    rows = []
    for done in sorted(kinds):
        path = snapshot_file(folder, model, steps, done)
        xml = report.scene_xml(report.estimate_bsdf_xml(model, path), [report.NOVEL_VIEW], [report.NOVEL_LIGHT],
                               settings["resolution"])
        (image,) = report.render_scene(xml, path.with_suffix(".xml"), report.novel_spp(settings, model),
                                       path.with_name(path.name.split(".")[0] + "-"))
        rows.append({"steps": done, "phase": kinds[done],
                     "rmse_tonemapped": metrics.rmse_tonemapped(reference, report.read_exr(image))})
    return rows


def table(results: list[dict], checkpoints: list[int]) -> list[str]:
    lines = ["| material | model | " + " | ".join(f"{c} steps" for c in checkpoints) + " |",
             "|---|---|" + "---|" * len(checkpoints)]
    for r in results:
        by_step = {row["steps"]: row["rmse_tonemapped"] for row in r["curve"]}
        cells = [f"{by_step[c]:.4f}" if c in by_step else "-" for c in checkpoints]
        lines.append(f"| {r['material']} | {r['model']} | " + " | ".join(cells) + " |")
    return lines


def figure(results: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["material"] for r in results))
    fig, axes = plt.subplots(1, len(names), figsize=(3.6 * len(names), 2.8), squeeze=False)
    for ax, name in zip(axes[0], names):
        for r in (r for r in results if r["material"] == name):
            ax.plot([row["steps"] for row in r["curve"]], [row["rmse_tonemapped"] for row in r["curve"]], "o-",
                    label=r["model"], markersize=3)
        ax.set_title(name, fontsize=8)
        ax.set_xlabel("steps")
        ax.set_ylabel("novel-view RMSE (tone-mapped)")
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m nbrdf_tools estimation-convergence",
                                description=__doc__.split("\n")[0])
    p.add_argument("--work", type=Path, default=report.default_out("estimation"), help="the report's working folder")
    p.add_argument("--materials", required=True, help="comma-separated materials (the report's names)")
    p.add_argument("--models", default="nbrdf,nbrdf-no-prior,principled", help="comma-separated models")
    p.add_argument("--steps", type=int, default=60, help="steps of each estimate (default: 60)")
    p.add_argument("--checkpoints", default="10,20,30,45,60", help="steps after which to measure")
    p.add_argument("--measure-spp", type=int, default=report.FULL["measure_spp"],
                   help=f"samples per pixel of the novel renders (the truth's: {report.TRUTH_SPP_FACTOR}x; "
                        "default: %(default)s)")
    p.add_argument("--out", type=Path, help="Markdown table (default: WORK/convergence.md); the figure goes to "
                                            "images/estimation-convergence.png beside it")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    import nbrdf_mitsuba  # noqa: F401  (first: registers the plugins, finds a libLLVM)
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    settings = dict(report.FULL, **report.given_counts(args, ("steps", "measure_spp")))
    checkpoints = sorted({int(c) for c in args.checkpoints.split(",") if c} | {args.steps})
    models = [m for m in args.models.split(",") if m]
    if set(models) - set(report.MODELS):
        raise SystemExit(f"unknown models: {', '.join(sorted(set(models) - set(report.MODELS)))}")
    chosen = report.materials(args.work, False, args.materials.split(","))
    results = []
    for name, material in chosen.items():
        report.prepare(name, material, settings, args.work)
        for model in models:
            results.append(run_curve(name, model, settings, checkpoints, args.work))
            print(f"{name} {model}: " + ", ".join(f"{r['steps']}: {r['rmse_tonemapped']:.4f}"
                                                  for r in results[-1]["curve"]), flush=True)
    out = args.out or args.work / "convergence.md"
    image = out.parent / "images" / "estimation-convergence.png"
    image.parent.mkdir(parents=True, exist_ok=True)
    figure(results, image)
    command = "python -m nbrdf_tools estimation-convergence " + " ".join(argv if argv is not None
                                                                               else sys.argv[1:])
    out.write_text("\n".join(["```sh", command.strip(), "```", "", *table(results, checkpoints), ""]))
    print(f"wrote {out} and {image}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
