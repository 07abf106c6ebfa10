"""The main job on the embedded default data: synthesise the MERL-format table of a default
material from its published fit, train its neural BRDF (``nbrdf train``), fit its Blinn-Phong
sampling lobe (``nbrdf fit-phong``), render the Veach MIS scene with the table (``merl``, the
ground truth) and with the network (``nbrdf``, Phong-sampled) on the plates, and write EXR and
PNG images side by side with the image error between them.

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


def train(cli: Path, table: Path, out: Path, material: str, samples: int) -> Path:
    """The NBRDF of `table` with its fitted Blinn-Phong lobe; retrained when the table is newer."""
    network = out / f"{material}.nbrdf.json"
    if not network.exists() or network.stat().st_mtime < table.stat().st_mtime:
        subprocess.run([str(cli), "train", str(table), "-o", str(network), "--samples", str(samples)], check=True)
        subprocess.run([str(cli), "fit-phong", str(network)], check=True)
    return network


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
    parser.add_argument("--samples", type=int, default=800_000, help="training samples of the NBRDF")
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
    print(f"table:   {table} ({time.perf_counter() - start:.1f} s)")
    start = time.perf_counter()
    network = train(args.cli, table, args.out, args.material, args.samples)
    print(f"network: {network} ({time.perf_counter() - start:.1f} s, with the Phong fit)")

    passes = max(1, min(args.passes, args.spp))
    resolution = (args.width, args.width * 2 // 3)
    images = {}
    for label, bsdf in (("table", {"type": "merl", "filename": str(table)}),
                        ("nbrdf", {"type": "nbrdf", "filename": str(network)})):
        scene_dict = veach_scene_dict(bsdf, integrator="mis", resolution=resolution)
        start = time.perf_counter()
        images[label] = render_passes(scene_dict, args.spp // passes, passes, f"rendering the {label}")
        print(f"render:  {label}, {args.spp} spp in {time.perf_counter() - start:.1f} s ({args.variant})")
        if not np.all(np.isfinite(images[label])):
            print(f"error: the {label} render contains NaN or Inf", file=sys.stderr)
            return 1

    truth, ours = images["table"], images["nbrdf"]
    rmse = float(np.sqrt(np.mean((ours - truth) ** 2)))
    mae = float(np.mean(np.abs(ours - truth)))
    stem = args.out / f"veach-{args.material}"
    for label, image in images.items():
        mi.Bitmap(image.astype(np.float32)).write(f"{stem}-{label}.exr")
    side_by_side = np.concatenate([truth, ours], axis=1).astype(np.float32)
    mi.util.write_bitmap(f"{stem}.png", side_by_side)
    print(f"error:   NBRDF vs table, MAE {mae:.4f}, RMSE {rmse:.4f} (linear radiance, mean pixel "
          f"{float(np.mean(truth)):.4f}; includes Monte Carlo noise at {args.spp} spp)")
    print(f"images:  {stem}-table.exr, {stem}-nbrdf.exr\n         {stem}.png (left: table, right: NBRDF)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
