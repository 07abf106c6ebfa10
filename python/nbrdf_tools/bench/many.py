"""Scenes with many distinct materials: load, first-render and later-render times and memory for
1, 16, 64 and 256 distinct neural BRDFs on spheres, beside the same scene with ``roughconductor``
spheres, for each ``jit_weights`` mode of the ``nbrdf`` BSDF (``auto``, the default, ``literal``
and ``opaque``).

    python -m nbrdf_tools bench-many [--counts 1,16,64,256] [--modes auto,literal,opaque,roughconductor]
                                     [--sampling FILE|tabulated|...] [--json FILE] [--quick]

The scene: N unit spheres in a square grid, each with its own material, under a constant
environment and a directional light, ``path`` integrator (``max_depth`` 3), a 256x256 image at
16 spp in ``llvm_ad_rgb``. Every (mode, count) runs in its own process, so that no other
scene's BSDFs enter Mitsuba's symbolic call (it traces every live BSDF instance) and so that
the first render compiles from scratch: each process gets an empty Dr.Jit kernel cache
(``DRJIT_CACHE_DIR``) unless ``--warm-cache``. The runs of the different modes alternate
(count by count, mode by mode, ``--rounds`` times) so that machine load affects them alike; the
table gives each figure's median over the rounds. Times are wall seconds with the CPU seconds of
the process (every thread) beside them; the load average is printed and stored.

The networks: the authors' pretrained networks of the MERL materials (shared data,
``reference-nbrdf/merl``, imported with ``nbrdf_mitsuba.import_keras``) when present, else
networks trained briefly (``nbrdf synth`` + ``nbrdf train``) from a few SGD fits. More networks
than sources are made distinct by shifting the output biases (a tint): every sphere has its own
weights, so none is compiled or cached as another's.

Where the first render's time goes: ``first_compile_s`` (LLVM compiling the kernels, from Dr.Jit's
kernel history), ``first_codegen_s`` (Dr.Jit writing their IR) and ``first_main_thread_cpu_s``
(the rendering thread's CPU seconds: tracing, code generation, compilation and its share of
running the kernels); ``later_codegen_s`` is the code generation of one later render (Mitsuba
retraces the scene every render and Dr.Jit regenerates the IR to find the cached kernel).

Memory per material: ``weights_bytes`` (the float32 parameters), ``sampler_bytes`` (the
tabulated sampler's arrays, where it samples so) and ``rss_per_material``: the growth of the
process's resident memory while the scene loads, divided by N (Python objects, Dr.Jit variables
and the library's handle included).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from nbrdf_tools.common import cli, progress
from nbrdf_tools.common.paths import MissingDataError, default_cli, default_out, shared_path

COUNTS = (1, 16, 64, 256)
MODES = ("auto", "literal", "opaque", "roughconductor")
SOURCES = ("gold-metallic-paint", "blue-metallic-paint", "red-plastic", "nickel", "white-fabric",
           "green-acrylic", "pink-felt", "black-obsidian")


# ---------------------------------------------------------------------------------------------
# Inputs


def _authors_networks(folder: Path) -> list[Path]:
    keras = shared_path("data", "reference-nbrdf", "merl")
    files = sorted(keras.glob("*.h5")) if keras.is_dir() else []
    if not files:
        return []
    from nbrdf_mitsuba import import_keras

    folder.mkdir(parents=True, exist_ok=True)
    made = []
    for h5 in files:
        target = folder / f"{h5.stem}.nbrdf.json"
        if not target.exists():
            import_keras.convert(h5, target)
        made.append(target)
    return made


def _trained_networks(folder: Path, nbrdf: Path, count: int) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    made = []
    for material in SOURCES[:count]:
        table, target = folder / f"{material}.binary", folder / f"{material}.nbrdf.json"
        if not target.exists():
            cli.run([nbrdf, "synth", "--model", "sgd", "--material", material, "-o", table])
            cli.run([nbrdf, "train", table, "-o", target, "--epochs", "1", "--samples", "20000", "--quiet"])
            table.unlink()
        made.append(target)
    return made


def tinted(document: dict, k: int) -> dict:
    """``document`` with output biases shifted by a small tint that differs for every ``k``:
    a distinct network (distinct weights) of almost the same appearance."""
    document = json.loads(json.dumps(document))
    shift = 0.02 * (1 + k // 3)
    bias = document["layers"][-1]["bias"]
    bias[k % len(bias)] += shift
    document["name"] = f"{document.get('name', 'network')}-tint{k}"
    return document


def networks(folder: Path, count: int, nbrdf: Path, few: bool = False) -> list[Path]:
    """``count`` distinct network files under ``folder``: the sources first, then tinted copies."""
    folder.mkdir(parents=True, exist_ok=True)
    sources = [] if few else _authors_networks(folder / "sources")
    if not sources:
        sources = _trained_networks(folder / "sources", nbrdf, 4 if few else len(SOURCES))
    out = list(sources[:count])
    for k in range(len(out), count):
        source = sources[k % len(sources)]
        target = folder / f"{source.name.removesuffix('.nbrdf.json')}-tint{k}.nbrdf.json"
        if not target.exists():
            target.write_text(json.dumps(tinted(json.loads(source.read_text()), k)))
        out.append(target)
    return out


# ---------------------------------------------------------------------------------------------
# One run (in its own process)


def scene_dict(bsdfs: list[dict], width: int, spp: int) -> dict:
    """N unit spheres in a square grid, one BSDF each, seen whole by the camera."""
    import math

    import mitsuba as mi

    side = math.ceil(math.sqrt(len(bsdfs)))
    spacing = 2.2
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 1.5 * spacing * side + 2],
                                                              target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": width, "height": width, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "environment": {"type": "constant", "radiance": {"type": "rgb", "value": 0.3}},
        "sun": {"type": "directional", "direction": [-1, -1, -1], "irradiance": {"type": "rgb", "value": 3.0}},
    }
    for k, bsdf in enumerate(bsdfs):
        i, j = k % side, k // side
        scene[f"sphere{k}"] = {"type": "sphere", "radius": 1.0, "bsdf": bsdf,
                               "center": [(i - (side - 1) / 2) * spacing, (j - (side - 1) / 2) * spacing, 0.0]}
    return scene


def material_dicts(mode: str, files: list[Path], sampling: str | None) -> list[dict]:
    if mode == "roughconductor":
        # Distinct parameters per sphere, as distinct networks have.
        return [{"type": "roughconductor", "distribution": "ggx", "alpha": 0.05 + 0.2 * k / len(files)}
                for k in range(len(files))]
    extra = {"sampling": sampling} if sampling else {}
    return [{"type": "nbrdf", "filename": str(f), "jit_weights": mode, **extra} for f in files]


def _rss() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _timed(action):
    wall, cpu = time.perf_counter(), time.process_time()
    result = action()
    return result, time.perf_counter() - wall, time.process_time() - cpu


def run_one(mode: str, files: list[Path], width: int, spp: int, renders: int, sampling: str | None,
            variant: str) -> dict:
    """Loads the scene, renders it ``renders + 1`` times; the figures of one run."""
    import nbrdf_mitsuba

    import drjit as dr
    import mitsuba as mi
    import numpy as np

    mi.set_variant(variant)
    nbrdf_mitsuba.register()
    bsdfs = material_dicts(mode, files, sampling)
    scene_description = scene_dict(bsdfs, width, spp)
    rss = _rss()
    scene, load_wall, load_cpu = _timed(lambda: mi.load_dict(scene_description))
    rss_per_material = (_rss() - rss) / len(files)

    def render(seed):
        image = mi.render(scene, spp=spp, seed=seed)
        dr.eval(image)
        dr.sync_thread()
        return image

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()  # drop the loading's kernels
    main_thread = time.thread_time()
    image, first_wall, first_cpu = _timed(lambda: render(0))
    first_main_cpu = time.thread_time() - main_thread
    first_kernels = _kernel_times(dr.kernel_history())
    later = [_timed(lambda s=seed: render(s))[1:] for seed in range(1, renders + 1)]
    later_kernels = _kernel_times(dr.kernel_history())
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    figures = {"mode": mode, "count": len(files), "load_s": load_wall, "load_cpu_s": load_cpu,
               "first_render_s": first_wall, "first_render_cpu_s": first_cpu,
               "first_main_thread_cpu_s": first_main_cpu, "first_codegen_s": first_kernels["codegen"],
               "first_compile_s": first_kernels["backend"],
               "later_codegen_s": later_kernels["codegen"] / max(renders, 1),
               "later_render_s": statistics.median(w for w, _ in later),
               "later_render_cpu_s": statistics.median(c for _, c in later),
               "rss_per_material": rss_per_material, "mean": float(np.mean(np.array(image)))}
    if mode != "roughconductor":
        figures.update(_material_memory(scene))
    return figures


def _kernel_times(history: list) -> dict:
    """Seconds that Dr.Jit spent generating IR (``codegen``) and that LLVM spent compiling it
    (``backend``: 0 for kernels found in the cache) over the launches in ``history``. Both run
    on the rendering thread, so on an idle machine they are CPU seconds of the first render;
    the rest of it is tracing (Python, Mitsuba) and running the kernels."""
    return {key: 1e-3 * sum(entry.get(f"{key}_time", 0.0) for entry in history)
            for key in ("codegen", "backend")}


def _material_memory(scene) -> dict:
    """Bytes of one material's data as the plugin holds it (the first sphere's)."""
    import drjit as dr

    bsdf = scene.shapes()[0].bsdf()
    figures = {"weights_bytes": 4 * bsdf._traced.parameter_count, "kernel": bsdf._traced.kernel()}
    table = bsdf._backend.table
    if table is not None:
        figures["sampler_bytes"] = 4 * sum(dr.width(a) for a in (table.mass, table.alias_probability, table.alias))
    return figures


# ---------------------------------------------------------------------------------------------
# The driver


def child(args) -> int:
    files = [Path(line) for line in Path(args.files).read_text().splitlines()]
    result = run_one(args.child, files, args.width, args.spp, args.renders, args.sampling, args.variant)
    print("RESULT " + json.dumps(result), flush=True)
    return 0


def spawn(mode: str, files: list[Path], args, folder: Path) -> dict:
    listing = folder / f"files-{len(files)}.txt"
    listing.write_text("\n".join(map(str, files)))
    command = [sys.executable, "-m", "nbrdf_tools.bench.many", "--child", mode, "--files", str(listing),
               "--width", str(args.width), "--spp", str(args.spp), "--renders", str(args.renders),
               "--variant", args.variant]
    if args.sampling:
        command += ["--sampling", args.sampling]
    env = dict(os.environ)
    with tempfile.TemporaryDirectory(prefix="nbrdf-bench-many-cache-") as cache:
        if not args.warm_cache:
            env["DRJIT_CACHE_DIR"] = cache
        done = subprocess.run(command, capture_output=True, text=True, env=env)
    lines = [line for line in done.stdout.splitlines() if line.startswith("RESULT ")]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"bench_many: {mode} with {len(files)} materials failed "
                           f"(exit {done.returncode}):\n{done.stderr[-3000:]}")
    return json.loads(lines[-1].removeprefix("RESULT "))


def summarise(runs: list[dict]) -> list[dict]:
    """The median of each figure over the rounds, per (count, mode), with the ratios the issue
    asks for: first render over one network's (same mode), later render over the fastest mode's
    at that count, load per material."""
    keys = sorted({(r["count"], r["mode"]) for r in runs}, key=lambda k: (k[0], MODES.index(k[1])))
    rows = []
    for count, mode in keys:
        group = [r for r in runs if r["count"] == count and r["mode"] == mode]
        row = {k: v for k, v in group[0].items() if not isinstance(v, float)}
        for key in group[0]:
            if isinstance(group[0][key], float):
                row[key] = statistics.median(r[key] for r in group)
        row["rounds"] = len(group)
        row["load_per_material_ms"] = 1e3 * row["load_s"] / count
        rows.append(row)
    for row in rows:
        nbrdf = [r for r in rows if r["count"] == row["count"] and r["mode"] != "roughconductor"]
        if nbrdf and row["mode"] != "roughconductor":
            fastest = min(r["later_render_cpu_s"] for r in nbrdf)
            row["later_vs_fastest_mode"] = row["later_render_cpu_s"] / fastest
        one = [r for r in rows if r["count"] == 1 and r["mode"] == row["mode"]]
        if one:
            row["first_vs_one_network"] = row["first_render_s"] / one[0]["first_render_s"]
            # The figure to compare on a loaded machine, where wall time is mostly waiting.
            row["first_cpu_vs_one_network"] = row["first_render_cpu_s"] / one[0]["first_render_cpu_s"]
    return rows


def print_table(rows: list[dict]) -> None:
    print(f"\n{'N':>4} {'mode':<15}{'load s':>14}{'ms/mat':>8}{'first s':>15}{'compile':>8}{'later s':>15}"
          f"{'later/best':>11}{'first/1':>9}{'(CPU)':>7}{'RSS/mat':>9}")
    for r in rows:
        print(f"{r['count']:>4} {r['mode']:<15}{r['load_s']:>7.2f} ({r['load_cpu_s']:>4.2f})"
              f"{r['load_per_material_ms']:>8.1f}"
              f"{r['first_render_s']:>7.2f} ({r['first_render_cpu_s']:>5.2f}){r['first_compile_s']:>8.2f}"
              f"{r['later_render_s']:>7.3f} ({r['later_render_cpu_s']:>5.3f})"
              f"{r.get('later_vs_fastest_mode', float('nan')):>11.2f}{r.get('first_vs_one_network', float('nan')):>9.2f}"
              f"{r.get('first_cpu_vs_one_network', float('nan')):>7.2f}"
              f"{r['rss_per_material'] / 1e3:>7.0f}kB")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--counts", default=",".join(map(str, COUNTS)), help="numbers of distinct materials")
    parser.add_argument("--modes", default=",".join(MODES),
                        help="nbrdf jit_weights modes and/or roughconductor (default: %(default)s)")
    parser.add_argument("--sampling", help="the nbrdf BSDFs' sampling (default: each file's; e.g. tabulated, "
                                           "whose table is built from the network at load time)")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--renders", type=int, default=3, help="later renders per run (their median is kept)")
    parser.add_argument("--rounds", type=int, default=1, help="runs of each (count, mode), interleaved")
    parser.add_argument("--warm-cache", action="store_true",
                        help="keep Dr.Jit's kernel cache (default: an empty one per run, a cold first render)")
    parser.add_argument("--quick", action="store_true",
                        help="CI size: counts 1,4, 64x64 at 4 spp, one later render, briefly trained networks")
    parser.add_argument("--json", type=Path, help="write the runs and the table as JSON")
    parser.add_argument("--out", type=Path, default=default_out("bench-many"),
                        help="folder of the networks (default: %(default)s)")
    parser.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf tool (default: %(default)s)")
    parser.add_argument("--no-progress", action="store_true")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--files", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        return child(args)
    progress.set_enabled(not args.no_progress)
    if args.quick:
        args.counts, args.width, args.spp, args.renders = "1,4", 64, 4, 1
    counts = [int(c) for c in args.counts.split(",")]
    modes = args.modes.split(",")
    for mode in modes:
        if mode not in MODES:
            parser.error(f"unknown mode '{mode}' (one of {', '.join(MODES)})")
    try:
        files = networks(args.out / ("quick" if args.quick else "networks"), max(counts), args.cli, few=args.quick)
    except (MissingDataError, cli.CommandError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    load_average = os.getloadavg()
    runs = []
    jobs = [(count, mode) for _ in range(args.rounds) for count in counts for mode in modes]
    for count, mode in progress.bar(jobs, desc="runs", unit="run"):
        runs.append(spawn(mode, files[:count], args, args.out))
    rows = summarise(runs)
    print(f"load average before: {load_average[0]:.2f}, after: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)")
    print_table(rows)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"variant": args.variant, "width": args.width, "spp": args.spp,
                                         "cold_cache": not args.warm_cache, "sampling": args.sampling,
                                         "load_average": [load_average[0], os.getloadavg()[0]],
                                         "cpus": os.cpu_count(), "rows": rows, "runs": runs}, indent=2))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
