"""The main job on the embedded default data: synthesise the MERL-format table of a default
material from its published fit, render the Veach MIS scene with that table on the plates through
the ``merl`` BSDF, and write EXR and PNG images.

    python python/demo.py [--material NAME] [--spp N] [--out DIR]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import nbrdf_mitsuba  # first: finds a libLLVM for Dr.Jit before Mitsuba starts its JIT
import mitsuba as mi
import numpy as np
from tqdm import tqdm

from veach_scene import veach_scene_dict

REPO = Path(__file__).resolve().parent.parent
DEFAULT_MATERIAL = "gold-metallic-paint"


def synthesise(cli: Path, model: str, material: str, out: Path) -> Path:
    table = out / f"{material}.{model}.binary"
    if not table.exists():
        subprocess.run(
            [str(cli), "synth", "--model", model, "--material", material, "-o", str(table)],
            check=True,
        )
    return table


def render_passes(scene_dict: dict, spp: int, passes: int, desc: str) -> np.ndarray:
    """Averages `passes` independent renders so the user sees progress on long renders."""
    total = None
    for k in tqdm(range(passes), desc=desc, unit="pass"):
        scene_dict["sensor"]["sampler"]["seed"] = k
        scene = mi.load_dict(scene_dict)
        image = np.array(mi.render(scene, spp=spp))
        total = image if total is None else total + image
    return total / passes


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--material", default=DEFAULT_MATERIAL, help="MERL material name (nbrdf list-materials)")
    parser.add_argument("--model", default="sgd", choices=["sgd", "abc"], help="published fit to tabulate")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel in all")
    parser.add_argument("--passes", type=int, default=8, help="renders averaged (progress granularity)")
    parser.add_argument("--width", type=int, default=384, help="image width (height is 2/3 of it)")
    parser.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant")
    parser.add_argument("--out", type=Path, default=REPO / "out" / "demo", help="output folder")
    parser.add_argument("--cli", type=Path, default=REPO / "target" / "release" / "nbrdf", help="nbrdf CLI")
    args = parser.parse_args()

    args.out.mkdir(parents=True, exist_ok=True)
    mi.set_variant(args.variant)
    nbrdf_mitsuba.register()

    start = time.perf_counter()
    table = synthesise(args.cli, args.model, args.material, args.out)
    print(f"table:  {table} ({time.perf_counter() - start:.1f} s)")

    passes = max(1, min(args.passes, args.spp))
    scene_dict = veach_scene_dict(
        {"type": "merl", "filename": str(table)},
        integrator="mis",
        resolution=(args.width, args.width * 2 // 3),
    )
    start = time.perf_counter()
    image = render_passes(scene_dict, args.spp // passes, passes, f"rendering {args.material}")
    seconds = time.perf_counter() - start
    if not np.all(np.isfinite(image)):
        print("error: the render contains NaN or Inf", file=sys.stderr)
        return 1
    stem = args.out / f"veach-{args.material}"
    bitmap = mi.Bitmap(image.astype(np.float32))
    bitmap.write(str(stem) + ".exr")
    mi.util.write_bitmap(str(stem) + ".png", image.astype(np.float32))
    print(f"render: {args.spp} spp in {seconds:.1f} s ({args.variant})")
    print(f"images: {stem}.exr\n        {stem}.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
