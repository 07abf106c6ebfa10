"""Rays per second of our BSDFs against Mitsuba's built-ins, in the same scene, variant and mode.

Every BSDF under test is put on the four plates of the Veach scene (direct illumination with MIS:
per sample one camera ray, one shadow ray and one BSDF ray), rendered once to compile the kernels,
then timed over several renders; runs of the different BSDFs alternate within one process so that
machine load affects them alike. Modes of the JIT variants: ``default`` (Dr.Jit's symbolic loops and
calls, Mitsuba's megakernel) and ``wavefront`` (symbolic loops and calls off, which the Rust backend
needs). A scalar variant (``--variant scalar_rgb``) has one mode, ``scalar``, and the Rust backend
alone, which Mitsuba calls once per direction through Python (docs/mitsuba.md, "Performance").

    python -m nbrdf_tools.bench_rays [--quick] [--json FILE] [--modes default,wavefront] [--no-progress]
    python -m nbrdf_tools.bench_rays --variant scalar_rgb --bsdfs nbrdf,roughconductor --width 128 --spp 4

The network is trained by ``nbrdf train`` (briefly: speed, not accuracy, is measured) unless the
authors' Keras network of the material is in the shared data.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import nbrdf_mitsuba  # first: finds a libLLVM for Dr.Jit before Mitsuba starts its JIT
import drjit as dr
import mitsuba as mi

from nbrdf_tools import cli, progress
from nbrdf_tools.paths import MissingDataError, default_cli, default_out, shared_path
from nbrdf_tools.progress import bar
from nbrdf_tools.render import sync
from nbrdf_tools.scenes.veach import veach_scene_dict

RAYS_PER_SAMPLE = 3  # camera ray, emitter (shadow) ray, BSDF ray of the MIS direct integrator
DEFAULT_MATERIAL = "gold-metallic-paint"


def builtin_bsdfs() -> dict[str, dict]:
    return {
        "diffuse": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.4, 0.3]}},
        "roughconductor": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.1},
        "roughplastic": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1},
        "principled": {"type": "principled", "base_color": {"type": "rgb", "value": [0.8, 0.5, 0.2]},
                       "roughness": 0.3, "metallic": 0.5},
    }


def ensure_inputs(material: str, out: Path, nbrdf: Path) -> tuple[Path, Path]:
    """The NBRDF and the MERL-format table of `material`, made once under `out`."""
    out.mkdir(parents=True, exist_ok=True)
    table = out / f"{material}.sgd.binary"
    if not table.exists():
        cli.run([nbrdf, "synth", "--model", "sgd", "--material", material, "-o", table])
    network = out / f"{material}.nbrdf.json"
    if not network.exists():
        keras = shared_path("data", "reference-nbrdf", "merl", f"{material}.h5")
        if keras.exists():
            from nbrdf_mitsuba import import_keras

            import_keras.convert(keras, network)
        else:
            cli.run([nbrdf, "train", table, "-o", network, "--epochs", "5", "--samples", "200000", "--quiet"])
    return network, table


def is_scalar(variant: str) -> bool:
    return variant.startswith("scalar_")


def candidates(network: Path, table: Path, mode: str) -> dict[str, dict]:
    """BSDFs to time in `mode`; the Rust-backed ones exist in wavefront and scalar mode only,
    the traced ones in the JIT modes only."""
    bsdfs = {}
    if mode == "scalar":
        bsdfs["nbrdf"] = {"type": "nbrdf", "filename": str(network), "backend": "rust"}
        bsdfs["merl"] = {"type": "merl", "filename": str(table), "backend": "rust"}
        bsdfs.update(builtin_bsdfs())
        return bsdfs
    bsdfs["nbrdf"] = {"type": "nbrdf", "filename": str(network), "backend": "jit"}
    bsdfs["nbrdf-opaque"] = {"type": "nbrdf", "filename": str(network), "backend": "jit", "jit_weights": "opaque"}
    bsdfs["merl"] = {"type": "merl", "filename": str(table), "backend": "jit"}
    if mode == "wavefront":
        bsdfs["nbrdf-rust"] = {"type": "nbrdf", "filename": str(network), "backend": "rust"}
        bsdfs["merl-rust"] = {"type": "merl", "filename": str(table), "backend": "rust"}
    bsdfs.update(builtin_bsdfs())
    return bsdfs


def set_mode(mode: str) -> None:
    if mode == "scalar":
        return
    symbolic = mode == "default"
    dr.set_flag(dr.JitFlag.SymbolicLoops, symbolic)
    dr.set_flag(dr.JitFlag.SymbolicCalls, symbolic)


def time_render(scene, spp: int) -> float:
    start = time.perf_counter()
    image = mi.render(scene, spp=spp)
    dr.eval(image)
    sync()
    return time.perf_counter() - start


def bench_mode(mode: str, bsdfs: dict[str, dict], resolution, spp: int, repeats: int) -> dict:
    set_mode(mode)
    scenes = {}
    for name, bsdf in bsdfs.items():
        scenes[name] = mi.load_dict(veach_scene_dict(bsdf, integrator="mis", resolution=resolution, spp=spp))
        time_render(scenes[name], spp)  # compiles and caches the kernels
    seconds = {name: [] for name in bsdfs}
    for _ in bar(range(repeats), desc=f"{mode} mode", unit="round"):
        for name, scene in scenes.items():
            seconds[name].append(time_render(scene, spp))
    rays = resolution[0] * resolution[1] * spp * RAYS_PER_SAMPLE
    return {name: {"mrays_per_s": rays / statistics.median(t) / 1e6, "seconds": statistics.median(t)}
            for name, t in seconds.items()}


def print_table(results: list[dict]) -> None:
    for result in results:
        bsdfs = result["bsdfs"]
        reference = bsdfs["roughconductor"]["mrays_per_s"]
        print(f"\n{result['scene']} scene, {result['variant']}, {result['mode']} mode")
        print(f"{'BSDF':<16}{'Mrays/s':>10}{'vs roughconductor':>20}")
        for name, figures in bsdfs.items():
            print(f"{name:<16}{figures['mrays_per_s']:>10.2f}{figures['mrays_per_s'] / reference:>19.2f}x")


def plot(results: list[dict], path: Path) -> Path:
    """Bar chart of Mrays/s per BSDF, one bar per mode (PNG and PDF), built-ins in grey tones."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    names = list(dict.fromkeys(name for result in results for name in result["bsdfs"]))
    x = np.arange(len(names))
    width = 0.8 / len(results)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.75 * len(names) + 2), 3.8))
    for k, result in enumerate(results):
        values = [result["bsdfs"].get(name, {}).get("mrays_per_s", 0.0) for name in names]
        bars = ax.bar(x + (k - (len(results) - 1) / 2) * width, values, width, label=f"{result['mode']} mode")
        ax.bar_label(bars, labels=[f"{v:.1f}" if v > 0 else "" for v in values], fontsize=6, padding=1)
    ax.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("Mrays/s (higher is better)")
    first = results[0]
    ax.set_title(f"{first['scene']} scene, {first['variant']}, {first['resolution'][0]}x{first['resolution'][1]}, "
                 f"{first['spp']} spp (MIS: 3 rays per sample)", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150)
    fig.savefig(path.with_suffix(".pdf"))
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--variant", default="llvm_ad_rgb",
                        help="an RGB variant: llvm_ad_rgb, cuda_ad_rgb or scalar_rgb (default: %(default)s)")
    parser.add_argument("--modes", default="default,wavefront",
                        help="comma-separated: default, wavefront (JIT variants; a scalar variant runs its one "
                             "mode, scalar)")
    parser.add_argument("--bsdfs", help="comma-separated: time only these BSDFs of the mode's list "
                                        "(nbrdf, nbrdf-opaque, merl, nbrdf-rust, merl-rust, diffuse, "
                                        "roughconductor, roughplastic, principled; default: all)")
    parser.add_argument("--material", default=DEFAULT_MATERIAL)
    parser.add_argument("--width", type=int, default=768)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="small image and few repeats (CI)")
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    parser.add_argument("--out", type=Path, default=default_out("bench"),
                        help="folder of the table and network (default: %(default)s)")
    parser.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf tool (default: %(default)s)")
    parser.add_argument("--plot", type=Path, help="bar chart (PNG, and PDF beside it; default: OUT/rays_per_second.png)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars (for logs)")
    args = parser.parse_args(argv)
    progress.set_enabled(not args.no_progress)
    if args.quick:
        args.width, args.spp, args.repeats = 192, 4, 2
    modes = ["scalar"] if is_scalar(args.variant) else args.modes.split(",")
    for mode in modes:
        if mode not in ("default", "wavefront", "scalar"):
            parser.error(f"unknown mode '{mode}'")
    wanted = args.bsdfs.split(",") if args.bsdfs else None
    if wanted and "roughconductor" not in wanted:
        wanted.append("roughconductor")  # the reference of the ratios

    mi.set_variant(args.variant)
    nbrdf_mitsuba.register()
    try:
        cli.check_cli(args.cli)
        network, table = ensure_inputs(args.material, args.out, args.cli)
    except (MissingDataError, cli.CommandError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    resolution = (args.width, args.width * 2 // 3)
    results = []
    for mode in modes:
        bsdfs = candidates(network, table, mode)
        if wanted:
            unknown = [name for name in wanted if name not in bsdfs]
            if unknown:
                parser.error(f"--bsdfs: {', '.join(unknown)} not in the {mode} mode's list ({', '.join(bsdfs)})")
            bsdfs = {name: bsdfs[name] for name in wanted}
        bsdfs = bench_mode(mode, bsdfs, resolution, args.spp, args.repeats)
        results.append({"scene": "veach", "variant": args.variant, "mode": mode, "resolution": list(resolution),
                        "spp": args.spp, "bsdfs": bsdfs})
    print_table(results)
    chart = plot(results, args.plot or args.out / "rays_per_second.png")
    print(f"\nwrote {chart} and {chart.with_suffix('.pdf')}")
    if args.json:
        payload = results[0] if len(results) == 1 else {"runs": results, **results[0]}
        args.json.write_text(json.dumps(payload, indent=2))
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
