"""Rays per second of our BSDFs against Mitsuba's built-ins, in the same scene, variant and mode:
the paper's speed table, with the memory each material needs.

BSDFs: ``nbrdf`` (the network file's default sampling, literal and ``-opaque`` weights), ``nbrdf``
with each sampling strategy (``nbrdf-cosine``, ``nbrdf-phong``, ``nbrdf-two_lobe``,
``nbrdf-tabulated``), ``merl`` (the
MERL-format table), ``measured`` (Mitsuba's BSDF of an RGL measurement, ``--rgl``; default the
shared ``paper_white_rgb.bsdf``, skipped with a note when absent), Mitsuba's ``roughconductor``,
``roughplastic``, ``principled`` and ``diffuse``; in wavefront mode also the ``rust`` backends.
Every one is printed and written with its Mrays/s, its ratios to ``measured`` and to
``roughconductor``, and ``memory_bytes``: the bytes of the material's data (a network's float32
parameters, the MERL table and the RGL file as stored, a built-in's traversable parameters as
float32); where the BSDF samples with the half-vector table built at load time (``tabulated``,
the stored default of most networks), ``sampler_bytes`` the table's float32 arrays beside it.

Every BSDF under test is put on the four plates of the Veach scene (direct illumination with MIS:
per sample one camera ray, one shadow ray and one BSDF ray), rendered once to compile the kernels,
then timed over several renders; runs of the different BSDFs alternate within one process so that
machine load affects them alike. Modes of the JIT variants: ``default`` (Dr.Jit's symbolic loops and
calls, Mitsuba's megakernel) and ``wavefront`` (symbolic loops and calls off, which the Rust backend
needs). A scalar variant (``--variant scalar_rgb``) has one mode, ``scalar``, and the Rust backend
alone, which Mitsuba calls once per direction through Python (docs/mitsuba.md, "Performance").

    python -m nbrdf_tools bench-rays [--quick] [--json FILE] [--modes default,wavefront] [--rgl PATH.bsdf]
    python -m nbrdf_tools bench-rays --variant scalar_rgb --bsdfs nbrdf,roughconductor --width 128 --spp 4

The network is trained by ``nbrdf train`` (briefly: speed, not accuracy, is measured) unless the
authors' Keras network of the material is in the shared data; ``nbrdf fit-phong --lobes 2``
stores its two sampling lobes and the lowest-variance strategy as its default (``nbrdf``'s sampling,
usually ``tabulated``; ``nbrdf-phong`` samples the first lobe).
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

from nbrdf_tools.common import cli, progress
from nbrdf_tools.common import network as nbrdf_network
from nbrdf_tools.common.paths import MissingDataError, default_cli, default_out, shared_path
from nbrdf_tools.common.progress import bar
from nbrdf_tools.common.render import sync
from nbrdf_tools.common.scenes.veach import veach_scene_dict

RAYS_PER_SAMPLE = 3  # camera ray, emitter (shadow) ray, BSDF ray of the MIS direct integrator
DEFAULT_MATERIAL = "gold-metallic-paint"
DEFAULT_RGL = "paper_white_rgb"
NBRDF_STRATEGIES = ("cosine", "phong", "two_lobe", "tabulated")
# The ratios' denominators: Mitsuba's sampling of measured data, and its analytic microfacet BSDF.
REFERENCES = ("measured", "roughconductor")


def builtin_bsdfs() -> dict[str, dict]:
    return {
        "roughconductor": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.1},
        "roughplastic": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1},
        "principled": {"type": "principled", "base_color": {"type": "rgb", "value": [0.8, 0.5, 0.2]},
                       "roughness": 0.3, "metallic": 0.5},
        "diffuse": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.4, 0.3]}},
    }


def ensure_inputs(material: str, out: Path, nbrdf: Path) -> tuple[Path, Path]:
    """The NBRDF (with two fitted sampling lobes) and the MERL-format table of `material`, made
    once under `out`."""
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
    if "second_lobe" not in nbrdf_network.sampling_of(network):
        cli.run([nbrdf, "fit-phong", network, "--lobes", "2"])
    return network, table


def is_scalar(variant: str) -> bool:
    return variant.startswith("scalar_")


def rgl_measurement(option: Path | None) -> tuple[Path | None, str | None]:
    """The RGL file of ``measured`` and, when there is none, the note saying what is missing.
    A path given with ``--rgl`` must exist (MissingDataError); the shared default may not."""
    if option is not None:
        if not option.is_file():
            raise MissingDataError(f"RGL measurement {option} (--rgl) is missing")
        return option, None
    default = shared_path("data", "rgl", f"{DEFAULT_RGL}.bsdf")
    if default.is_file():
        return default, None
    return None, (f"measured skipped: {default} is missing (pass --rgl PATH.bsdf, or set NBRDF_SHARED to the "
                  "shared data folder that holds data/rgl)")


def candidates(network: Path, table: Path, mode: str, measured: Path | None = None) -> dict[str, dict]:
    """BSDFs to time in `mode`; the Rust-backed ones exist in wavefront and scalar mode only,
    the traced ones (and Mitsuba's `measured`) in the JIT modes only."""
    bsdfs = {}
    if mode == "scalar":
        bsdfs["nbrdf"] = {"type": "nbrdf", "filename": str(network), "backend": "rust"}
        bsdfs["merl"] = {"type": "merl", "filename": str(table), "backend": "rust"}
        bsdfs.update(builtin_bsdfs())
        return bsdfs
    # The table times the literal kernels by name: with more than jit.AUTO_LITERAL_MAX networks
    # alive (this process holds six) the default "auto" would pick the shared kernel instead.
    bsdfs["nbrdf"] = {"type": "nbrdf", "filename": str(network), "backend": "jit", "jit_weights": "literal"}
    bsdfs["nbrdf-opaque"] = {"type": "nbrdf", "filename": str(network), "backend": "jit", "jit_weights": "opaque"}
    for strategy in NBRDF_STRATEGIES:
        bsdfs[f"nbrdf-{strategy}"] = {"type": "nbrdf", "filename": str(network), "backend": "jit",
                                      "jit_weights": "literal", "sampling": strategy}
    bsdfs["merl"] = {"type": "merl", "filename": str(table), "backend": "jit"}
    if measured is not None:
        bsdfs["measured"] = {"type": "measured", "filename": str(measured)}
    if mode == "wavefront":
        bsdfs["nbrdf-rust"] = {"type": "nbrdf", "filename": str(network), "backend": "rust"}
        bsdfs["merl-rust"] = {"type": "merl", "filename": str(table), "backend": "rust"}
    bsdfs.update(builtin_bsdfs())
    return bsdfs


def network_parameter_count(network: Path) -> int:
    return nbrdf_network.parameter_count(network)


def traversed_float_count(bsdf: dict) -> int:
    """Floats among the parameters Mitsuba's ``traverse`` exposes for a BSDF (its whole state
    for the built-ins: colours count three)."""
    count = 0
    for _, value in mi.traverse(mi.load_dict(bsdf)).items():
        if dr.is_array_v(value) and dr.is_arithmetic_v(value):
            count += dr.width(value) * (dr.size_v(value) if dr.depth_v(value) > 1 else 1)
    return count


def memory(bsdf: dict) -> dict:
    """``memory_bytes`` of a material (and what it counts) and ``file_bytes`` where it has a file:
    a network's float32 parameters, a MERL table or an RGL measurement as stored, a built-in's
    traversable parameters as float32."""
    if bsdf["type"] == "nbrdf":
        path = Path(bsdf["filename"])
        count = network_parameter_count(path)
        return {"memory_bytes": 4 * count, "memory": f"{count} float32 parameters",
                "file_bytes": path.stat().st_size}
    if bsdf["type"] in ("merl", "measured"):
        size = Path(bsdf["filename"]).stat().st_size
        what = "MERL table (float64)" if bsdf["type"] == "merl" else "RGL file"
        return {"memory_bytes": size, "memory": what, "file_bytes": size}
    count = traversed_float_count(bsdf)
    return {"memory_bytes": 4 * count, "memory": f"{count} float32 parameters"}


def sampler_memory(bsdf: dict) -> dict:
    """``sampler_bytes`` of a BSDF that samples with the tabulated sampler: the float32 arrays of
    its traced table (masses and alias tables), built when the material loads and not stored in
    its file; empty for every other BSDF."""
    if bsdf["type"] not in ("nbrdf", "merl"):
        return {}
    table = mi.load_dict(bsdf)._backend.table
    if table is None:
        return {}
    count = sum(dr.width(a) for a in (table.mass, table.alias_probability, table.alias))
    return {"sampler_bytes": 4 * count, "sampler": f"half-vector table, {count} 32-bit values (built at load)"}


def add_ratios(bsdfs: dict) -> None:
    """``ratio_vs_NAME`` (Mrays/s over that of NAME) for each of :data:`REFERENCES` timed here."""
    for reference in REFERENCES:
        if reference in bsdfs:
            base = bsdfs[reference]["mrays_per_s"]
            for figures in bsdfs.values():
                figures[f"ratio_vs_{reference}"] = figures["mrays_per_s"] / base


def human_bytes(n: int) -> str:
    for unit, scale in (("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} B"


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
        print(f"\n{result['scene']} scene, {result['variant']}, {result['mode']} mode")
        print(f"{'BSDF':<18}{'Mrays/s':>10}{'vs measured':>13}{'vs roughconductor':>19}{'memory':>11}"
              f"{'+ sampler':>11}")
        for name, figures in bsdfs.items():
            ratios = [f"{figures[f'ratio_vs_{r}']:.2f}x" if f"ratio_vs_{r}" in figures else "-" for r in REFERENCES]
            sampler = human_bytes(figures["sampler_bytes"]) if "sampler_bytes" in figures else "-"
            print(f"{name:<18}{figures['mrays_per_s']:>10.2f}{ratios[0]:>13}{ratios[1]:>19}"
                  f"{human_bytes(figures['memory_bytes']):>11}{sampler:>11}")


def plot(results: list[dict], path: Path) -> Path:
    """Bar chart of Mrays/s per BSDF, one bar per mode (PNG and PDF); each BSDF labelled with its
    memory."""
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
    sizes = {name: figures["memory_bytes"] for result in results for name, figures in result["bsdfs"].items()
             if "memory_bytes" in figures}
    labels = [f"{name}\n{human_bytes(sizes[name])}" if name in sizes else name for name in names]
    ax.set_xticks(x, labels, rotation=30, ha="right", fontsize=8)
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
                                        "(nbrdf, nbrdf-opaque, nbrdf-cosine, nbrdf-phong, nbrdf-two_lobe, nbrdf-tabulated, "
                                        "merl, measured, nbrdf-rust, merl-rust, diffuse, "
                                        "roughconductor, roughplastic, principled; default: all)")
    parser.add_argument("--material", default=DEFAULT_MATERIAL,
                        help="MERL material of the nbrdf and merl BSDFs (default: %(default)s)")
    parser.add_argument("--rgl", type=Path,
                        help=f"RGL measurement (.bsdf) of the measured BSDF (default: the shared {DEFAULT_RGL}.bsdf "
                             "when present, else measured is skipped)")
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
        measured, note = rgl_measurement(args.rgl)
        network, table = ensure_inputs(args.material, args.out, args.cli)
    except (MissingDataError, cli.CommandError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if note:
        print(f"note: {note}")
    resolution = (args.width, args.width * 2 // 3)
    results = []
    for mode in modes:
        tested = candidates(network, table, mode, measured)
        if wanted:
            unknown = [name for name in wanted if name not in tested]
            if unknown:
                parser.error(f"--bsdfs: {', '.join(unknown)} not in the {mode} mode's list ({', '.join(tested)})")
            tested = {name: tested[name] for name in wanted}
        bsdfs = bench_mode(mode, tested, resolution, args.spp, args.repeats)
        for name, bsdf in tested.items():
            bsdfs[name].update(memory(bsdf))
            bsdfs[name].update(sampler_memory(bsdf))
        add_ratios(bsdfs)
        results.append({"scene": "veach", "variant": args.variant, "mode": mode, "resolution": list(resolution),
                        "spp": args.spp, "material": args.material,
                        "measured": str(measured) if measured else None, "notes": [note] if note else [],
                        "bsdfs": bsdfs})
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
