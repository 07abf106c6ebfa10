"""The Veach MIS scene in every kind of Mitsuba variant, with ``nbrdf`` and ``merl`` on the plates
and Mitsuba's own ``roughconductor`` and ``diffuse`` (RGB parameters) as the yardstick of what
Mitsuba's spectral uplift does to RGB data (issue 31).

    python -m nbrdf_tools variants --stored-only --out docs/results/variants.md   # the page from its data
    python -m nbrdf_tools variants [--out docs/results/variants.md] [--figure docs/images/variants.png]
        [--data docs/results/data/variants.json]
        [--width 192] [--spp 256] [--scalar-width 72] [--scalar-spp 16] [--timing-repeats 5] [--work out/variants]

Renders ``scalar_rgb``, ``scalar_spectral``, ``llvm_ad_rgb``, ``llvm_ad_mono``, ``llvm_ad_spectral``
and ``llvm_ad_spectral_polarized`` (each BSDF's default backend: ``rust`` in scalar variants, ``jit``
in LLVM ones), counts non-finite pixels and compares each image with the one it should match:

* spectral with the RGB render of the same family (``scalar_``/``llvm_ad_``), equal up to the
  uplift and to the spectral render's extra (wavelength) noise, measured beside it by the same
  spectral variant at another seed;
* mono with the luminance (Rec. 709, ``mi.luminance``) of the RGB render at the same seed: the
  scene's direct lighting is linear in the BSDF value and its lights are grey, so they are equal
  to float rounding;
* spectral polarized with spectral at the same seed.

The materials: the MERL-format table of ``--material`` made from its published fit (``nbrdf
synth``) and its network (``nbrdf train`` + ``fit-phong``), as :mod:`nbrdf_tools.demo` makes them
(reused from WORK when present). Writes the Markdown table (``--out``), the figure (one row per
BSDF, one column per variant) and the EXR renders under WORK; what the page reports is stored in
``--data``, from which ``--stored-only`` writes the page again without rendering.
"""

from __future__ import annotations

import argparse
import io
import os
import sys
import time
from pathlib import Path

import nbrdf_mitsuba  # noqa: F401  (first: finds a libLLVM for Dr.Jit before Mitsuba starts its JIT)
import mitsuba as mi
import numpy as np

from nbrdf_tools.common import cli, metrics, progress, stored_page
from nbrdf_tools.demo import DEFAULT_MATERIAL, srgb, synthesise, train
from nbrdf_tools.common.paths import REPO, MissingDataError, default_cli, default_out
from nbrdf_tools.common.render import render, write_exr
from nbrdf_tools.common.scenes.veach import veach_scene_dict

PAGE = "variants"
MACHINE = "a shared 2-core machine"

VARIANTS = ("scalar_rgb", "scalar_spectral", "llvm_ad_rgb", "llvm_ad_mono", "llvm_ad_spectral",
            "llvm_ad_spectral_polarized")
# Which image each variant's render should match: (variant, seed); "luminance" compares with the
# luminance of that render.
MATCHES = {
    "scalar_spectral": ("scalar_rgb", "up to the uplift"),
    "llvm_ad_mono": ("llvm_ad_rgb", "luminance"),
    "llvm_ad_spectral": ("llvm_ad_rgb", "up to the uplift"),
    "llvm_ad_spectral_polarized": ("llvm_ad_spectral", "equal"),
}
# Mitsuba's luminance of linear Rec. 709 RGB (include/mitsuba/core/spectrum.h).
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])
YARDSTICK_RGB = [0.8, 0.5, 0.2]
DEFAULT_FIGURE = REPO / "docs" / "images" / "variants.png"


def bsdfs(network: Path, table: Path) -> dict[str, dict]:
    colour = {"type": "rgb", "value": YARDSTICK_RGB}
    return {
        "nbrdf": {"type": "nbrdf", "filename": str(network)},
        "merl": {"type": "merl", "filename": str(table)},
        "roughconductor": {"type": "roughconductor", "material": "none", "alpha": 0.15,
                           "specular_reflectance": colour},
        "diffuse": {"type": "diffuse", "reflectance": colour},
    }


def render_variant(variant: str, bsdf: dict, resolution: tuple[int, int], spp: int, seed: int):
    """(linear RGB image, seconds including the scene's load and kernel compilation)."""
    mi.set_variant(variant)
    start = time.perf_counter()
    scene = veach_scene_dict(bsdf, integrator="mis", resolution=resolution, spp=spp)
    if mi.is_monochromatic:  # what Mitsuba's film writes there anyway (it warns about "rgb")
        scene["sensor"]["film"]["pixel_format"] = "luminance"
    image = render(mi.load_dict(scene), spp, seed=seed)
    if image.shape[-1] == 1:
        image = np.repeat(image, 3, axis=-1)
    return image, time.perf_counter() - start


BLOCK = 8  # pixels per side of the block means that average the Monte Carlo noise down


def block_means(image: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """The image's means over ``block`` x ``block`` tiles (edges that do not fill a tile left out)."""
    h, w = (image.shape[0] // block) * block, (image.shape[1] // block) * block
    tiles = image[:h, :w].reshape(h // block, block, w // block, block, -1)
    return tiles.mean(axis=(1, 3))


def compare(variant: str, images: dict, noise: dict) -> dict | None:
    """The comparison of ``variant``'s image with the one it should match (see MATCHES)."""
    if variant not in MATCHES or variant not in images:
        return None
    other, kind = MATCHES[variant]
    if other not in images:
        return None
    reference, image = images[other], images[variant]
    if kind == "luminance":
        reference = np.repeat((reference @ LUMINANCE)[..., None], 3, axis=-1)
    row = {"against": f"luminance of {other}" if kind == "luminance" else other, "kind": kind,
           "mae": metrics.mae(reference, image), **display_errors(reference, image)}
    if variant in noise:  # the same variant at another seed: its own Monte Carlo noise
        row.update({f"noise_{k}": v for k, v in display_errors(image, noise[variant]).items()})
    return row


def display_errors(reference: np.ndarray, image: np.ndarray) -> dict[str, float]:
    """Errors of the display values (``metrics.tone_map``): the light sources' pixels (radiance up
    to 900) would otherwise make the whole of a linear average, and their coverage noise with it."""
    return {"display_mae": metrics.mae_tonemapped(reference, image),
            "block_mae": metrics.mae(block_means(metrics.tone_map(reference)), block_means(metrics.tone_map(image)))}


def figure(images: dict[str, dict[str, np.ndarray]], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, columns = list(images), list(VARIANTS)
    fig, axes = plt.subplots(len(rows), len(columns), figsize=(2.0 * len(columns), 1.45 * len(rows) + 0.3),
                             squeeze=False)
    for r, name in enumerate(rows):
        for c, variant in enumerate(columns):
            ax = axes[r][c]
            ax.set_xticks([])
            ax.set_yticks([])
            if variant in images[name]:
                ax.imshow(srgb(images[name][variant]), interpolation="nearest", aspect="auto")
            if r == 0:
                ax.set_title(variant, fontsize=7.5)
            if c == 0:
                ax.set_ylabel(name, fontsize=8)
    fig.tight_layout(pad=0.3)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    path.parent.mkdir(parents=True, exist_ok=True)
    small_png(buffer, path)
    return path


def small_png(png, path: Path) -> None:
    """``png`` (a file or buffer) re-encoded with a 256-colour palette, as the README's picture:
    the figure stays a small file in the repository."""
    from PIL import Image

    Image.open(png).convert("RGB").quantize(256, dither=Image.Dither.NONE).save(path, optimize=True)


def page(data: dict, opening: str | None = None) -> str:
    """The whole page from its stored data (:func:`page_data`); ``opening``: the command that writes
    it from that data (default: the results page's own)."""
    opening = opening or stored_page.opening_command(PAGE)
    s = data["settings"]
    lines = ["# Every variant: the Veach scene in RGB, mono, spectral and polarized variants", "",
             "```sh", f"{opening}   # this page, from its stored data",
             f"{data['command']}   # to measure anew: renders every variant, rewrites the data, page and figure",
             "```", "",
             f"Mitsuba {data['mitsuba']}. LLVM variants: {s['width']} x {s['height']} pixels, "
             f"{s['spp']} spp; scalar variants: {s['scalar_width']} x {s['scalar_height']}, "
             f"{s['scalar_spp']} spp (they call the nbrdf and merl BSDFs one direction at a time through "
             "Python). Mitsuba's `direct` integrator with MIS; each BSDF's default backend (`rust` in scalar "
             f"variants, `jit` in LLVM ones). Material: {s['material']} (`nbrdf synth` table and its "
             f"network); yardsticks: Mitsuba's `roughconductor` (alpha 0.15) and `diffuse` with the RGB "
             f"colour {YARDSTICK_RGB}.", "",
             "Spectral variants uplift the nbrdf/merl RGB value per evaluation as Mitsuba uplifts "
             "unbounded RGB data (scale = 2 max(rgb), `srgb_model_fetch` of rgb / scale, value = scale "
             "`srgb_model_eval`; docs/mitsuba.md, \"Variants\"); the yardsticks use Mitsuba's own uplift of "
             "their RGB parameters. \"noise\" is the same variant rendered again at another seed: a spectral "
             "image's difference from the RGB one is the uplift's only where it exceeds that. The means over "
             f"{BLOCK} x {BLOCK}-pixel tiles average most of that noise away; what remains of the spectral-RGB "
             "difference there, beside the same figure for Mitsuba's own BSDFs, is the uplift. Errors are "
             "taken on display values (`metrics.tone_map`: gamma 2.2, clipped to [0, 1]) besides the linear "
             "MAE: the lights' own pixels (radiance up to 900) would otherwise make most of a linear "
             "average, and their pixel-coverage noise with it.", "",
             f"![one row per BSDF, one column per variant]({stored_page.link(data['figure'], PAGE)})", "",
             "| BSDF | variant | render (s) | non-finite pixels | mean display value (R, G, B) | compared with | "
             f"MAE, linear | MAE, display | MAE of {BLOCK}x{BLOCK} means, display | noise: MAE, display | "
             f"noise: MAE of {BLOCK}x{BLOCK} means, display |",
             "|---|---|---:|---:|---|---|---:|---:|---:|---:|---:|"]
    for r in data["rows"]:
        c = r["comparison"]
        mean = ", ".join(f"{v:.4f}" for v in r["mean"])
        cells = [r["bsdf"], f"`{r['variant']}`", f"{r['seconds']:.1f}", str(r["nonfinite"]), mean]
        if c:
            cells += [c["against"]] + [f"{c[k]:.2e}" if k in c else "" for k in (
                "mae", "display_mae", "block_mae", "noise_display_mae", "noise_block_mae")]
        else:
            cells += ["(reference)", "", "", "", "", ""]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", summary(data["uplift_ratios"])]
    lines += ["", "MAE: `nbrdf_tools.common.metrics.mae` (all pixels and channels). Times "
              f"include loading the scene and compiling its kernels, on {data['machine']}."]
    return "\n".join(lines + timing_lines(data.get("timing"), data["machine"])) + "\n"


def page_data(command: str, settings: dict, results: dict, comparisons: dict, figure_path: Path,
              timing: dict | None) -> dict:
    """What the page reports, as stored in its data file."""
    rows = [{"bsdf": name, "variant": variant, "seconds": r["seconds"], "nonfinite": r["nonfinite"],
             "mean": [float(v) for v in r["mean"]], "comparison": comparisons[name].get(variant)}
            for name, per_variant in results.items() for variant, r in per_variant.items()]
    for row in rows:
        if row["comparison"]:
            row["comparison"] = {k: (float(v) if isinstance(v, (float, np.floating)) else v)
                                 for k, v in row["comparison"].items() if k != "kind"}
    return {"mitsuba": mi.__version__, "machine": MACHINE, "command": command, "settings": settings,
            "figure": str(figure_path.resolve().relative_to(REPO)) if figure_path.resolve().is_relative_to(REPO)
            else str(figure_path), "rows": rows, "uplift_ratios": uplift_ratios(comparisons), "timing": timing}


TIMED_VARIANTS = ("llvm_ad_rgb", "llvm_ad_spectral")


def timings(materials: dict, resolution: tuple[int, int], spp: int, repeats: int) -> dict:
    """Median (wall, CPU) seconds of a render with compiled kernels, per (BSDF, variant): every
    scene loaded and rendered once first, then the renders interleaved (A, B, A, B ...) so that
    load from other jobs spreads over all of them. CPU time is the process's (Dr.Jit's threads
    included)."""
    import drjit as dr

    scenes = {}
    for variant in TIMED_VARIANTS:
        mi.set_variant(variant)
        for name, bsdf in materials.items():
            scenes[name, variant] = mi.load_dict(veach_scene_dict(bsdf, resolution=resolution, spp=spp))
            render(scenes[name, variant], spp, seed=2**31 - 1)
    samples = {key: [] for key in scenes}
    for r in progress.bar(range(repeats), desc="timing", unit="round"):
        for (name, variant), scene in scenes.items():
            mi.set_variant(variant)
            wall, cpu = time.perf_counter(), time.process_time()
            dr.eval(mi.render(scene, spp=spp, seed=r))
            dr.sync_thread()
            samples[name, variant].append((time.perf_counter() - wall, time.process_time() - cpu))
    return {key: np.median(np.asarray(value), axis=0) for key, value in samples.items()}


def timing_data(times: dict, resolution: tuple[int, int], spp: int, repeats: int) -> dict:
    """The stored form of :func:`timings`, with the machine's load at the end."""
    rows = []
    for name in dict.fromkeys(name for name, _ in times):
        seconds = {v: [float(x) for x in times[name, v]] for v in TIMED_VARIANTS}
        rows.append({"bsdf": name, "seconds": seconds,
                     "cpu_ratio": seconds[TIMED_VARIANTS[1]][1] / seconds[TIMED_VARIANTS[0]][1]})
    return {"width": resolution[0], "height": resolution[1], "spp": spp, "repeats": repeats,
            "load_average": os.getloadavg()[0], "rows": rows}


def timing_lines(timing: dict | None, machine: str) -> list[str]:
    if not timing:
        return []
    lines = ["", "## Cost of the uplift", "",
             f"Warm renders (kernels compiled), {timing['width']} x {timing['height']} pixels, {timing['spp']} spp, "
             f"median of {timing['repeats']} interleaved rounds; wall and CPU seconds of the whole process, on "
             f"{machine} (load average {timing['load_average']:.1f} at the end):", "",
             "| BSDF | " + " | ".join(f"`{v}` wall / CPU (s)" for v in TIMED_VARIANTS) + " | spectral / RGB, CPU |",
             "|---|" + "---:|" * (len(TIMED_VARIANTS) + 1)]
    for row in timing["rows"]:
        cells = [f"{row['seconds'][v][0]:.2f} / {row['seconds'][v][1]:.2f}" for v in TIMED_VARIANTS]
        lines.append(f"| {row['bsdf']} | " + " | ".join(cells) + f" | {row['cpu_ratio']:.2f} |")
    return lines


def uplift_ratios(comparisons: dict) -> dict[str, dict[str, float]]:
    """The spectral-RGB difference of the tile means as a multiple of the spectral render's own
    noise there, per spectral variant and BSDF: about 1 where the uplift's effect is below the
    Monte Carlo noise."""
    ratios = {}
    for variant in ("llvm_ad_spectral", "scalar_spectral"):
        found = {name: float(c[variant]["block_mae"] / c[variant]["noise_block_mae"])
                 for name, c in comparisons.items() if c.get(variant) and c[variant].get("noise_block_mae")}
        if found:
            ratios[variant] = found
    return ratios


def summary(ratios: dict[str, dict[str, float]]) -> str:
    if not ratios:
        return ""
    parts = [f"`{variant}`: " + ", ".join(f"{name} {ratio:.2f}" for name, ratio in found.items())
             for variant, found in ratios.items()]
    return ("Spectral against RGB, MAE of the tile means divided by the same variant's noise MAE of the tile "
            "means (about 1: the difference is the Monte Carlo noise; the yardsticks show Mitsuba's own "
            "uplift on the same scale): " + "; ".join(parts) + ".")


def parse_arguments(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--material", default=DEFAULT_MATERIAL, help="MERL material name (nbrdf list-materials)")
    parser.add_argument("--samples", type=int, default=800_000, help="training samples of the network")
    parser.add_argument("--width", type=int, default=192, help="LLVM variants' image width (height 2/3)")
    parser.add_argument("--spp", type=int, default=256, help="LLVM variants' samples per pixel")
    parser.add_argument("--scalar-width", type=int, default=72, help="scalar variants' image width")
    parser.add_argument("--scalar-spp", type=int, default=16, help="scalar variants' samples per pixel")
    parser.add_argument("--timing-repeats", type=int, default=5,
                        help="interleaved warm renders timed per BSDF in llvm_ad_rgb and llvm_ad_spectral (0: none)")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS, help="variants to render")
    parser.add_argument("--work", type=Path, default=default_out("variants"), help="materials and EXR renders")
    stored_page.add_arguments(parser, PAGE)
    parser.add_argument("--figure", type=Path, default=DEFAULT_FIGURE, help="the figure (default: %(default)s)")
    parser.add_argument("--cli", type=Path, default=default_cli(), help="nbrdf CLI (default: %(default)s)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars (for logs)")
    return parser.parse_args(argv)


def render_all(materials: dict, args: argparse.Namespace) -> tuple[dict, dict, dict]:
    """(results, images, noise images) per BSDF and variant; EXRs under WORK."""
    results = {name: {} for name in materials}
    images = {name: {} for name in materials}
    noise = {name: {} for name in materials}
    jobs = [(name, variant) for name in materials for variant in args.variants]
    for name, variant in progress.bar(jobs, desc="rendering", unit="image"):
        scalar = variant.startswith("scalar")
        width, spp = (args.scalar_width, args.scalar_spp) if scalar else (args.width, args.spp)
        resolution = (width, width * 2 // 3)
        image, seconds = render_variant(variant, materials[name], resolution, spp, seed=0)
        if "spectral" in variant and not variant.endswith("polarized"):
            noise[name][variant] = render_variant(variant, materials[name], resolution, spp, seed=1)[0]
        images[name][variant] = image
        bad = metrics.nonfinite_count(image)
        results[name][variant] = {"seconds": seconds, "nonfinite": bad,
                                  "mean": metrics.tone_map(image).reshape(-1, 3).mean(axis=0)}
        write_exr(args.work / f"veach-{name}-{variant}.exr", image)
        progress.log(f"{name:15s} {variant:28s} {seconds:6.1f} s  mean {np.mean(image):.4f}  non-finite {bad}")
    return results, images, noise


def command_line(args: argparse.Namespace) -> str:
    """The command that regenerates the page (the options that differ from the defaults)."""
    return "python -m nbrdf_tools variants" + "".join(
        f" {flag} {value}" for flag, value, default in (
            ("--width", args.width, 192), ("--spp", args.spp, 256), ("--scalar-width", args.scalar_width, 72),
            ("--scalar-spp", args.scalar_spp, 16), ("--material", args.material, DEFAULT_MATERIAL),
            ("--timing-repeats", args.timing_repeats, 5))
        if value != default)


def main(argv: list[str] | None = None) -> int:
    args = parse_arguments(argv)
    if args.stored_only:
        stored_page.write(args.out, page(stored_page.load(stored_page.data_for(args, PAGE))))
        print(f"wrote {args.out} from {stored_page.data_for(args, PAGE)}")
        return 0
    progress.set_enabled(not args.no_progress)
    missing = [v for v in args.variants if v not in mi.variants()]
    if missing:
        print(f"error: the installed Mitsuba lacks the variants {', '.join(missing)}", file=sys.stderr)
        return 1
    try:
        cli.check_cli(args.cli)
        args.work.mkdir(parents=True, exist_ok=True)
        table = synthesise(args.cli, "sgd", args.material, args.work)
        network = train(args.cli, table, args.work, args.material, args.samples)
    except (MissingDataError, cli.CommandError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1

    settings = {"width": args.width, "height": args.width * 2 // 3, "spp": args.spp, "material": args.material,
                "scalar_width": args.scalar_width, "scalar_height": args.scalar_width * 2 // 3,
                "scalar_spp": args.scalar_spp}
    materials = bsdfs(network, table)
    results, images, noise = render_all(materials, args)
    comparisons = {name: {v: compare(v, images[name], noise[name]) for v in args.variants} for name in materials}
    figure_path = figure(images, args.figure)
    timing = None
    if args.timing_repeats > 0 and all(v in mi.variants() for v in TIMED_VARIANTS):
        timed = {name: materials[name] for name in ("nbrdf", "merl", "roughconductor")}
        resolution, spp = (args.width, args.width * 2 // 3), max(1, args.spp // 8)
        timing = timing_data(timings(timed, resolution, spp, args.timing_repeats), resolution, spp,
                             args.timing_repeats)
    data = page_data(command_line(args), settings, results, comparisons, figure_path, timing)
    data_file = stored_page.save(stored_page.data_for(args, PAGE), data)
    text = page(data, stored_page.opening_command(PAGE, args.out, data_file))
    stored_page.write(args.out, text)
    print(text)
    print(f"data: {data_file}\nfigure: {figure_path}\nrenders: {args.work}")
    failed = any(r["nonfinite"] for per_variant in results.values() for r in per_variant.values())
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
