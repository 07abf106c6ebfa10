"""Convergence of the sampling strategies: error against samples per pixel and against render time.

For each material, the scene is rendered with every sampling strategy at 1, 2, 4, ... spp and
each render is timed (wall clock, after the kernels are compiled; renders of up to 32 spp are
repeated with the same seed and the fastest time kept) and compared with a converged
reference; a CSV, a JSON file, EXR renders, PNG plots (log-log, one curve per strategy) and a
Markdown summary land in the output folder.

Strategies (docs/design.md section 6): ``uniform``, ``cosine``, ``phong-fit`` and ``two-lobe-fit``
sample our NBRDF (the ``nbrdf`` BSDF, sampling ``uniform``, ``cosine``, ``phong``, ``two_lobe``) by
the uniform hemisphere, the cosine lobe, the best single Blinn-Phong lobe (``nbrdf fit-phong
--lobes 1``) and the two-lobe mixture (``--lobes 2``, stored in the network file);
``phong-predicted`` samples the NBRDF through the lobe that the latent-space predictor gives
(``--ae AE.json --predictor P.json``, from ``nbrdf ae train`` and ``nbrdf predictor train``;
skipped with a note without them); ``tabulated`` samples the NBRDF's half-vector table (built
when the plugin loads it); ``default`` (only when named in ``--strategies``) loads the NBRDF with no
``sampling`` at all, i.e. with the strategy that ``nbrdf fit-phong`` stored as the file's
``sampling.default`` (named in the JSON's ``default_sampling``); ``measured`` is Mitsuba's own ``measured`` BSDF with its own
sampling (RGL materials only; it samples the measurement with its data-driven warp).

Several seeds (``--seeds``) handle the heavy-tailed noise of single renders: the equal-time
figures (``equal_time`` in the JSON, the summary's tables) are the median over seeds of the RMSE
(``rmse``), beside the root of the mean squared error over seeds (``rmse_pooled``); for RGL
materials also each strategy's RMSE over ``measured``'s at the same time (``vs_measured``) and
the best NBRDF strategy (``best_nbrdf``, ``best_vs_measured``).

Beside ``measured``, the Veach scene is also rendered, timed only, with ``diffuse`` plates (a
BSDF that costs next to nothing; ``timings`` in the JSON): its render time is the scene's share
of every render, so it bounds what any BSDF can gain on ``measured`` at equal time. The summary
(``cost_floor``) gives, at the highest common spp, each strategy's RMSE and time over
measured's and that bound (per-sample ratio x sqrt(floor time / measured's time)).

References and ground truths (cached under ``OUT/references`` with JSON sidecars, re-rendered when
any input changes; see ground_truth.py), all with multiple importance sampling (emitter + BSDF
samples: the same integral, much less noise) at ``--gt-spp``:

* the ground truth: the tabulated material through the ``merl`` BSDF (MERL materials), or the
  measurement through Mitsuba's ``measured`` BSDF (RGL materials);
* the converged NBRDF: our network at the same sample count, with the same random numbers.

The sampling error of a strategy is measured against the converged render of the *same* BSDF
(fields ``mae``, ``rmse``, ``relmse``, ``mape``, ``psnr_peak1``; see nbrdf_tools.metrics): the
NBRDF for ``uniform``/``cosine``/``phong-*``, the measurement for ``measured``. The
representation error (NBRDF against ground truth at ``--gt-spp``) is reported separately, with
the same metrics plus ``ssim`` (scikit-image) and ``flip_hdr`` (NVIDIA's HDR-FLIP) over the whole
image, and the total error of every render against the ground truth is in the
``*_vs_ground_truth`` fields.

In the Veach scene the errors are measured on the plates only (the floor and wall are diffuse);
in the kitchen on the whole image. The kitchen replaces several materials at once, and a strategy
there samples every replaced material alike (skipped with a note when one of them lacks what it
samples with); ``measured`` (RGL only) and ``phong-predicted`` are skipped there with a note. Its
summary gives the stored defaults as counts over the materials (``default_sampling``, per
material in ``default_samplings``).

    python -m nbrdf_tools.convergence --scene veach [--materials a,b] [--rgl x,PATH.bsdf] [--integrator bsdf|mis]
        [--strategies a,b] [--seeds N]
    python -m nbrdf_tools.convergence --scene kitchen [--kitchen PATH] [--strategies a,b] [--seeds N]
    python -m nbrdf_tools.convergence --scene veach --quick --json out/convergence.json

MERL materials need nothing but the CLI (tables are synthesised from the embedded fits and the
networks trained); RGL materials need their ``.bsdf`` measurement (a path, or a name in the shared
data; the default RGL pair is left out with a note when the shared data is absent), the kitchen
its scene. What is missing is reported before any work starts. Everything, caches included,
goes under ``--out`` when it is given.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import math
import sys
import time
from pathlib import Path

import nbrdf_mitsuba  # first: finds a libLLVM for Dr.Jit before Mitsuba starts its JIT
import mitsuba as mi
import numpy as np

from nbrdf_tools import cli, metrics, progress
from nbrdf_tools.ground_truth import RenderCache, file_hash
from nbrdf_tools.materials import VEACH_MERL, VEACH_RGL, Artefacts, Material
from nbrdf_tools.paths import SCENES, MissingDataError, default_cli, default_out, shared_path
from nbrdf_tools.progress import bar, log
from nbrdf_tools.render import render_passes, timed_render, warm_up, write_exr, write_png
STRATEGIES = ("uniform", "cosine", "phong-fit", "two-lobe-fit", "phong-predicted", "tabulated", "default", "measured")
# None: the BSDF without a ``sampling`` parameter, i.e. the file's ``sampling.default``.
NBRDF_SAMPLING = {"uniform": "uniform", "cosine": "cosine", "phong-fit": "phong", "two-lobe-fit": "two_lobe",
                  "phong-predicted": "phong", "tabulated": "tabulated", "default": None}
#: What ``--strategies`` renders unless told: ``default`` is one of the others under another
#: name (the one the file names), so it is rendered only on request.
DEFAULT_STRATEGIES = tuple(s for s in STRATEGIES if s != "default")
#: The plates' BSDF of the cost floor (timed beside ``measured``): one that costs next to nothing,
#: so its render time is the scene's share of every render.
COST_FLOOR_BSDF = "diffuse"
REFERENCE_SEED = 1_000_000  # references use seeds from here on; test renders stay far below
QUICK_TRAIN_ARGS = ["--samples", "40000", "--epochs", "3", "--min-epochs", "1"]


# ---------------------------------------------------------------------------------------------
# Scenes


class VeachSetup:
    name = "veach"

    def __init__(self, args):
        from nbrdf_tools.scenes.veach import VEACH_XML

        self.resolution = (args.width, args.height or round(args.width * 2 / 3))
        self.integrator = args.integrator
        self.xml = VEACH_XML

    def load(self, bsdf: dict, integrator: str | None = None):
        from nbrdf_tools.scenes.veach import load_veach_xml

        return load_veach_xml(bsdf, integrator=integrator or self.integrator, resolution=self.resolution)

    def mask(self, scene):
        from nbrdf_tools.scenes.veach import plate_mask

        return plate_mask(scene)

    def description(self, bsdf: dict, integrator: str) -> dict:
        return {"scene": "veach", "xml": file_hash(self.xml), "plates": bsdf, "integrator": integrator,
                "resolution": list(self.resolution)}


class KitchenSetup:
    name = "kitchen"

    def __init__(self, args):
        from nbrdf_tools.scenes import kitchen

        self.module = kitchen
        self.path = kitchen.kitchen_path(args.kitchen)
        if not self.path.is_file():
            raise MissingDataError(f"kitchen scene {self.path} not found (pass --kitchen PATH, set NBRDF_KITCHEN, "
                                   "or set NBRDF_SHARED to the shared data folder that holds scenes/kitchen)")
        self.description_file = Path(args.kitchen_materials)
        self.overrides = kitchen.load_description(self.description_file)
        evaluation = self.overrides.get("evaluation", {})
        width = args.width or evaluation.get("resx", 320)
        self.resolution = (width, args.height or round(width * 9 / 16))
        self.max_depth = args.max_depth or evaluation.get("max_depth", 8)

    def load(self, bsdfs: dict[str, dict]):
        return self.module.load_kitchen(bsdfs, scene=self.path, resx=self.resolution[0], resy=self.resolution[1],
                                        max_depth=self.max_depth, spp=1)

    def description(self, bsdfs: dict[str, dict]) -> dict:
        return {"scene": "kitchen", "xml": file_hash(self.path), "overrides": bsdfs, "integrator": "path",
                "max_depth": self.max_depth, "resolution": list(self.resolution)}

    def inputs(self) -> list[Path]:
        return [self.path, self.description_file]


# ---------------------------------------------------------------------------------------------
# Measurements


def spp_levels(max_spp: int) -> list[int]:
    levels, spp = [], 1
    while spp <= max_spp:
        levels.append(spp)
        spp *= 2
    return levels


def bsdf_files(bsdf) -> list[Path]:
    """The data files a BSDF dict (or dict of them) reads."""
    if isinstance(bsdf, dict) and "type" in bsdf:
        return [Path(bsdf["filename"])] if "filename" in bsdf else []
    files = []
    for value in (bsdf.values() if isinstance(bsdf, dict) else bsdf):
        files += bsdf_files(value)
    return sorted(set(files))


def rmse_at_time(points: list[tuple[float, float]], seconds: float) -> float:
    """RMSE at a render time, interpolated log-log between measured (seconds, rmse) points;
    beyond them extrapolated with the Monte Carlo rate RMSE ~ t^(-1/2)."""
    points = sorted(points)
    ts = np.log([p[0] for p in points])
    es = np.log([p[1] for p in points])
    t = math.log(seconds)
    if t <= ts[0]:
        return float(math.exp(es[0] - 0.5 * (t - ts[0])))
    if t >= ts[-1]:
        return float(math.exp(es[-1] - 0.5 * (t - ts[-1])))
    return float(math.exp(np.interp(t, ts, es)))


def render_seed(level_index: int, scene_index: int, seed_index: int) -> int:
    """The seed of one render of a series: distinct per spp level, scene and repetition (seed
    index 0 keeps the random numbers of single-seed runs)."""
    return 1000 * (level_index + 1) + scene_index + 100_000 * seed_index


def fastest_render(scene, spp: int, seed: int) -> tuple[np.ndarray, float]:
    """(image, seconds): short renders are timed again (same seed, same image) and the fastest
    run kept, since other processes on the machine disturb short timings the most."""
    image, seconds = timed_render(scene, spp, seed=seed)
    for _ in range(timing_repeats(spp) - 1):
        seconds = min(seconds, timed_render(scene, spp, seed=seed)[1])
    return image, seconds


def measure(strategies: dict, levels: list[int], mask, ground_truth, label: str, save_dir: Path | None,
            save_spp: set[int], seeds: int = 1, timing_only: dict | None = None,
            timings: list[dict] | None = None) -> list[dict]:
    """Renders every strategy at every spp level, ``seeds`` times with independent random numbers
    (interleaved, so that machine load hits them alike), and measures each against its reference
    and against the ground truth. Rows carry the seed's index (``seed``). The scenes of
    ``timing_only`` (name: scene) are rendered in the same interleaved order and only timed, into
    ``timings`` (rows of strategy, spp, seed and seconds)."""
    rows = []
    timing_only = timing_only or {}
    for entry in strategies.values():
        entry["warm_up_seconds"] = warm_up(entry["scene"])
    for scene in timing_only.values():
        warm_up(scene)
    total = len(levels) * (len(strategies) + len(timing_only)) * seeds
    with bar(total=total, desc=f"{label}: renders", unit="render", leave=False) as renders:
        for level_index, spp in enumerate(levels):
            for seed_index, (strategy_index, (name, entry)) in itertools.product(range(seeds),
                                                                                 enumerate(strategies.items())):
                image, seconds = fastest_render(entry["scene"], spp,
                                                render_seed(level_index, strategy_index, seed_index))
                row = {"strategy": name, "spp": spp, "seed": seed_index, "seconds": seconds,
                       **metrics.render_metrics(entry["reference"], image, mask),
                       "nonfinite": metrics.nonfinite_count(image)}
                for key, value in metrics.render_metrics(ground_truth, image, mask).items():
                    row[f"{key}_vs_ground_truth"] = value
                row["reference"] = entry["reference_name"]
                rows.append(row)
                if save_dir is not None and spp in save_spp and seed_index == 0:
                    write_exr(save_dir / f"{name}-{spp:04d}spp.exr", image)
                renders.update()
            for seed_index, (scene_index, (name, scene)) in itertools.product(range(seeds),
                                                                             enumerate(timing_only.items())):
                seed = render_seed(level_index, len(strategies) + scene_index, seed_index)
                _, seconds = fastest_render(scene, spp, seed)
                timings.append({"strategy": name, "spp": spp, "seed": seed_index, "seconds": seconds})
                renders.update()
    return rows


def representation_metrics(ground_truth: np.ndarray, image: np.ndarray, mask=None) -> dict:
    """The metrics of a converged render against the ground truth: the per-render ones (over the
    masked pixels), ``relative_rmse``, and ``ssim`` and ``flip_hdr`` over the whole image."""
    return {**metrics.render_metrics(ground_truth, image, mask),
            "relative_rmse": metrics.relative_rmse(ground_truth, image, mask),
            "ssim": metrics.ssim(ground_truth, image), "flip_hdr": metrics.flip_hdr(ground_truth, image)}


def material_specs(args) -> list[str]:
    """The Veach materials: MERL names, then RGL ones as ``rgl:NAME`` or ``.bsdf`` paths."""
    rgl = [m if m.endswith(".bsdf") else f"rgl:{m}" for m in (args.rgl or "").split(",") if m]
    return [m for m in args.materials.split(",") if m] + rgl


def timing_repeats(spp: int) -> int:
    return 3 if spp <= 8 else 2 if spp <= 32 else 1


def series(rows: list[dict], strategy: str, metric: str = "rmse") -> dict[str, np.ndarray] | None:
    """A strategy's curve over its seeds: per spp level the median time and the median, lowest
    and highest error and the root mean square over seeds (``pooled``; for ``rmse`` the RMSE of
    all seeds' pixels together; arrays in spp order), or None when the strategy has no rows."""
    levels = sorted({r["spp"] for r in rows if r["strategy"] == strategy})
    if not levels:
        return None
    per_level = [[r for r in rows if r["strategy"] == strategy and r["spp"] == spp] for spp in levels]
    errors = [np.array([r[metric] for r in level]) for level in per_level]
    return {"spp": np.array(levels), "seconds": np.array([np.median([r["seconds"] for r in level])
                                                         for level in per_level]),
            "median": np.array([np.median(e) for e in errors]), "low": np.array([e.min() for e in errors]),
            "pooled": np.array([np.sqrt(np.mean(e ** 2)) for e in errors]),
            "high": np.array([e.max() for e in errors]), "seeds": min(len(level) for level in per_level)}


def equal_time_summary(rows: list[dict]) -> dict:
    """RMSE of every strategy at the longest render time that all strategies reached: the median
    over seeds (``rmse``) and the root mean square over seeds (``rmse_pooled``); with ``measured``
    among them, each strategy's median RMSE over measured's (``vs_measured``) and the best NBRDF
    strategy's; with ``phong-fit``, each other strategy's over the single lobe's (``vs_phong_fit``)."""
    curves = {strategy: series(rows, strategy) for strategy in dict.fromkeys(r["strategy"] for r in rows)}
    budget = min(float(curve["seconds"].max()) for curve in curves.values())
    summary = {"seconds": budget, "statistic": "median over seeds",
               "seeds": min(int(curve["seeds"]) for curve in curves.values()),
               "rmse": {s: rmse_at_time(list(zip(c["seconds"], c["median"])), budget) for s, c in curves.items()},
               "rmse_pooled": {s: rmse_at_time(list(zip(c["seconds"], c["pooled"])), budget)
                               for s, c in curves.items()}}
    if "measured" in summary["rmse"]:
        measured = summary["rmse"]["measured"]
        summary["vs_measured"] = {s: r / measured for s, r in summary["rmse"].items() if s != "measured"}
        nbrdf = {s: r for s, r in summary["vs_measured"].items() if s in NBRDF_SAMPLING}
        if nbrdf:
            best = min(nbrdf, key=nbrdf.get)
            summary.update(best_nbrdf=best, best_vs_measured=nbrdf[best])
    if "phong-fit" in summary["rmse"]:
        lobe = summary["rmse"]["phong-fit"]
        summary["vs_phong_fit"] = {s: r / lobe for s, r in summary["rmse"].items() if s != "phong-fit"}
    return summary


def cost_floor(rows: list[dict], timings: list[dict], floor: str = COST_FLOOR_BSDF) -> dict | None:
    """What the render time costs each NBRDF strategy against ``measured``, and the least any
    BSDF could cost: at the highest spp that all reached (median over seeds), each strategy's RMSE
    over measured's (``per_sample``: same samples, so the sampler's quality alone), its render
    time over measured's (``time``), and the plates rendered with ``floor`` (a BSDF that costs next
    to nothing, timed in the same runs; ``floor_time``). ``bound``: the equal-time ratio that each
    strategy's per-sample error would reach at the floor's time, i.e. if the BSDF's evaluation and
    sampling cost nothing (equal time: the RMSE ratio is the per-sample ratio times the square root
    of the time ratio). None without measured or the floor's timings."""
    floor_rows = [t for t in timings if t["strategy"] == floor]
    if not floor_rows or not any(r["strategy"] == "measured" for r in rows):
        return None
    strategies = list(dict.fromkeys(r["strategy"] for r in rows))
    spp = min(max(r["spp"] for r in rows + floor_rows if r["strategy"] == s) for s in strategies + [floor])

    def median(strategy: str, key: str, source: list[dict]) -> float:
        return float(np.median([r[key] for r in source if r["strategy"] == strategy and r["spp"] == spp]))

    measured_time, measured_rmse = median("measured", "seconds", rows), median("measured", "rmse", rows)
    if not (measured_time > 0 and measured_rmse > 0):
        return None  # nothing to compare with (a noiseless or untimed measured render)
    floor_time = median(floor, "seconds", floor_rows) / measured_time
    nbrdf = [s for s in strategies if s in NBRDF_SAMPLING]
    per_sample = {s: median(s, "rmse", rows) / measured_rmse for s in nbrdf}
    return {"bsdf": floor, "spp": spp, "statistic": "median over seeds", "floor_time": floor_time,
            "per_sample": per_sample, "time": {s: median(s, "seconds", rows) / measured_time for s in nbrdf},
            "bound": {s: r * math.sqrt(floor_time) for s, r in per_sample.items()}}


def stored_default_sampling(network: Path) -> str | None:
    """The network file's ``sampling.default`` (what the plugin samples with when the scene names
    no ``sampling``), None when it names none."""
    try:
        sampling = json.loads(Path(network).read_text()).get("sampling") or {}
    except (OSError, ValueError):
        return None
    return sampling.get("default")


# ---------------------------------------------------------------------------------------------
# Plots


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _power_of_two_axis(ax, levels) -> None:
    """spp on a log2 axis, ticks labelled 1, 2, 4, ... (every other one when crowded)."""
    from matplotlib.ticker import FixedLocator, NullLocator

    levels = sorted(levels)
    step = 1 if len(levels) <= 9 else 2
    ax.set_xscale("log", base=2)
    ax.xaxis.set_major_locator(FixedLocator(levels[::step]))
    ax.xaxis.set_minor_locator(NullLocator())
    ax.set_xticklabels([str(int(v)) for v in levels[::step]])


def _log_axes(ax) -> None:
    """Log-log axes; the x axis (render time) labelled at 1, 2, 5 x 10^k as plain numbers (the
    default minor labels such as 2x10^-1 overlap), the y axis at the decades."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())


def _curve(ax, x, curve, colour, label, ms=4):
    """Median over seeds (time order), with the min-max band when there are several seeds."""
    order = np.argsort(x)
    (line,) = ax.plot(x[order], curve["median"][order], "o-", ms=ms, color=colour, label=label)
    if curve["seeds"] > 1:
        ax.fill_between(x[order], curve["low"][order], curve["high"][order], color=colour, alpha=0.2, lw=0)
    return line


def save_figure(fig, path: Path, dpi: int = 150) -> None:
    """PNG and PDF side by side."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    fig.savefig(path.with_suffix(".pdf"))


def plot_material(path: Path, title: str, rows: list[dict], representation: float | None, metric: str = "rmse"):
    """Error against spp (power-of-two axis, with a 1/sqrt(spp) guide) and against render time
    (points in time order), one curve per strategy: the median over seeds with a min-max band."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    seeds, first = 1, []
    for i, strategy in enumerate(STRATEGIES):
        curve = series(rows, strategy, metric)
        if curve is None:
            continue
        seeds = max(seeds, curve["seeds"])
        _curve(axes[0], curve["spp"].astype(float), curve, f"C{i}", strategy)
        _curve(axes[1], curve["seconds"], curve, f"C{i}", strategy)
        first.append((curve["spp"][0], curve["median"][0]))
    levels = sorted({r["spp"] for r in rows})
    if first and len(levels) > 1:
        spp0, error0 = max(first, key=lambda p: p[1])
        guide = error0 * np.sqrt(spp0 / np.array(levels, dtype=float))
        axes[0].plot(levels, guide, color="black", ls=":", lw=1, label=r"$\propto 1/\sqrt{\mathrm{spp}}$")
    for ax, xlabel in zip(axes, ("samples per pixel", "render time (s)")):
        _log_axes(ax)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"{metric.upper()} (sampling error)")
        ax.grid(True, which="both", alpha=0.3)
        if representation is not None and representation > 0:
            ax.axhline(representation, color="grey", ls="--", lw=1, label="NBRDF vs ground truth")
    _power_of_two_axis(axes[0], levels)
    axes[0].legend(fontsize=8)
    band = f"; median of {seeds} seeds, band min-max" if seeds > 1 else ""
    fig.suptitle(title + band)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def plot_overview(path: Path, title: str, per_material: dict[str, list[dict]], metric: str = "rmse"):
    """Error against render time per material (small multiples)."""
    plt = _pyplot()
    names = list(per_material)
    cols = min(4, len(names))
    rows_n = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(3.6 * cols, 3.0 * rows_n), squeeze=False)
    colours = {s: f"C{i}" for i, s in enumerate(STRATEGIES)}
    handles = {}
    for ax, name in zip(axes.ravel(), names):
        for strategy in STRATEGIES:
            curve = series(per_material[name], strategy, metric)
            if curve is not None:
                handles[strategy] = _curve(ax, curve["seconds"], curve, colours[strategy], strategy, ms=3)
        _log_axes(ax)
        ax.set_title(name, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    fig.legend(list(handles.values()), list(handles), loc="lower right", fontsize=8)
    fig.supxlabel("render time (s)")
    fig.supylabel(f"{metric.upper()} (sampling error)")
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# Runs


def reference(cache: RenderCache, name: str, description: dict, files, settings: dict, scene_fn, spp: int,
              passes: int, label: str) -> np.ndarray:
    def make():
        return render_passes(scene_fn(), spp, spp_per_pass=passes, seed=REFERENCE_SEED, desc=label)

    return cache.get(name, description, files, settings, make)


def predicted_lobe(args, material: Material, out: Path) -> tuple[float, float] | None:
    """``(n, w)`` of ``nbrdf predict-phong`` for the material's network, or None without a
    predictor. The network file itself is left alone (its lobe stays the fitted one)."""
    if not (args.ae and args.predictor):
        return None
    target = out / "predicted" / f"{material.name}.nbrdf.json"
    target.parent.mkdir(parents=True, exist_ok=True)
    cli.run([args.cli, "predict-phong", "--ae", args.ae, "--predictor", args.predictor, material.network,
             "-o", target])
    sampling = json.loads(target.read_text())["sampling"]
    return float(sampling["exponent"]), float(sampling["specular_weight"])


def run_veach(args, artefacts: Artefacts, cache: RenderCache, out: Path, notes: list[str]) -> dict:
    setup = VeachSetup(args)
    levels = spp_levels(args.max_spp)
    specs = material_specs(args)
    results, representation, equal_time, per_material, predicted_lobes = [], [], [], {}, {}
    timings = []
    tag = "" if setup.integrator == "bsdf" else f"-{setup.integrator}"  # keeps the two runs apart
    settings = {"spp": args.gt_spp, "resolution": list(setup.resolution), "integrator": "mis",
                "seed": REFERENCE_SEED, "spp_per_pass": args.spp_per_pass}
    for spec in bar(specs, desc="veach: materials", unit="material"):
        material: Material = artefacts.get(spec)
        for note in material.notes:
            notes.append(f"{material.name}: {note}")
        label = material.name
        # References: the ground truth and the converged NBRDF (same seeds: common random numbers).
        gt_bsdf = material.ground_truth_bsdf()
        ground_truth = reference(cache, f"veach-{label}-ground-truth", setup.description(gt_bsdf, "mis"),
                                 bsdf_files(gt_bsdf), settings, lambda bsdf=gt_bsdf: setup.load(bsdf, "mis"),
                                 args.gt_spp, args.spp_per_pass, f"{label}: ground truth")
        ref_bsdf = material.nbrdf("phong" if material.has_phong else "cosine")
        nbrdf_ref = reference(cache, f"veach-{label}-nbrdf", setup.description(ref_bsdf, "mis"), bsdf_files(ref_bsdf),
                              settings, lambda bsdf=ref_bsdf: setup.load(bsdf, "mis"), args.gt_spp, args.spp_per_pass,
                              f"{label}: converged NBRDF")
        mask_scene = setup.load({"type": "diffuse"})
        mask = setup.mask(mask_scene)
        rep = {"scene": "veach", "material": label, "kind": material.kind, "model": "nbrdf",
               "network": material.network_source, "spp": args.gt_spp, "region": "plates",
               **representation_metrics(ground_truth, nbrdf_ref, mask)}
        representation.append(rep)
        if material.kind == "rgl":
            table_bsdf = material.table_bsdf("phong" if material.has_phong else None)
            table_ref = reference(cache, f"veach-{label}-table", setup.description(table_bsdf, "mis"),
                                  bsdf_files(table_bsdf), settings, lambda bsdf=table_bsdf: setup.load(bsdf, "mis"),
                                  args.gt_spp, args.spp_per_pass, f"{label}: tabulated")
            representation.append({**rep, "model": "table", "network": "-",
                                   **representation_metrics(ground_truth, table_ref, mask)})
        # Strategies.
        strategies = {}
        for strategy in (s for s in STRATEGIES if s in args.strategies):
            if strategy in NBRDF_SAMPLING:
                if strategy == "phong-fit" and not material.has_phong:
                    continue
                if strategy == "two-lobe-fit" and not material.has_two_lobes:
                    continue
                extra = {}
                if strategy == "phong-predicted":
                    lobe = predicted_lobe(args, material, out)
                    if lobe is None:
                        continue
                    extra = {"exponent": lobe[0], "specular_weight": lobe[1]}
                    predicted_lobes[label] = lobe
                bsdf = material.nbrdf(NBRDF_SAMPLING[strategy], **extra)
                strategies[strategy] = {"scene": setup.load(bsdf), "reference": nbrdf_ref, "reference_name": "nbrdf"}
            elif strategy == "measured" and material.measured is not None:
                bsdf = {"type": "measured", "filename": str(material.measured)}
                strategies[strategy] = {"scene": setup.load(bsdf), "reference": ground_truth,
                                        "reference_name": "measured"}
        save_dir = out / f"renders{tag}" / label
        save_spp = {levels[0], levels[len(levels) // 2], levels[-1]}
        # Beside measured, the plates in a BSDF that costs next to nothing: the scene's share of a
        # render, which bounds what any BSDF can gain on measured at equal time (cost_floor).
        floor = {COST_FLOOR_BSDF: mask_scene} if "measured" in strategies else {}
        material_timings = []
        rows = measure(strategies, levels, mask, ground_truth, label, save_dir, save_spp, args.seeds,
                       timing_only=floor, timings=material_timings)
        for row in material_timings:
            row.update(scene="veach", material=label, integrator=setup.integrator)
        timings += material_timings
        write_exr(save_dir / "ground-truth.exr", ground_truth)
        write_exr(save_dir / "nbrdf-converged.exr", nbrdf_ref)
        write_png(save_dir / "ground-truth.png", ground_truth)
        write_png(save_dir / "nbrdf-converged.png", nbrdf_ref)
        for row in rows:
            row.update(scene="veach", material=label, integrator=setup.integrator, region="plates")
        results += rows
        per_material[label] = rows
        summary = equal_time_summary(rows)
        floor_summary = cost_floor(rows, material_timings)
        if floor_summary is not None:
            summary["cost_floor"] = floor_summary
        equal_time.append({"scene": "veach", "material": label, "kind": material.kind,
                           "exponent": material.exponent, "specular_weight": material.specular_weight,
                           "two_lobe_exponents": material.two_lobe_exponents,
                           "two_lobe_weights": material.two_lobe_weights,
                           "default_sampling": stored_default_sampling(material.network),
                           **({"predicted_exponent": predicted_lobes[label][0],
                               "predicted_specular_weight": predicted_lobes[label][1]}
                              if label in predicted_lobes else {}),
                           **summary})
        plot_material(out / "plots" / f"veach{tag}-{label}.png",
                      f"Veach ({'pure BSDF sampling' if setup.integrator == 'bsdf' else 'MIS'}), {label}: "
                      f"error on the plates", rows, rep["rmse"])
        log(f"{label}: " + ", ".join(f"{s} {v:.4g}" for s, v in summary["rmse"].items())
            + f" RMSE at {summary['seconds']:.2f} s; NBRDF vs ground truth RMSE {rep['rmse']:.4g}")
        del strategies, mask_scene
    plot_overview(out / "plots" / f"veach{tag}-overview.png",
                  f"Veach scene, {'pure BSDF sampling' if setup.integrator == 'bsdf' else 'MIS'}: RMSE on the plates "
                  "against render time", per_material)
    return {"results": results, "representation": representation, "equal_time": equal_time, "timings": timings}


def kitchen_skip_reason(strategy: str, has_phong: bool, has_two_lobes: bool) -> str | None:
    """Why a strategy is not rendered in the kitchen, None when it is: every replaced material
    needs what the strategy samples with, and the kitchen's materials are MERL tables."""
    if strategy == "measured":
        return "Mitsuba's measured BSDF needs RGL measurements, the kitchen's materials are MERL tables"
    if strategy == "phong-predicted":
        return "the predicted lobe is measured in the Veach scene only"
    if strategy == "phong-fit" and not has_phong:
        return "not every replaced material has a fitted lobe (nbrdf fit-phong)"
    if strategy == "two-lobe-fit" and not has_two_lobes:
        return "not every replaced material has a two-lobe mixture (nbrdf fit-phong --lobes 2)"
    return None


def default_counts(defaults: dict[str, str | None]) -> str:
    """The stored defaults of several materials as one cell, e.g. ``tabulated x9, cosine x4``."""
    counts: dict[str, int] = {}
    for default in defaults.values():
        counts[default or "none"] = counts.get(default or "none", 0) + 1
    return ", ".join(f"{d} x{n}" for d, n in sorted(counts.items(), key=lambda item: (-item[1], item[0])))


def run_kitchen(args, artefacts: Artefacts, cache: RenderCache, out: Path, notes: list[str]) -> dict:
    setup = KitchenSetup(args)
    module = setup.module
    names = sorted(set(setup.overrides["overrides"].values()))
    materials = {}
    for name in bar(names, desc="kitchen: materials", unit="material"):
        materials[name] = artefacts.get(name)
        for note in materials[name].notes:
            notes.append(f"{name}: {note}")
    has_phong = all(m.has_phong for m in materials.values())
    has_two_lobes = all(m.has_two_lobes for m in materials.values())
    label = f"{len(setup.overrides['overrides'])} overrides"
    levels = spp_levels(args.max_spp)
    settings = {"spp": args.gt_spp, "resolution": list(setup.resolution), "integrator": "path",
                "max_depth": setup.max_depth, "seed": REFERENCE_SEED, "spp_per_pass": args.spp_per_pass}
    files = setup.inputs()

    def bsdfs(strategy):
        return module.override_bsdfs(setup.overrides, materials, strategy)

    gt_bsdfs = bsdfs("table-phong" if has_phong else "table")
    ground_truth = reference(cache, "kitchen-ground-truth", setup.description(gt_bsdfs), files + bsdf_files(gt_bsdfs),
                             settings, lambda: setup.load(gt_bsdfs), args.gt_spp, args.spp_per_pass,
                             "kitchen: ground truth")
    ref_bsdfs = bsdfs("phong" if has_phong else "cosine")
    nbrdf_ref = reference(cache, "kitchen-nbrdf", setup.description(ref_bsdfs), files + bsdf_files(ref_bsdfs),
                          settings, lambda: setup.load(ref_bsdfs), args.gt_spp, args.spp_per_pass,
                          "kitchen: converged NBRDF")
    overridden = None
    probe = setup.load(ref_bsdfs)
    from nbrdf_tools.render import primary_hit_mask

    overridden = primary_hit_mask(probe, bsdf_ids=setup.overrides["overrides"].keys())
    rep = {"scene": "kitchen", "material": label, "kind": "merl", "model": "nbrdf",
           "network": ",".join(sorted({m.network_source for m in materials.values()})), "spp": args.gt_spp,
           "region": "image", **representation_metrics(ground_truth, nbrdf_ref)}
    rep_overridden = {**rep, "region": "replaced materials",
                      **representation_metrics(ground_truth, nbrdf_ref, overridden)}
    strategies, skipped = {}, []
    for strategy in (s for s in STRATEGIES if s in args.strategies):
        reason = kitchen_skip_reason(strategy, has_phong, has_two_lobes)
        if reason:
            skipped.append(f"kitchen: {strategy} skipped: {reason}")
            continue
        strategies[strategy] = {"scene": setup.load(bsdfs(NBRDF_SAMPLING[strategy])), "reference": nbrdf_ref,
                                "reference_name": "nbrdf"}
    notes += skipped
    if not strategies:
        raise MissingDataError("kitchen: no strategy left to render; " + "; ".join(skipped))
    save_dir = out / "renders" / "kitchen"
    rows = measure(strategies, levels, None, ground_truth, "kitchen", save_dir, {levels[0], levels[-1]}, args.seeds)
    for row in rows:
        row.update(scene="kitchen", material=label, integrator="path", region="image")
    # Fireflies traceable to our BSDFs: the NBRDF and the table, Phong-sampled alike with the same
    # random numbers at the highest spp, counted against the ground truth.
    top = levels[-1]
    seed = 424242
    check_strategy = "phong-fit" if has_phong else "cosine"
    check_scene = (strategies[check_strategy]["scene"] if check_strategy in strategies
                   else setup.load(bsdfs(NBRDF_SAMPLING[check_strategy])))
    nbrdf_image, _ = timed_render(check_scene, top, seed=seed)
    table_image, _ = timed_render(setup.load(gt_bsdfs), top, seed=seed)
    checks = {
        "spp": top,
        "nonfinite_pixels": {"nbrdf": metrics.nonfinite_count(nbrdf_image), "merl": metrics.nonfinite_count(table_image),
                             "nbrdf_reference": metrics.nonfinite_count(nbrdf_ref),
                             "all_strategy_renders": int(sum(r["nonfinite"] for r in rows))},
        "fireflies": {"nbrdf": metrics.firefly_count(ground_truth, nbrdf_image),
                      "merl": metrics.firefly_count(ground_truth, table_image),
                      "rule": "luminance > 10 x ground truth + 1"},
        "max_over_ground_truth": {"nbrdf": float(np.max(nbrdf_image - ground_truth)),
                                  "merl": float(np.max(table_image - ground_truth))},
        "overridden_pixels_percent": float(100 * overridden.mean()),
        "pixels": int(overridden.size),
    }
    for name, image in (("ground-truth", ground_truth), ("nbrdf-converged", nbrdf_ref),
                        (f"nbrdf-phong-{top}spp", nbrdf_image), (f"merl-phong-{top}spp", table_image)):
        write_exr(save_dir / f"{name}.exr", image)
        write_png(save_dir / f"{name}.png", image)
    summary = equal_time_summary(rows)
    plot_material(out / "plots" / "kitchen.png", f"Kitchen (path tracing), {label} replaced: error on the image",
                  rows, rep["rmse"])
    log("kitchen: " + ", ".join(f"{s} {v:.4g}" for s, v in summary["rmse"].items())
        + f" RMSE at {summary['seconds']:.2f} s; NBRDF vs ground truth RMSE {rep['rmse']:.4g}")
    defaults = {name: stored_default_sampling(m.network) for name, m in materials.items()}
    return {"results": rows, "representation": [rep, rep_overridden],
            "equal_time": [{"scene": "kitchen", "material": label, "default_sampling": default_counts(defaults),
                            "default_samplings": defaults, **summary}], "kitchen": checks}


# ---------------------------------------------------------------------------------------------
# Reports


def vs_measured_table(equal_time: list[dict]) -> list[str]:
    """Markdown lines: per material with ``measured``, each NBRDF strategy's RMSE over
    measured's at equal time (median over seeds; the pooled RMSE's ratio in brackets) and the
    best; none without such materials (e.g. reports written before these fields)."""
    rows = [e for e in equal_time if "vs_measured" in e]
    if not rows:
        return []
    strategies = [s for s in STRATEGIES if s in NBRDF_SAMPLING and any(s in e["vs_measured"] for e in rows)]
    lines = ["RMSE of each NBRDF strategy over the RMSE of Mitsuba's `measured` (sampling the measurement) "
             "at the same render time, median over seeds (in brackets: root mean square over seeds); below 1 "
             "is better than `measured`:", "",
             "| material | time (s) | measured RMSE | " + " | ".join(f"{s} / measured" for s in strategies)
             + " | best |",
             "|" + "---|" * (len(strategies) + 4)]
    for e in rows:
        pooled = e.get("rmse_pooled", {})
        cells = []
        for s in strategies:
            if s not in e["vs_measured"]:
                cells.append("-")
                continue
            cell = f"{e['vs_measured'][s]:.2f}"
            if s in pooled and "measured" in pooled:
                cell += f" ({pooled[s] / pooled['measured']:.2f})"
            cells.append(cell)
        best = f"{e['best_nbrdf']} {e['best_vs_measured']:.2f}" if "best_nbrdf" in e else "-"
        lines.append(f"| {e['material']} | {e['seconds']:.2f} | {e['rmse']['measured']:.4g} | "
                     + " | ".join(cells) + f" | {best} |")
    return lines + [""]


def cost_floor_table(equal_time: list[dict]) -> list[str]:
    """Markdown lines: per material with a cost floor (``cost_floor``), each NBRDF strategy's RMSE
    and render time over measured's at the same spp, the floor BSDF's time, and the lowest
    equal-time ratio that any strategy's per-sample error allows at the floor's time; none
    without such materials."""
    rows = [e for e in equal_time if "cost_floor" in e]
    if not rows:
        return []
    floors = [e["cost_floor"] for e in rows]
    strategies = [s for s in STRATEGIES if any(s in f["per_sample"] for f in floors)]
    bsdf = floors[0]["bsdf"]
    lines = [f"Per sample and per render against `measured` at the same spp (median over seeds): RMSE / "
             f"render time, each over measured's; `{bsdf}`: the render time with `{bsdf}` plates, a BSDF that "
             "costs next to nothing (the scene's share of every render); bound: the lowest equal-time ratio "
             "to measured that a strategy's per-sample error allows if its BSDF cost nothing "
             f"(per-sample ratio x sqrt(`{bsdf}` time)), beside the best strategy's measured ratio:", "",
             "| material | spp | " + " | ".join(strategies) + f" | `{bsdf}` time | bound | best at equal time |",
             "|" + "---|" * (len(strategies) + 5)]
    for e, f in zip(rows, floors):
        cells = [f"{f['per_sample'][s]:.2f} / {f['time'][s]:.2f}" if s in f["per_sample"] else "-"
                 for s in strategies]
        lowest = min(f["bound"], key=f["bound"].get)
        best = f"{e['best_nbrdf']} {e['best_vs_measured']:.2f}" if "best_nbrdf" in e else "-"
        lines.append(f"| {e['material']} | {f['spp']} | " + " | ".join(cells)
                     + f" | {f['floor_time']:.2f} | {f['bound'][lowest]:.2f} ({lowest}) | {best} |")
    return lines + [""]


def vs_phong_fit_table(equal_time: list[dict]) -> list[str]:
    """Markdown lines: per material, each strategy's RMSE over the single lobe's (``phong-fit``)
    at equal time (median over seeds) and the file's stored default; none without phong-fit."""
    rows = [e for e in equal_time if "vs_phong_fit" in e]
    if not rows:
        return []
    strategies = [s for s in STRATEGIES if any(s in e["vs_phong_fit"] for e in rows)]
    lines = ["RMSE of each strategy over the single Blinn-Phong lobe's (`phong-fit`) at the same render time, "
             "median over seeds; below 1 is better than one lobe; `default` is the network file's "
             "`sampling.default`:", "",
             "| material | stored default | " + " | ".join(f"{s} / phong-fit" for s in strategies) + " |",
             "|" + "---|" * (len(strategies) + 2)]
    for e in rows:
        cells = [f"{e['vs_phong_fit'][s]:.2f}" if s in e["vs_phong_fit"] else "-" for s in strategies]
        lines.append(f"| {e['material']} | {e.get('default_sampling') or '-'} | " + " | ".join(cells) + " |")
    return lines + [""]


def markdown(report: dict) -> str:
    lines = []
    scene = report["settings"]["scene"]
    if report["equal_time"]:
        strategies = [s for s in STRATEGIES if any(s in e["rmse"] for e in report["equal_time"])]
        lines += [f"RMSE (sampling error{', plates only' if scene == 'veach' else ''}) at equal render time "
                  f"({report['settings']['integrator_label']}, {report['settings']['resolution'][0]}x"
                  f"{report['settings']['resolution'][1]}"
                  + (f", median of {report['settings']['seeds']} seeds" if report["settings"].get("seeds", 1) > 1 else "")
                  + "):", ""]
        header = ("| material | Phong n, w | two lobes n1, w1; n2, w2 | time (s) | " + " | ".join(strategies)
                  + " | phong-fit / cosine | phong-fit / uniform |")
        predicted = "phong-predicted" in strategies
        if predicted:
            header += " predicted n, w | phong-predicted / phong-fit |"
        lines += [header, "|" + "---|" * (header.count("|") - 1)]
        for e in report["equal_time"]:
            r = e["rmse"]
            phong = e.get("exponent")
            lobe = f"{phong:.3g}, {e['specular_weight']:.2f}" if phong is not None else "-"
            two = e.get("two_lobe_exponents")
            lobes = (f"{two[0]:.3g}, {e['two_lobe_weights'][0]:.2f}; {two[1]:.3g}, {e['two_lobe_weights'][1]:.2f}"
                     if two else "-")
            cells = [f"{r[s]:.4g}" if s in r else "-" for s in strategies]
            ratio_c = f"{r['phong-fit'] / r['cosine']:.2f}" if "phong-fit" in r and "cosine" in r else "-"
            ratio_u = f"{r['phong-fit'] / r['uniform']:.3f}" if "phong-fit" in r and "uniform" in r else "-"
            line = (f"| {e['material']} | {lobe} | {lobes} | {e['seconds']:.2f} | " + " | ".join(cells)
                    + f" | {ratio_c} | {ratio_u} |")
            if predicted:
                pn = e.get("predicted_exponent")
                plobe = f"{pn:.3g}, {e['predicted_specular_weight']:.2f}" if pn is not None else "-"
                ratio_p = (f"{r['phong-predicted'] / r['phong-fit']:.2f}"
                           if "phong-predicted" in r and "phong-fit" in r else "-")
                line += f" {plobe} | {ratio_p} |"
            lines.append(line)
        lines.append("")
        lines += vs_phong_fit_table(report["equal_time"])
        lines += vs_measured_table(report["equal_time"])
        lines += cost_floor_table(report["equal_time"])
    if report["representation"]:
        lines += [f"Representation error against the ground truth ({report['settings']['gt_spp']} spp, MIS/path, "
                  "same random numbers):", "",
                  "| material | model | network | region | MAE | RMSE | relative RMSE | relMSE | MAPE | "
                  "PSNR, peak 1 (dB) | SSIM (image) | HDR-FLIP (image) |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in report["representation"]:
            # (Reports written before relMSE, SSIM and FLIP were added show "-" there on --replot;
            # their "psnr" was the peak-1 one.)
            ssim = f"{r['ssim']:.4f}" if "ssim" in r else "-"
            flip = f"{r['flip_hdr']:.4f}" if "flip_hdr" in r else "-"
            relmse = f"{r['relmse']:.4g}" if "relmse" in r else "-"
            psnr = r.get("psnr_peak1", r.get("psnr"))
            lines.append(f"| {r['material']} | {r['model']} | {r['network']} | {r['region']} | {r['mae']:.4g} | "
                         f"{r['rmse']:.4g} | {r['relative_rmse']:.3f} | {relmse} | {r['mape']:.4g} | "
                         f"{psnr:.1f} | {ssim} | {flip} |")
        lines.append("")
    if report.get("kitchen"):
        k = report["kitchen"]
        nonfinite = k["nonfinite_pixels"]
        lines += [f"Kitchen checks: non-finite values: {nonfinite['all_strategy_renders']} in all strategy renders, "
                  f"{nonfinite['nbrdf_reference']} in the converged NBRDF, {nonfinite['nbrdf']} (NBRDF) and "
                  f"{nonfinite['merl']} (table) in the Phong-sampled {k['spp']} spp renders made with the same random "
                  f"numbers; fireflies there ({k['fireflies']['rule']}): NBRDF {k['fireflies']['nbrdf']}, table "
                  f"{k['fireflies']['merl']} of {k.get('pixels', 'all')} pixels; the replaced materials cover "
                  f"{k['overridden_pixels_percent']:.1f} % of the image.", ""]
    for note in report["notes"]:
        lines.append(f"* {note}")
    return "\n".join(lines) + "\n"


def replot(report: dict, scene_out: Path) -> None:
    """The plots of a finished run (from its JSON), e.g. after changing the plotting code."""
    per_material: dict[str, list[dict]] = {}
    for row in report["results"]:
        per_material.setdefault(row["material"], []).append(row)
    representation = {r["material"]: r["rmse"] for r in report["representation"] if r["model"] == "nbrdf"}
    scene = report["settings"]["scene"]
    label = report["settings"]["integrator_label"]
    if scene == "veach":
        integrator = report["settings"]["integrator"]
        tag = "" if integrator == "bsdf" else f"-{integrator}"
        for name, rows in per_material.items():
            plot_material(scene_out / "plots" / f"veach{tag}-{name}.png", f"Veach ({label}), {name}: error on the plates",
                          rows, representation.get(name))
        plot_overview(scene_out / "plots" / f"veach{tag}-overview.png",
                      f"Veach scene, {label}: RMSE on the plates against render time", per_material)
    else:
        for name, rows in per_material.items():
            plot_material(scene_out / "plots" / "kitchen.png",
                          f"Kitchen ({label}), {name} replaced: error on the image", rows, representation.get(name))


def write_csv(path: Path, rows: list[dict]) -> None:
    if not rows:
        return
    keys = ["scene", "material", "strategy", "spp", "seconds", "mae", "rmse", "relmse", "mape", "psnr_peak1"]
    keys += [k for k in rows[0] if k not in keys]
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", choices=["veach", "kitchen"], default="veach")
    parser.add_argument("--materials", default=",".join(VEACH_MERL),
                        help="comma-separated MERL materials for the Veach scene (default: %(default)s)")
    parser.add_argument("--rgl", default=None,
                        help="comma-separated RGL materials for the Veach scene: paths of .bsdf measurements or "
                             "names in the shared data (SHARED/data/rgl/NAME.bsdf); empty for none (default: "
                             f"{','.join(VEACH_RGL)} when the shared data holds them, else none)")
    parser.add_argument("--integrator", choices=["bsdf", "mis"], default="bsdf",
                        help="Veach: bsdf = pure BSDF sampling (direct, emitter_samples = 0), mis = MIS")
    parser.add_argument("--width", type=int, help="image width (Veach: 384, kitchen: from kitchen_materials.json)")
    parser.add_argument("--height", type=int, help="image height (default: 2/3 of the width, kitchen 9/16)")
    parser.add_argument("--max-spp", type=int, default=128, help="highest spp of the series 1, 2, 4, ...")
    parser.add_argument("--strategies", default=",".join(DEFAULT_STRATEGIES),
                        help="comma-separated strategies to render, of those available per material, "
                             f"of {', '.join(STRATEGIES)}; the kitchen skips measured and phong-predicted with a "
                             "note (default: %(default)s)")
    parser.add_argument("--seeds", type=int, default=1,
                        help="independent renders per strategy and spp; the plots show their median and range "
                             "(default: %(default)s)")
    parser.add_argument("--gt-spp", type=int, default=1024, help="spp of the ground truths and references")
    parser.add_argument("--spp-per-pass", type=int, default=64, help="spp per pass of the reference renders")
    parser.add_argument("--max-depth", type=int, help="kitchen: path length (default from kitchen_materials.json)")
    parser.add_argument("--kitchen", help="kitchen scene.xml or its folder (default ../shared/scenes/kitchen)")
    parser.add_argument("--kitchen-materials", default=str(SCENES / "kitchen_materials.json"),
                        help="the override description")
    parser.add_argument("--train-args", default="", help="extra arguments of `nbrdf train`, e.g. '--epochs 30'")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--quick", action="store_true",
                        help="tiny images, few samples, one material, briefly trained networks (CI, checks)")
    parser.add_argument("--json", type=Path, help="write the results as JSON here as well")
    parser.add_argument("--out", type=Path,
                        help="output folder of everything, caches included (default: out/convergence with the "
                             "materials and references cached in out/; quick: out/convergence-quick)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars (for logs)")
    parser.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf command-line tool")
    parser.add_argument("--force", action="store_true", help="re-render cached references")
    parser.add_argument("--ae", type=Path, help="autoencoder (nbrdf ae train) for the phong-predicted strategy")
    parser.add_argument("--predictor", type=Path,
                        help="Phong-parameter predictor (nbrdf predictor train) for the phong-predicted strategy")
    parser.add_argument("--replot", action="store_true",
                        help="only redraw the plots and the summary of the last run's JSON (same --scene, --out, "
                             "--integrator)")
    args = parser.parse_args(argv)

    train_args = args.train_args.split()
    progress.set_enabled(not args.no_progress)
    args.strategies = [s for s in args.strategies.split(",") if s]
    unknown = [s for s in args.strategies if s not in STRATEGIES]
    if unknown or not args.strategies:
        parser.error(f"--strategies: unknown {', '.join(unknown) or '(none given)'}; choose from {', '.join(STRATEGIES)}")
    if args.scene == "kitchen" and all(kitchen_skip_reason(s, True, True) for s in args.strategies):
        parser.error(f"--strategies: the kitchen renders none of {', '.join(args.strategies)}; choose from "
                     f"{', '.join(s for s in STRATEGIES if not kitchen_skip_reason(s, True, True))}")
    notes = []
    if args.rgl is None:
        shared_rgl = [m for m in VEACH_RGL if shared_path("data", "rgl", f"{m}.bsdf").is_file()]
        args.rgl = "" if args.quick else ",".join(shared_rgl)
        if not args.quick and len(shared_rgl) < len(VEACH_RGL):
            message = (f"RGL materials {', '.join(m for m in VEACH_RGL if m not in shared_rgl)} left out: not in "
                       f"{shared_path('data', 'rgl')} (set NBRDF_SHARED, or pass --rgl PATH.bsdf,...)")
            print(f"note: {message}")
            notes.append(message)
    if args.quick:
        args.max_spp = min(args.max_spp, 4)
        args.gt_spp = min(args.gt_spp, 32)
        if args.scene == "veach":
            args.width = args.width or 64
            args.height = args.height or 43
            args.materials = args.materials if args.materials != ",".join(VEACH_MERL) else "blue-metallic-paint"
        else:
            args.width = args.width or 48
            args.height = args.height or 27
            args.max_spp = min(args.max_spp, 2)
            args.gt_spp = min(args.gt_spp, 8)
            args.max_depth = args.max_depth or 3
        train_args = train_args or QUICK_TRAIN_ARGS
    if args.scene == "veach":
        args.width = args.width or 384
    out = args.out or default_out("convergence-quick" if args.quick else "convergence")
    # Materials and references are shared between runs in out/ unless --out (or --quick) says where.
    cache_root = out if (args.out or args.quick) else default_out()
    scene_out = out / args.scene
    suffix = "" if args.scene == "kitchen" or args.integrator == "bsdf" else "-mis"
    if args.replot:
        report = json.loads((scene_out / f"convergence{suffix}.json").read_text())
        replot(report, scene_out)
        (scene_out / f"summary{suffix}.md").write_text(markdown(report))
        print(markdown(report))
        return 0

    # Everything the run needs is checked before any work starts.
    artefacts = Artefacts(cache_root, args.cli, train_args=train_args, log=log)
    try:
        if args.scene == "kitchen":
            KitchenSetup(args)
            problems = artefacts.missing(sorted(set(json.loads(Path(args.kitchen_materials).read_text())
                                                    ["overrides"].values())))
        else:
            problems = artefacts.missing(material_specs(args))
        if args.ae and args.predictor and args.scene == "veach":
            problems += [f"{path}: no such file" for path in (args.ae, args.predictor) if not path.is_file()]
    except (MissingDataError, cli.CommandError) as error:
        problems = [str(error)]
    if problems:
        print("error: missing inputs, nothing done:\n  " + "\n  ".join(problems), file=sys.stderr)
        return 2
    scene_out.mkdir(parents=True, exist_ok=True)
    mi.set_variant(args.variant)
    nbrdf_mitsuba.register()
    cache = RenderCache(cache_root / "references", force=args.force)
    if artefacts.can_train():
        notes.append(f"NBRDFs trained with `nbrdf train` on the MERL tables and on the RGL measurements themselves "
                     f"({' '.join(train_args) or 'default recipe'})")
    else:
        notes.append("NBRDFs imported from the authors' Keras networks (`nbrdf train` is not available)")
    if not artefacts.can_fit_phong():
        notes.append("Blinn-Phong lobes: `nbrdf fit-phong` is not available, phong-fit and two-lobe-fit skipped")
    if not (args.ae and args.predictor) and args.scene == "veach":
        message = "phong-predicted skipped: pass --ae AE.json --predictor P.json (nbrdf ae train, nbrdf predictor train)"
        print(f"note: {message}")
        notes.append(message)

    start = time.perf_counter()
    try:
        if args.scene == "veach":
            report = run_veach(args, artefacts, cache, scene_out, notes)
            resolution = VeachSetup(args).resolution
            integrator_label = "pure BSDF sampling" if args.integrator == "bsdf" else "MIS"
        else:
            report = run_kitchen(args, artefacts, cache, scene_out, notes)
            resolution = KitchenSetup(args).resolution
            integrator_label = "path tracing"
    except (MissingDataError, cli.CommandError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    report["notes"] = notes
    report["settings"] = {"scene": args.scene, "resolution": list(resolution), "max_spp": args.max_spp,
                          "gt_spp": args.gt_spp, "seeds": args.seeds,
                          "integrator": args.integrator if args.scene == "veach" else "path",
                          "integrator_label": integrator_label, "variant": args.variant, "quick": args.quick,
                          "train_args": train_args, "seconds": round(time.perf_counter() - start, 1),
                          "metrics": "MAE, RMSE, relMSE (eps 0.01), MAPE (eps 0.01), PSNR (peak 1) on linear RGB; "
                                     "representation also SSIM (scikit-image, tone-mapped) and HDR-FLIP, whole image",
                          "cache": {"hits": cache.hits, "misses": cache.misses}}
    write_csv(scene_out / f"convergence{suffix}.csv", report["results"])
    (scene_out / f"convergence{suffix}.json").write_text(json.dumps(report, indent=2) + "\n")
    text = markdown(report)
    (scene_out / f"summary{suffix}.md").write_text(text)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    print()
    print(text)
    print(f"wrote {scene_out}/convergence{suffix}.csv, .json, summary{suffix}.md, plots/ and renders/ "
          f"in {report['settings']['seconds']:.0f} s")
    if args.json:
        print(f"wrote {args.json}")
    bad = sum(r["nonfinite"] for r in report["results"])
    if bad:
        print(f"error: {bad} non-finite pixel values in the renders", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
