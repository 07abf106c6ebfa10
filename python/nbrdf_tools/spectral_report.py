"""Spectral networks against RGB networks of the same source (issue 31): distils Mitsuba's
``roughconductor`` with measured spectral indices of refraction (``material`` Au, Cu) into a
spectral network (``--variant llvm_ad_spectral``: file format version 3, 16 B-spline coefficients
over 360-830 nm) and into an RGB network (``llvm_ad_rgb``), then compares both with the source.

    python -m nbrdf_tools.spectral_report [--out docs/results/spectral-networks.md]
        [--figure docs/images/spectral-networks.png] [--materials Au,Cu] [--alpha 0.2]
        [--samples N] [--epochs N] [--size 96] [--spp 64] [--pairs 20000] [--quick] [--work out/spectral-networks]

Reported:

* per wavelength (every 10 nm, distill's :data:`~nbrdf_mitsuba.distill.WAVELENGTHS`), the log
  error ``mean |ln(1 + f cos) - ln(1 + f_net cos)|`` over ``--pairs`` uniform pairs of directions
  (the one log-error measure of :mod:`nbrdf_tools.compare_materials`, per wavelength) of the
  spectral network and of the RGB network as ``llvm_ad_spectral`` renders it (Mitsuba's uplift of
  its RGB value);
* sphere images (a sphere under a directional light and a dim constant environment) in
  ``llvm_ad_spectral`` and in ``llvm_ad_rgb``: source, spectral network, RGB network, errors
  from :mod:`nbrdf_tools.metrics` against the source's image in the same variant and seed;
* how finely distill samples the spectrum: linear interpolation between samples 5, 10, 20 and
  40 nm apart against the source's spectra every 1 nm (why distill takes 10 nm);
* the weights: 961 for the 6-21-21-16 spectral network, 675 for the 6-21-21-3 RGB one.

``--quick`` (a few seconds of training, tiny images; for tests) says so in the report.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import nbrdf_mitsuba  # noqa: F401  (first: finds a libLLVM for Dr.Jit before Mitsuba starts its JIT)
import mitsuba as mi
import numpy as np

from nbrdf_tools import metrics, progress
from nbrdf_tools.compare_materials import sample_directions, splitmix_uniforms
from nbrdf_tools.paths import REPO, default_out
from nbrdf_tools.render import write_exr

DEFAULT_OUT = REPO / "docs" / "results" / "spectral-networks.md"
DEFAULT_FIGURE = REPO / "docs" / "images" / "spectral-networks.png"
SPECTRAL, RGB = "llvm_ad_spectral", "llvm_ad_rgb"
STEPS_NM = (5.0, 10.0, 20.0, 40.0)
#: The stream of compare_materials' splitmix uniforms this report draws its pairs from.
PAIR_STREAM = 21


def source_dict(material: str, alpha: float) -> dict:
    return {"type": "roughconductor", "material": material, "alpha": alpha}


def distil(source: Path, output: Path, variant: str, extra: list[str]) -> dict:
    """Runs ``python -m nbrdf_mitsuba.distill SOURCE -o OUTPUT --variant VARIANT`` in this process;
    returns the network's provenance and the wall-clock seconds."""
    from nbrdf_mitsuba import distill

    start = time.perf_counter()
    status = distill.main([str(source), "-o", str(output), "--variant", variant, "-q", *extra])
    if status != 0:
        raise SystemExit(f"spectral_report: distilling {source} in {variant} failed (status {status})")
    document = json.loads(output.read_text(encoding="utf-8"))
    return {"provenance": document["provenance"], "seconds": time.perf_counter() - start,
            "parameters": sum(len(layer["weights"]) + len(layer["bias"]) for layer in document["layers"]),
            "version": document["version"]}


def pairs(count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(view, light) planar float64: ``count`` uniform pairs above the horizon (float32 too)."""
    u = splitmix_uniforms(seed, PAIR_STREAM, 0, 2 * count)
    light, view = sample_directions("uniform", u)
    keep = (light.astype(np.float32)[2] > 0) & (view.astype(np.float32)[2] > 0)
    return view[:, keep][:, :count], light[:, keep][:, :count]


def per_wavelength_log_error(bsdfs: dict, view: np.ndarray, light: np.ndarray) -> dict[str, np.ndarray]:
    """For each BSDF but ``source`` (dictionaries for ``mi.load_dict``), the log error against
    ``source`` at each of distill's wavelengths, in ``llvm_ad_spectral``."""
    from nbrdf_mitsuba import distill

    mi.set_variant(SPECTRAL)
    values = {name: distill.eval_cos(mi.load_dict(spec), view, light) for name, spec in bsdfs.items()}
    reference = np.log1p(np.maximum(values.pop("source"), 0.0))
    return {name: np.array([metrics.mae(reference[j], np.log1p(np.maximum(v[j], 0.0)))
                            for j in range(len(v))]) for name, v in values.items()}


def interpolation_errors(spec: dict, view: np.ndarray, light: np.ndarray) -> dict[float, tuple[float, float]]:
    """Per sampling step (nm): (mean, worst) relative RMS over pairs of the piecewise-linear
    spectrum through the samples against the spectrum every 1 nm (pairs whose spectrum peaks
    above 1e-3 only)."""
    from nbrdf_mitsuba import distill

    mi.set_variant(SPECTRAL)
    bsdf = mi.load_dict(spec)
    fine = np.arange(360.0, 830.0 + 1e-9, 1.0)
    reference = distill.eval_cos(bsdf, view, light, fine)
    seen = reference.max(axis=0) > 1e-3
    out = {}
    for step in STEPS_NM:
        grid = np.arange(360.0, 830.0 + 1e-9, step)
        samples = distill.eval_cos(bsdf, view, light, grid)
        interpolated = np.stack([np.interp(fine, grid, samples[:, i]) for i in range(view.shape[1])], 1)
        errors = np.array([metrics.relative_rmse(reference[:, i], interpolated[:, i]) for i in np.flatnonzero(seen)])
        out[step] = (float(errors.mean()), float(errors.max()))
    return out


def sphere_scene(bsdf: dict, size: int) -> dict:
    """A sphere under a directional light 40 degrees off the view and a dim white environment."""
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 22.0,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 6], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}}},
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "sun": {"type": "directional", "direction": [-0.5, -0.45, -0.75], "irradiance": {"type": "d65", "scale": 3.0}},
        "sky": {"type": "constant", "radiance": {"type": "d65", "scale": 0.15}},
    }


def render_spheres(bsdfs: dict, size: int, spp: int, variant: str, seed: int = 0) -> dict[str, np.ndarray]:
    from nbrdf_tools.render import render

    mi.set_variant(variant)
    images = {}
    for name, spec in bsdfs.items():
        images[name] = render(mi.load_dict(sphere_scene(spec, size)), spp, seed=seed)
    return images


def image_errors(images: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    reference = images["source"]
    return {name: {"relative_rmse": metrics.relative_rmse(reference, image),
                   "mae_tonemapped": metrics.mae_tonemapped(reference, image)}
            for name, image in images.items() if name != "source"}


def measure(material: str, args, work: Path) -> dict:
    """Everything the report says about one material."""
    spec = source_dict(material, args.alpha)
    source = work / f"{material}.json"
    source.write_text(json.dumps(spec) + "\n")
    extra = [*(["--samples", str(args.samples)] if args.samples else []),
             *(["--epochs", str(args.epochs)] if args.epochs else [])]
    nets = {"spectral": work / f"{material}-spectral.nbrdf.json", "rgb": work / f"{material}-rgb.nbrdf.json"}
    runs = {kind: distil(source, path, SPECTRAL if kind == "spectral" else RGB, extra) for kind, path in nets.items()}
    bsdfs = {"source": spec, **{kind: {"type": "nbrdf", "filename": str(path)} for kind, path in nets.items()}}
    view, light = pairs(args.pairs)
    log_errors = per_wavelength_log_error(bsdfs, view, light)
    images = {variant: render_spheres(bsdfs, args.size, args.spp, variant) for variant in (SPECTRAL, RGB)}
    errors = {variant: image_errors(found) for variant, found in images.items()}
    small_view, small_light = pairs(200 if args.quick else 2000, seed=1)
    return {"material": material, "spec": spec, "runs": runs, "log_errors": log_errors, "images": images,
            "image_errors": errors, "interpolation": interpolation_errors(spec, small_view, small_light)}


def figure(results: list[dict], path: Path) -> Path:
    """One row per material: the six sphere images (tone-mapped) and the per-wavelength errors."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from nbrdf_mitsuba import distill

    columns = [(SPECTRAL, "source"), (SPECTRAL, "spectral"), (SPECTRAL, "rgb"), (RGB, "source"), (RGB, "spectral"),
               (RGB, "rgb")]
    fig, axes = plt.subplots(len(results), len(columns) + 1, figsize=(2.0 * len(columns) + 4.0, 2.3 * len(results)),
                             squeeze=False, gridspec_kw={"width_ratios": [1] * len(columns) + [2.2]})
    for row, result in zip(axes, results):
        for ax, (variant, name) in zip(row, columns):
            ax.imshow(metrics.tone_map(result["images"][variant][name]))
            ax.set_xticks([])
            ax.set_yticks([])
            label = {"source": "roughconductor", "spectral": "spectral net", "rgb": "RGB net"}[name]
            ax.set_title(f"{label}\n{variant}", fontsize=7)
        row[0].set_ylabel(result["material"])
        ax = row[-1]
        for name, label in (("spectral", "spectral network"), ("rgb", "RGB network, uplifted")):
            ax.plot(distill.WAVELENGTHS, result["log_errors"][name], label=label)
        ax.set_xlabel("wavelength (nm)", fontsize=7)
        ax.set_ylabel("log error", fontsize=7)
        ax.set_yscale("log")
        ax.tick_params(labelsize=6)
        ax.legend(fontsize=6)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def markdown(command: str, args, results: list[dict], figure_path: Path, out: Path) -> str:
    from nbrdf_mitsuba import distill

    first = results[0]["runs"]["spectral"]
    provenance = first["provenance"]
    lines = [
        "# Spectral networks", "", "```sh", command, "```", "",
        *(["**Quick run** (`--quick`: tiny training budget and images, for tests; not the figures of record).", ""]
          if args.quick else []),
        f"Sources: Mitsuba's `roughconductor` with `alpha` {args.alpha} and `material` "
        f"{', '.join(r['material'] for r in results)} (indices of refraction from measured spectral data). Each is "
        "distilled twice by `python -m nbrdf_mitsuba.distill`: in `llvm_ad_spectral` into a **spectral network** "
        "(file format version 3: 16 cubic B-spline coefficients over 360-830 nm; Mitsuba evaluates the source "
        f"every {distill.WAVELENGTHS[1] - distill.WAVELENGTHS[0]:g} nm) and in `llvm_ad_rgb` into an **RGB "
        f"network**; {provenance.get('samples', '?')} training pairs, at most {provenance.get('max_epochs', '?')} "
        "epochs, the same seed.", "",
        f"Weights: the spectral network has {first['parameters']} (6-21-21-16), the RGB one "
        f"{results[0]['runs']['rgb']['parameters']} (6-21-21-3): "
        f"{first['parameters'] / results[0]['runs']['rgb']['parameters']:.2f}x.", "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, shared with other jobs (times indicative).", "",
        f"![spheres and per-wavelength errors]({os.path.relpath(figure_path, out.parent)})", "",
        "## Log error per wavelength", "",
        f"`mean |ln(1 + f cos) - ln(1 + f_net cos)|` over {args.pairs} uniform pairs of directions, in "
        "`llvm_ad_spectral`: the spectral network's own spectrum, and the RGB network's value uplifted by "
        "Mitsuba per wavelength (how a spectral render sees it).", "",
        "| material | network | mean over wavelengths | worst wavelength | 400 nm | 500 nm | 600 nm | 700 nm |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    w = distill.WAVELENGTHS
    for r in results:
        for name, label in (("spectral", "spectral"), ("rgb", "RGB, uplifted")):
            e = r["log_errors"][name]
            at = [f"{e[int(np.argmin(np.abs(w - nm)))]:.2e}" for nm in (400, 500, 600, 700)]
            lines.append(f"| {r['material']} | {label} | {e.mean():.2e} | {e.max():.2e} ({w[int(np.argmax(e))]:g} nm) | "
                         + " | ".join(at) + " |")
    lines += ["", "## Sphere images", "",
              f"{args.size} x {args.size} pixels, {args.spp} spp, a directional light (D65) and a dim constant "
              "environment; errors against the source rendered in the same variant at the same seed "
              "(`nbrdf_tools.metrics`: relative RMSE, and the mean absolute error after tone mapping).", "",
              "| material | variant | network | relative RMSE | MAE (tone-mapped) |", "|---|---|---|---:|---:|"]
    for r in results:
        for variant in (SPECTRAL, RGB):
            for name, label in (("spectral", "spectral"), ("rgb", "RGB")):
                e = r["image_errors"][variant][name]
                lines.append(f"| {r['material']} | `{variant}` | {label} | {e['relative_rmse']:.4f} | "
                             f"{e['mae_tonemapped']:.4f} |")
    lines += ["", "## Sampling the source's spectrum", "",
              "Linear interpolation between samples every 5-40 nm against the source's spectrum every 1 nm "
              "(relative RMS over the wavelengths, mean and worst over pairs of directions):", "",
              "| material | " + " | ".join(f"{s:g} nm" for s in STEPS_NM) + " |",
              "|---|" + "---:|" * len(STEPS_NM)]
    for r in results:
        lines.append(f"| {r['material']} | " + " | ".join(
            f"{100 * m:.3f} % (worst {100 * x:.3f} %)" for m, x in (r["interpolation"][s] for s in STEPS_NM)) + " |")
    lines += ["", "## Training", "", "| material | network | epochs | best validation loss | distill wall clock |",
              "|---|---|---:|---:|---:|"]
    for r in results:
        for name in ("spectral", "rgb"):
            run = r["runs"][name]
            lines.append(f"| {r['material']} | {name} (version {run['version']}) | {run['provenance'].get('epochs')} | "
                         f"{run['provenance'].get('best_validation_loss', float('nan')):.3e} | {run['seconds']:.1f} s |")
    return "\n".join(lines) + "\n"


def parse_arguments(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m nbrdf_tools.spectral_report", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="the Markdown report (default: %(default)s)")
    parser.add_argument("--figure", type=Path, default=DEFAULT_FIGURE, help="the figure (default: %(default)s)")
    parser.add_argument("--work", type=Path, default=default_out("spectral-networks"),
                        help="sources and networks (default: %(default)s)")
    parser.add_argument("--materials", default="Au,Cu", help="comma-separated Mitsuba conductor names (default: Au,Cu)")
    parser.add_argument("--alpha", type=float, default=0.2, help="roughconductor's alpha (default: 0.2)")
    parser.add_argument("--samples", type=int, help="training pairs (default: the trainer's)")
    parser.add_argument("--epochs", type=int, help="most epochs (default: the trainer's)")
    parser.add_argument("--size", type=int, default=96, help="sphere image size in pixels (default: 96)")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel (default: 64)")
    parser.add_argument("--pairs", type=int, default=20000, help="pairs of directions for the log error (default: 20000)")
    parser.add_argument("--quick", action="store_true",
                        help="tiny budget (2000 pairs, 3 epochs, 24-pixel images, 4 spp, 2000 error pairs), for tests")
    args = parser.parse_args(argv)
    if args.quick:
        args.samples, args.epochs = args.samples or 2000, args.epochs or 3
        args.size, args.spp, args.pairs = 24, 4, 2000
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_arguments(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    materials = [m.strip() for m in args.materials.split(",") if m.strip()]
    results = []
    for material in progress.bar(materials, desc="materials", unit="material"):
        result = measure(material, args, args.work)
        for variant in (SPECTRAL, RGB):
            for name, image in result["images"][variant].items():
                mi.set_variant(variant)
                write_exr(args.work / f"{material}-{variant}-{name}.exr", image)
        results.append(result)
    figure(results, args.figure)
    words = ["python -m nbrdf_tools.spectral_report", *(argv if argv is not None else sys.argv[1:])]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(" ".join(words), args, results, args.figure, args.out), encoding="utf-8")
    print(f"wrote {args.out} and {args.figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
