"""The text of docs/results/spectral-networks.md from its stored data
(:func:`nbrdf_tools.pages.spectral_networks.page_data`): the introduction and the tables of log
errors, images, interpolation and training."""

from __future__ import annotations

from nbrdf_tools.common import stored_page
from nbrdf_tools.pages.spectral_networks import AT_NM, LABELS, NETWORKS, PAGE, STEPS_NM, VARIANTS


def _introduction(data: dict) -> list[str]:
    materials = [s for s in data["sources"] if not s["rgl"]]
    rgl = [s for s in data["sources"] if s["rgl"]]
    first = data["sources"][0]["training"]
    lines = [
        *(["**Quick run** (`--quick`: tiny training budget and images, for tests; not the figures of record).", ""]
          if data["quick"] else []),
        *([f"Sources: Mitsuba's `roughconductor` with `alpha` {data['alpha']} and `material` "
           f"{', '.join(s['label'] for s in materials)} (indices of refraction from measured spectral data). "
           "Each is distilled twice by `python -m nbrdf_mitsuba.distill`: in `llvm_ad_spectral` into a **spectral "
           "network** (file format version 3: 16 cubic B-spline coefficients over 360-830 nm; Mitsuba evaluates the "
           f"source every {data['wavelength_step']:g} nm) and in `llvm_ad_rgb` into an **RGB "
           f"network**; {data['samples'] or '?'} training pairs, at most {data['max_epochs'] or '?'} "
           "epochs, the same seed.", ""] if materials else []),
        *[f"RGL measurement `{s['file']}`{' (' + s['note'] + ')' if s['note'] else ''}: the spectral network distilled "
          "from Mitsuba's `measured` in `llvm_ad_spectral`, the RGB network by `nbrdf train` (the measurement's sRGB "
          "projection under D65). Mitsuba's `measured` refuses spectral files in RGB variants, so there is no "
          "`llvm_ad_rgb` reference for it." for s in rgl],
        *([""] if rgl else ["No spectral RGL measurement was at hand: the four shared RGL files (`../shared/data/rgl`) "
                            "are RGB (`*_rgb.bsdf`); `--rgl FILE.bsdf` adds one (an RGB file is made spectral with "
                            "synthetic spectra by `nbrdf_tools.data.spectral_rgl`).", ""]),
        f"Weights: the spectral network has {first['spectral']['parameters']} (6-21-21-16), the RGB one "
        f"{first['rgb']['parameters']} (6-21-21-3): {first['spectral']['parameters'] / first['rgb']['parameters']:.2f}x.",
        "",
        f"Machine: {data['machine']}, shared with other jobs (load average {data['load_average']:.1f} at the end; "
        "times indicative).", "",
        f"![spheres and per-wavelength errors]({stored_page.link(data['figure'], PAGE)})", "",
        "Reading the tables: the per-wavelength log error compares the BSDFs themselves, without noise. The "
        "sphere images hold Monte Carlo noise on both sides (the networks sample with their fitted lobes or "
        "tables, the source with its own distribution): compare each error with the noise floor. "
        "Mitsuba's `roughconductor` is not the same material in both variants: "
        "in RGB variants its Fresnel term takes the index of refraction converted to RGB, not the sRGB projection "
        "of its spectral reflectance. A spectral network (whose RGB value is that projection) is therefore held in "
        "`llvm_ad_rgb` to a reference it did not learn, as the RGB network (uplifted) is in `llvm_ad_spectral`: "
        "each network is measured against its own source in its own variant, and against the other variant's "
        "for what a user switching variants sees.", "",
    ]
    return lines


def _log_error_table(data: dict) -> list[str]:
    lines = ["## Log error per wavelength", "",
             f"`mean |ln(1 + f cos) - ln(1 + f_net cos)|` over {data['pairs']} uniform pairs of directions, in "
             "`llvm_ad_spectral`: the spectral network's own spectrum, and the RGB network's value uplifted by "
             "Mitsuba per wavelength (how a spectral render sees it).", "",
             "| source | network | mean over wavelengths | worst wavelength | "
             + " | ".join(f"{nm} nm" for nm in AT_NM) + " |",
             "|---|---|---:|---:|" + "---:|" * len(AT_NM)]
    for s in data["sources"]:
        for name, label in (("spectral", "spectral"), ("rgb", "RGB, uplifted")):
            e = s["log_errors"][name]
            lines.append(f"| {s['label']} | {label} | {e['mean']:.2e} | {e['max']:.2e} ({e['worst_nm']:g} nm) | "
                         + " | ".join(f"{v:.2e}" for v in e["at"]) + " |")
    return lines


def _sampling_summary(data: dict) -> str:
    chosen = [f"{s['label']} {LABELS[kind]}: {run['sampling']}"
              for s in data["sources"] for kind, run in s["training"].items() if run.get("sampling")]
    return ", ".join(chosen) or "none fitted"


def _image_table(data: dict) -> list[str]:
    lines = ["", "## Sphere images", "",
             f"{data['size']} x {data['size']} pixels, {data['spp']} spp, a directional light (D65) and a dim constant "
             "environment; errors against the source rendered in the same variant at the same seed "
             "(`nbrdf_tools.common.metrics`: RMSE of the tone-mapped images, SSIM, HDR-FLIP, relative RMSE of the linear "
             "images); render seconds after a 1-spp render that compiles the kernels (wall / CPU). Each network "
             "samples with what `nbrdf fit-phong` stored for it (lowest variance: "
             f"{_sampling_summary(data)}), the source its own distribution, so "
             "their noise differs: *noise floor* is the source against itself rendered at another seed "
             "(HDR-FLIP / SSIM), the part of each error that is Monte Carlo noise.", "",
             "| source | variant | network | RMSE (tone-mapped) | SSIM | HDR-FLIP | relative RMSE | noise floor | "
             "render s |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for s in data["sources"]:
        for variant in VARIANTS:
            for name, label in (("spectral", "spectral"), ("rgb", "RGB")):
                found = s["images"][variant][name]
                e, noise = found["errors"], found["noise"]
                cells = ([f"{e['rmse_tonemapped']:.4f}", f"{e['ssim']:.4f}", f"{e['flip_hdr']:.4f}",
                          f"{e['relative_rmse']:.4f}", f"{noise['flip_hdr']:.4f} / {noise['ssim']:.4f}"]
                         if e else ["-"] * 5)
                lines.append(f"| {s['label']} | `{variant}` | {label} | " + " | ".join(cells)
                             + f" | {found['wall']:.2f} / {found['cpu']:.2f} |")
    return lines


def _interpolation_table(data: dict) -> list[str]:
    found = [s for s in data["sources"] if s["interpolation"]]
    if not found:
        return []
    lines = ["", "## Sampling the source's spectrum", "",
             "Linear interpolation between samples every 5-40 nm against the source's spectrum every 1 nm "
             "(relative RMS over the wavelengths, mean and worst over pairs of directions):", "",
             "| source | " + " | ".join(f"{s:g} nm" for s in STEPS_NM) + " |", "|---|" + "---:|" * len(STEPS_NM)]
    for s in found:
        lines.append(f"| {s['label']} | " + " | ".join(
            f"{100 * m:.3f} % (worst {100 * x:.3f} %)" for m, x in (s["interpolation"][f"{step:g}"] for step in STEPS_NM))
            + " |")
    return lines


def _training_table(data: dict) -> list[str]:
    lines = ["", "## Training", "",
             "| source | network | made by | epochs | best validation loss | wall s | CPU s |",
             "|---|---|---|---:|---:|---:|---:|"]
    for s in data["sources"]:
        for name in NETWORKS:
            run = s["training"][name]
            loss = run["best_validation_loss"]
            lines.append(f"| {s['label']} | {name} (version {run['version']}) | {run['how']} | {run['epochs']} | "
                         f"{float('nan') if loss is None else loss:.3e} | {run['seconds']:.1f} | "
                         f"{run['cpu_seconds']:.1f} |")
    return lines


def page(data: dict, opening: str | None = None) -> str:
    """The whole page from its stored data (:func:`page_data`); ``opening``: the command that writes
    it from that data (default: the results page's own)."""
    opening = opening or stored_page.opening_command(PAGE)
    lines = ["# Spectral networks", "", "```sh", f"{opening}   # this page, from its stored data",
             f"{data['command']}   # to measure anew (rewrites the data, page and figure)", "```", "",
             *_introduction(data), *_log_error_table(data), *_image_table(data), *_interpolation_table(data),
             *_training_table(data)]
    return "\n".join(lines) + "\n"
