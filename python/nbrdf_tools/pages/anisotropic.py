"""Anisotropic distillation: a roughconductor with an elliptical highlight, distilled with
``--anisotropy on`` and ``off``, rendered beside Mitsuba's own BSDF on surfaces whose ``to_world``
turns the tangent frame.

    python -m nbrdf_tools anisotropic --stored-only --out docs/results/anisotropic.md
    python -m nbrdf_tools anisotropic [--out docs/results/anisotropic.md] [--data docs/results/anisotropic]
        [--alpha-u 0.05] [--alpha-v 0.3] [--samples N] [--epochs N] [--spp 64] [--size 192]

The scene (:func:`scene`): a plate turned by ``--plate-angle`` degrees about its normal and a
sphere turned by ``--sphere-angle`` degrees about the x axis, lit by a point light (the
``direct`` integrator with emitter samples only, so the three renders trace the same paths and
differ by the BSDF alone). Errors of each network's render against Mitsuba's (names of
:mod:`nbrdf_tools.common.metrics`). Writes DATA/anisotropic.json, DATA/anisotropic.png (side by side, with
error maps), the networks (DATA/work) and the page (``--out``). With ``--stored-only`` the page is
written from DATA/anisotropic.json alone, measuring nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from nbrdf_tools.common.paths import REPO

PAGE = Path("docs/results/anisotropic.md")
DATA = Path("docs/results/anisotropic")
OPENING = f"python -m nbrdf_tools anisotropic --stored-only --out {PAGE}"


def conductor(alpha_u: float, alpha_v: float) -> dict:
    return {"type": "roughconductor", "distribution": "ggx", "material": "Au",
            "alpha_u": alpha_u, "alpha_v": alpha_v}


def distill(source: Path, out: Path, anisotropy: str, extra: list[str]) -> dict:
    command = [sys.executable, "-m", "nbrdf_mitsuba.distill", str(source), "-o", str(out), "-q",
               "--anisotropy", anisotropy, *extra]
    start = time.perf_counter()
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"anisotropic_report: {' '.join(command)} failed:\n{result.stderr}")
    provenance = json.loads(out.read_text())["provenance"]
    return {"network": str(out), "wall_seconds": time.perf_counter() - start,
            "training_seconds": provenance["seconds"], "epochs": provenance["epochs"],
            "max_epochs": provenance["max_epochs"],
            "samples": provenance["samples"], "best_validation_loss": provenance["best_validation_loss"],
            "anisotropic": json.loads(out.read_text()).get("anisotropic", False)}


def scene(bsdf: dict, size: int, spp: int, plate_angle: float, sphere_angle: float) -> dict:
    import mitsuba as mi

    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": T().look_at(origin=[0, -4.0, 3.0], target=[0, 0, 0.3], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": size, "height": size * 3 // 4,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "plate": {"type": "rectangle", "bsdf": bsdf,
                  "to_world": T().scale(1.6).rotate([0, 0, 1], plate_angle)},
        "ball": {"type": "sphere", "bsdf": bsdf,
                 "to_world": T().translate([0.0, 0.3, 0.75]).rotate([1, 0, 0], sphere_angle).scale(0.7)},
        "light": {"type": "point", "position": [0.8, 1.6, 3.0], "intensity": {"type": "rgb", "value": 14.0}},
    }


def render(bsdf: dict, args):
    import mitsuba as mi
    import numpy as np

    return np.array(mi.render(mi.load_dict(scene(bsdf, args.size, args.spp, args.plate_angle, args.sphere_angle)),
                              seed=1), dtype=np.float64)[..., :3]


def errors(reference, image) -> dict:
    from nbrdf_tools.common import metrics

    return {"rmse_tonemapped": metrics.rmse_tonemapped(reference, image),
            "relative_rmse": metrics.relative_rmse(reference, image),
            "ssim": metrics.ssim(reference, image), "flip_hdr": metrics.flip_hdr(reference, image)}


def figure(images: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from nbrdf_tools.common.metrics import tone_map

    names = list(images)
    reference = images[names[0]]
    fig, axes = plt.subplots(2, len(names), figsize=(4 * len(names), 6.2))
    for k, name in enumerate(names):
        axes[0, k].imshow(tone_map(images[name]))
        axes[0, k].set_title(name, fontsize=10)
        diff = np.abs(tone_map(images[name]) - tone_map(reference)).mean(axis=-1)
        axes[1, k].imshow(diff, cmap="magma", vmin=0, vmax=0.3)
        axes[1, k].set_title("|tone-mapped difference| vs Mitsuba" if k else "(reference)", fontsize=9)
    for ax in axes.flat:
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def report(data: dict) -> str:
    """The page, from the stored results alone."""
    bsdf, scene, networks, errors = data["bsdf"], data["scene"], data["networks"], data["errors"]
    on, off = networks["on"], networks["off"]
    aniso, iso = errors["anisotropic NBRDF"], errors["isotropic NBRDF"]
    all_epochs = on["epochs"] == on["max_epochs"] and off["epochs"] == off["max_epochs"]
    wall_minutes = (on["wall_seconds"] + off["wall_seconds"]) / 60
    lines = [
        f"# Anisotropic distillation: {bsdf['type']} on turned surfaces", "",
        "```sh", OPENING, "```", "",
        f"The command above writes this page from the stored results, `{DATA}/anisotropic.json`. To measure "
        "anew (distils both networks, renders the scene, and rewrites that file, the figure, the networks "
        f"in `{DATA}/work/` and this page): `{data['command']}`.", "",
        f"Mitsuba's `{bsdf['type']}` ({bsdf['distribution'].upper()}, material `{bsdf['material']}`, "
        f"`alpha_u` {bsdf['alpha_u']}, `alpha_v` {bsdf['alpha_v']}: a highlight narrow along the tangent and "
        "wide across it) is distilled twice with `python -m nbrdf_mitsuba.distill`, with `--anisotropy on` "
        "(the network's input carries the half vector's azimuth `phi_h`) and with `--anisotropy off` (the "
        "isotropic network, `phi_h` = 0), both at the trainer's default budget: "
        f"{on['samples']:,} training pairs for the anisotropic network, {off['samples']:,} for the isotropic "
        f"one, up to {on['max_epochs']} epochs with early stopping"
        + (f" (both ran all {on['max_epochs']})" if all_epochs else "") + ". "
        f"The three BSDFs then render the same scene: a plate turned by {scene['plate_angle']:g} degrees about "
        f"its normal and a sphere turned by {scene['sphere_angle']:g} degrees about the x axis (`to_world` "
        "turns their tangent frames, and with them the highlights' orientation), lit by a point light, "
        f"{scene['size'][0]} x {scene['size'][1]} pixels, {scene['spp']} samples per pixel, `direct` integrator "
        "with emitter samples only (the three renders trace the same paths and differ by the BSDF alone), "
        f"`{data['variant']}`.", "",
        "Errors of each network's render against Mitsuba's roughconductor (whole image; names of "
        "`nbrdf_tools.common.metrics`: `rmse_tonemapped` is the RMSE of the gamma-2.2 tone-mapped images, "
        "`relative_rmse` the linear RMSE over the reference's RMS, SSIM and HDR-FLIP as defined there):", "",
        "| network | training | epochs | rmse_tonemapped | relative_rmse | SSIM | HDR-FLIP |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for key, label, name in (("on", "anisotropic", "anisotropic NBRDF"), ("off", "isotropic", "isotropic NBRDF")):
        n, e = networks[key], errors[name]
        lines.append(f"| {label} (`--anisotropy {key}`) | {n['training_seconds']:.0f} s | {n['epochs']} | "
                     f"{e['rmse_tonemapped']:.4f} | {e['relative_rmse']:.3f} | {e['ssim']:.4f} | "
                     f"{e['flip_hdr']:.3f} |")
    lines += [
        "", f"![Mitsuba's {bsdf['type']}, the anisotropic and the isotropic NBRDF; below, tone-mapped "
        f"differences](anisotropic/anisotropic.png)", "",
        "The anisotropic network renders the turned highlights like Mitsuba's BSDF: the streak on the plate "
        f"follows the plate's {scene['plate_angle']:g}-degree turn and the sphere's wedge-shaped highlight "
        "(the sphere's tangent frame converges "
        "at its pole) has the same shape and place; its tone-mapped RMSE is "
        f"{iso['rmse_tonemapped'] / aniso['rmse_tonemapped']:.0f}x lower than the isotropic network's, and its "
        "remaining error (the difference map) is a faint banding along the highlight's edges. The isotropic "
        "network cannot do this whatever its budget: its input has no `phi_h`, and the adaptive sampling it is "
        "trained with has `phi_h` = 0 (the half vector tilted towards the tangent), so it learns the narrow "
        "`alpha_u` slice and repeats it in every azimuth, a small round highlight where Mitsuba's is a long "
        f"streak. The validation losses in the JSON ({on['best_validation_loss']:.1e} anisotropic, "
        f"{off['best_validation_loss']:.1e} isotropic) are not comparable: each network is validated on its "
        "own sampling, and the isotropic one's covers only the slice it can fit.", "",
        f"Machine: {data['machine']}" + (f" ({data['conditions']})" if data.get("conditions") else "")
        + f"; the whole command took about {wall_minutes:.0f} minutes, nearly all of it training; Mitsuba's "
        "evaluation of the pairs takes a few seconds.",
    ]
    reduced = data.get("reduced_budget")
    if reduced:
        ra, ri = reduced["errors"]["anisotropic NBRDF"], reduced["errors"]["isotropic NBRDF"]
        lines += ["", f"At a reduced budget ({reduced['samples']:,} pairs and {reduced['epochs']} epochs for "
                  f"each network, {reduced['training_seconds']['on']} s and {reduced['training_seconds']['off']} s "
                  "of training) the errors were nearly the same (anisotropic tone-mapped RMSE "
                  f"{ra['rmse_tonemapped']:.4f}, SSIM {ra['ssim']:.4f}, HDR-FLIP {ra['flip_hdr']:.3f}; isotropic "
                  f"{ri['rmse_tonemapped']:.4f}, {ri['ssim']:.4f}, {ri['flip_hdr']:.3f}): the larger budget buys "
                  "the anisotropic network little on this material."]
    lines += ["", "`tests/test_anisotropic_report.py` checks the same ordering at 30,000 pairs, 30 epochs and a "
              "64-pixel image (the anisotropic network's tone-mapped RMSE under half the isotropic one's).", "",
              f"Numbers, networks and the source dictionary: `{DATA.name}/anisotropic.json`, `{DATA.name}/work/`."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m nbrdf_tools anisotropic",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=REPO / PAGE, help=f"the Markdown page (default: {PAGE})")
    parser.add_argument("--data", type=Path, default=REPO / DATA,
                        help=f"folder of the JSON, the PNG and the networks (default: {DATA})")
    parser.add_argument("--stored-only", action="store_true",
                        help="write the page from DATA/anisotropic.json, measuring nothing")
    parser.add_argument("--alpha-u", type=float, default=0.05, help="roughconductor alpha_u (default: 0.05)")
    parser.add_argument("--alpha-v", type=float, default=0.3, help="roughconductor alpha_v (default: 0.3)")
    parser.add_argument("--samples", type=int, help="training pairs of both networks (default: the trainer's)")
    parser.add_argument("--epochs", type=int, help="most epochs (default: the trainer's)")
    parser.add_argument("--seed", type=int, default=0, help="training seed (default: 0)")
    parser.add_argument("--size", type=int, default=192, help="image width in pixels (default: 192)")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel (default: 64)")
    parser.add_argument("--plate-angle", type=float, default=40.0,
                        help="degrees the plate turns about its normal (default: 40)")
    parser.add_argument("--sphere-angle", type=float, default=50.0,
                        help="degrees the sphere turns about the x axis (default: 50)")
    parser.add_argument("--no-figure", action="store_true", help="skip the PNG (tests)")
    args = parser.parse_args(argv)
    if min(args.alpha_u, args.alpha_v) <= 0:
        parser.error("the roughnesses must be positive")
    stored = args.data / "anisotropic.json"
    if args.stored_only:
        args.out.write_text(report(json.loads(stored.read_text())))
        print(f"wrote {args.out}")
        return 0

    import mitsuba as mi

    from nbrdf_mitsuba.distill import pick_variant

    work = args.data / "work"
    work.mkdir(parents=True, exist_ok=True)
    spec = conductor(args.alpha_u, args.alpha_v)
    source = work / "roughconductor.json"
    source.write_text(json.dumps(spec, indent=2) + "\n")
    extra = [*(["--samples", str(args.samples)] if args.samples else []),
             *(["--epochs", str(args.epochs)] if args.epochs else []), "--seed", str(args.seed)]
    networks = {}
    for anisotropy in ("on", "off"):
        networks[anisotropy] = distill(source, work / f"roughconductor-{anisotropy}.nbrdf.json", anisotropy, extra)
        print(f"--anisotropy {anisotropy}: {networks[anisotropy]['epochs']} epochs, "
              f"{networks[anisotropy]['training_seconds']:.1f} s", flush=True)
    mi.set_variant(pick_variant())
    images = {"Mitsuba roughconductor": render(spec, args)}
    for anisotropy, label in (("on", "anisotropic NBRDF"), ("off", "isotropic NBRDF")):
        images[label] = render({"type": "nbrdf", "filename": networks[anisotropy]["network"]}, args)
    reference = images["Mitsuba roughconductor"]
    words = list(argv if argv is not None else sys.argv[1:])
    result = {
        "command": " ".join(["python -m nbrdf_tools anisotropic", *words]),
        "machine": f"{os.cpu_count()} cores", "bsdf": spec, "variant": mi.variant(),
        "scene": {"size": [args.size, args.size * 3 // 4], "spp": args.spp, "plate_angle": args.plate_angle,
                  "sphere_angle": args.sphere_angle},
        "networks": networks,
        "errors": {label: errors(reference, image) for label, image in images.items() if image is not reference},
    }
    if stored.is_file() and "reduced_budget" in (previous := json.loads(stored.read_text())):
        result["reduced_budget"] = previous["reduced_budget"]  # a separate run at another budget
    stored.write_text(json.dumps(result, indent=2) + "\n")
    if not args.no_figure:
        figure(images, args.data / "anisotropic.png")
    for label, e in result["errors"].items():
        print(f"{label}: " + ", ".join(f"{k} {v:.4f}" for k, v in e.items()))
    args.out.write_text(report(result))
    print(f"wrote {stored} and {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
