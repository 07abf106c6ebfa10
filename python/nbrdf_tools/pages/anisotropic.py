"""Anisotropic distillation: a roughconductor with an elliptical highlight, distilled with
``--anisotropy on`` and ``off``, rendered beside Mitsuba's own BSDF on surfaces whose ``to_world``
turns the tangent frame.

    python -m nbrdf_tools anisotropic --out docs/results/anisotropic
        [--alpha-u 0.05] [--alpha-v 0.3] [--samples N] [--epochs N] [--spp 64] [--size 192]

The scene (:func:`scene`): a plate turned by ``--plate-angle`` degrees about its normal and a
sphere turned by ``--sphere-angle`` degrees about the x axis, lit by a point light (the
``direct`` integrator with emitter samples only, so the three renders trace the same paths and
differ by the BSDF alone). Errors of each network's render against Mitsuba's (names of
:mod:`nbrdf_tools.common.metrics`). Writes OUT/anisotropic.json, OUT/anisotropic.png (side by side, with
error maps) and the networks (OUT/work).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path


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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m nbrdf_tools anisotropic",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/results/anisotropic"),
                        help="folder of the JSON, the PNG and the networks (default: %(default)s)")
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

    import mitsuba as mi

    from nbrdf_mitsuba.distill import pick_variant

    work = args.out / "work"
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
    result = {
        "command": "python -m nbrdf_tools anisotropic " + " ".join(argv if argv is not None else sys.argv[1:]),
        "bsdf": spec, "variant": mi.variant(),
        "scene": {"size": [args.size, args.size * 3 // 4], "spp": args.spp, "plate_angle": args.plate_angle,
                  "sphere_angle": args.sphere_angle},
        "networks": networks,
        "errors": {label: errors(reference, image) for label, image in images.items() if image is not reference},
    }
    (args.out / "anisotropic.json").write_text(json.dumps(result, indent=2) + "\n")
    if not args.no_figure:
        figure(images, args.out / "anisotropic.png")
    for label, e in result["errors"].items():
        print(f"{label}: " + ", ".join(f"{k} {v:.4f}" for k, v in e.items()))
    print(f"wrote {args.out / 'anisotropic.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
