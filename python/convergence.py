"""Convergence of the sampling strategies: error against samples per pixel and against render time.

For each material, the scene is rendered with every sampling strategy at 1, 2, 4, ... spp and
each render is timed (wall clock, after the kernels are compiled; renders of up to 32 spp are
repeated with the same seed and the fastest time kept) and compared with a converged
reference; a CSV, a JSON file, EXR renders, PNG plots (log-log, one curve per strategy) and a
Markdown summary land in the output folder.

Strategies (DESIGN.md section 6): ``uniform``, ``cosine`` and ``phong-fit`` sample our NBRDF
(the ``nbrdf`` BSDF) by the uniform hemisphere, the cosine lobe and the Blinn-Phong lobe fitted by
``nbrdf fit-phong``; ``phong-predicted`` needs the predictor of the latent-space work (skipped,
with a note, while it does not exist); ``measured`` is Mitsuba's own ``measured`` BSDF with its
own sampling (RGL materials only).

References and ground truths (cached under ``OUT/references`` with JSON sidecars, re-rendered when
any input changes; see ground_truth.py), all with multiple importance sampling (emitter + BSDF
samples: the same integral, much less noise) at ``--gt-spp``:

* the ground truth: the tabulated material through the ``merl`` BSDF (MERL materials), or the
  measurement through Mitsuba's ``measured`` BSDF (RGL materials);
* the converged NBRDF: our network at the same sample count, with the same random numbers.

The sampling error of a strategy is measured against the converged render of the *same* BSDF
(fields ``mae``, ``rmse``, ``mape``, ``psnr``): the NBRDF for ``uniform``/``cosine``/``phong-*``,
the measurement for ``measured``. The representation error (NBRDF against ground truth at
``--gt-spp``) is reported separately, and the total error of every render against the ground
truth is in the ``*_vs_ground_truth`` fields.

In the Veach scene the errors are measured on the plates only (the floor and wall are diffuse);
in the kitchen on the whole image.

    python python/convergence.py --scene veach [--materials a,b] [--rgl x,y] [--integrator bsdf|mis]
    python python/convergence.py --scene kitchen [--kitchen PATH]
    python python/convergence.py --scene veach --quick --json out/convergence.json
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from pathlib import Path

import nbrdf_mitsuba  # first: finds a libLLVM for Dr.Jit before Mitsuba starts its JIT
import mitsuba as mi
import numpy as np
from tqdm import tqdm

import metrics
from ground_truth import RenderCache, file_hash
from materials import VEACH_MERL, VEACH_RGL, Artefacts, Material, default_cli
from render_utils import render_passes, timed_render, warm_up, write_exr, write_png

REPO = Path(__file__).resolve().parent.parent
STRATEGIES = ("uniform", "cosine", "phong-fit", "phong-predicted", "measured")
NBRDF_SAMPLING = {"uniform": "uniform", "cosine": "cosine", "phong-fit": "phong"}
REFERENCE_SEED = 1_000_000  # references use seeds from here on; test renders stay far below
QUICK_TRAIN_ARGS = ["--samples", "40000", "--epochs", "3", "--min-epochs", "1"]


def log(message: str) -> None:
    tqdm.write(message)


# ---------------------------------------------------------------------------------------------
# Scenes


class VeachSetup:
    name = "veach"

    def __init__(self, args):
        from veach_scene import VEACH_XML

        self.resolution = (args.width, args.height or round(args.width * 2 / 3))
        self.integrator = args.integrator
        self.xml = VEACH_XML

    def load(self, bsdf: dict, integrator: str | None = None):
        from veach_scene import load_veach_xml

        return load_veach_xml(bsdf, integrator=integrator or self.integrator, resolution=self.resolution)

    def mask(self, scene):
        from veach_scene import plate_mask

        return plate_mask(scene)

    def description(self, bsdf: dict, integrator: str) -> dict:
        return {"scene": "veach", "xml": file_hash(self.xml), "plates": bsdf, "integrator": integrator,
                "resolution": list(self.resolution)}


class KitchenSetup:
    name = "kitchen"

    def __init__(self, args):
        import kitchen_scene

        self.module = kitchen_scene
        self.path = kitchen_scene.kitchen_path(args.kitchen)
        if not self.path.is_file():
            raise SystemExit(f"error: kitchen scene {self.path} not found (pass --kitchen PATH or set NBRDF_KITCHEN)")
        self.description_file = Path(args.kitchen_materials)
        self.overrides = kitchen_scene.load_description(self.description_file)
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


def measure(strategies: dict, levels: list[int], mask, ground_truth, label: str, save_dir: Path | None,
            save_spp: set[int]) -> list[dict]:
    """Renders every strategy at every spp level (interleaved, so that machine load hits them
    alike) and measures each against its reference and against the ground truth."""
    rows = []
    for name, entry in strategies.items():
        entry["warm_up_seconds"] = warm_up(entry["scene"])
    total = len(levels) * len(strategies)
    with tqdm(total=total, desc=f"{label}: renders", unit="render", leave=False) as bar:
        for level_index, spp in enumerate(levels):
            for strategy_index, (name, entry) in enumerate(strategies.items()):
                seed = 1000 * (level_index + 1) + strategy_index
                image, seconds = timed_render(entry["scene"], spp, seed=seed)
                # Short renders are timed again (same seed, same image) and the fastest run kept:
                # other processes on the machine disturb short timings the most.
                for _ in range(timing_repeats(spp) - 1):
                    seconds = min(seconds, timed_render(entry["scene"], spp, seed=seed)[1])
                row = {"strategy": name, "spp": spp, "seconds": seconds,
                       **metrics.all_metrics(entry["reference"], image, mask),
                       "nonfinite": metrics.nonfinite_count(image)}
                for key, value in metrics.all_metrics(ground_truth, image, mask).items():
                    row[f"{key}_vs_ground_truth"] = value
                row["reference"] = entry["reference_name"]
                rows.append(row)
                if save_dir is not None and spp in save_spp:
                    write_exr(save_dir / f"{name}-{spp:04d}spp.exr", image)
                bar.update()
    return rows


def timing_repeats(spp: int) -> int:
    return 3 if spp <= 8 else 2 if spp <= 32 else 1


def equal_time_summary(rows: list[dict]) -> dict:
    """RMSE of every strategy at the longest render time that all strategies reached."""
    by_strategy: dict[str, list[tuple[float, float]]] = {}
    for row in rows:
        by_strategy.setdefault(row["strategy"], []).append((row["seconds"], row["rmse"]))
    budget = min(max(t for t, _ in points) for points in by_strategy.values())
    return {"seconds": budget, "rmse": {s: rmse_at_time(p, budget) for s, p in by_strategy.items()}}


# ---------------------------------------------------------------------------------------------
# Plots


def plot_material(path: Path, title: str, rows: list[dict], representation: float | None, metric: str = "rmse"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for i, strategy in enumerate(STRATEGIES):
        points = sorted((r["spp"], r["seconds"], r[metric]) for r in rows if r["strategy"] == strategy)
        if not points:
            continue
        spp, seconds, error = zip(*points)
        axes[0].plot(spp, error, "o-", color=f"C{i}", label=strategy)
        axes[1].plot(seconds, error, "o-", color=f"C{i}", label=strategy)
    for ax, xlabel in zip(axes, ("samples per pixel", "render time (s)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"{metric.upper()} (sampling error)")
        ax.grid(True, which="both", alpha=0.3)
        if representation is not None and representation > 0:
            ax.axhline(representation, color="grey", ls="--", lw=1, label="NBRDF vs ground truth")
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_overview(path: Path, title: str, per_material: dict[str, list[dict]], metric: str = "rmse"):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(per_material)
    cols = min(4, len(names))
    rows_n = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(3.6 * cols, 3.0 * rows_n), squeeze=False)
    colours = {s: f"C{i}" for i, s in enumerate(STRATEGIES)}
    handles = {}
    for ax, name in zip(axes.ravel(), names):
        for strategy in STRATEGIES:
            points = sorted((r["spp"], r["seconds"], r[metric]) for r in per_material[name] if r["strategy"] == strategy)
            if points:
                _, seconds, error = zip(*points)
                (handles[strategy],) = ax.plot(seconds, error, "o-", ms=3, color=colours[strategy], label=strategy)
        ax.set_xscale("log")
        ax.set_yscale("log")
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
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# Runs


def reference(cache: RenderCache, name: str, description: dict, files, settings: dict, scene_fn, spp: int,
              passes: int, label: str) -> np.ndarray:
    def make():
        return render_passes(scene_fn(), spp, spp_per_pass=passes, seed=REFERENCE_SEED, desc=label)

    return cache.get(name, description, files, settings, make)


def run_veach(args, artefacts: Artefacts, cache: RenderCache, out: Path, notes: list[str]) -> dict:
    setup = VeachSetup(args)
    levels = spp_levels(args.max_spp)
    specs = [m for m in args.materials.split(",") if m] + [f"rgl:{m}" for m in args.rgl.split(",") if m]
    results, representation, equal_time, per_material = [], [], [], {}
    tag = "" if setup.integrator == "bsdf" else f"-{setup.integrator}"  # keeps the two runs apart
    settings = {"spp": args.gt_spp, "resolution": list(setup.resolution), "integrator": "mis",
                "seed": REFERENCE_SEED, "spp_per_pass": args.spp_per_pass}
    for spec in tqdm(specs, desc="veach: materials", unit="material"):
        material: Material = artefacts.get(spec)
        for note in material.notes:
            notes.append(f"{material.name}: {note}")
        label = material.name
        # References: the ground truth and the converged NBRDF (same seeds: common random numbers).
        gt_bsdf = material.ground_truth_bsdf()
        ground_truth = reference(cache, f"veach-{label}-ground-truth", setup.description(gt_bsdf, "mis"),
                                 bsdf_files(gt_bsdf), settings, lambda: setup.load(gt_bsdf, "mis"),
                                 args.gt_spp, args.spp_per_pass, f"{label}: ground truth")
        ref_bsdf = material.nbrdf("phong" if material.has_phong else "cosine")
        nbrdf_ref = reference(cache, f"veach-{label}-nbrdf", setup.description(ref_bsdf, "mis"), bsdf_files(ref_bsdf),
                              settings, lambda: setup.load(ref_bsdf, "mis"), args.gt_spp, args.spp_per_pass,
                              f"{label}: converged NBRDF")
        mask_scene = setup.load({"type": "diffuse"})
        mask = setup.mask(mask_scene)
        rep = {"scene": "veach", "material": label, "kind": material.kind, "model": "nbrdf",
               "network": material.network_source, "spp": args.gt_spp, "region": "plates",
               **metrics.all_metrics(ground_truth, nbrdf_ref, mask),
               "relative_rmse": metrics.rmse(ground_truth, nbrdf_ref, mask) / float(np.sqrt(np.mean(ground_truth[mask] ** 2)))}
        representation.append(rep)
        if material.kind == "rgl":
            table_bsdf = material.table_bsdf("phong" if material.has_phong else None)
            table_ref = reference(cache, f"veach-{label}-table", setup.description(table_bsdf, "mis"),
                                  bsdf_files(table_bsdf), settings, lambda: setup.load(table_bsdf, "mis"),
                                  args.gt_spp, args.spp_per_pass, f"{label}: tabulated")
            representation.append({**rep, "model": "table", "network": "-", **metrics.all_metrics(ground_truth, table_ref, mask),
                                   "relative_rmse": metrics.rmse(ground_truth, table_ref, mask)
                                   / float(np.sqrt(np.mean(ground_truth[mask] ** 2)))})
        # Strategies.
        strategies = {}
        for strategy in STRATEGIES:
            if strategy in NBRDF_SAMPLING:
                if strategy == "phong-fit" and not material.has_phong:
                    continue
                bsdf = material.nbrdf(NBRDF_SAMPLING[strategy])
                strategies[strategy] = {"scene": setup.load(bsdf), "reference": nbrdf_ref, "reference_name": "nbrdf"}
            elif strategy == "measured" and material.measured is not None:
                bsdf = {"type": "measured", "filename": str(material.measured)}
                strategies[strategy] = {"scene": setup.load(bsdf), "reference": ground_truth,
                                        "reference_name": "measured"}
        save_dir = out / f"renders{tag}" / label
        save_spp = {levels[0], levels[len(levels) // 2], levels[-1]}
        rows = measure(strategies, levels, mask, ground_truth, label, save_dir, save_spp)
        write_exr(save_dir / "ground-truth.exr", ground_truth)
        write_exr(save_dir / "nbrdf-converged.exr", nbrdf_ref)
        write_png(save_dir / "ground-truth.png", ground_truth)
        write_png(save_dir / "nbrdf-converged.png", nbrdf_ref)
        for row in rows:
            row.update(scene="veach", material=label, integrator=setup.integrator, region="plates")
        results += rows
        per_material[label] = rows
        summary = equal_time_summary(rows)
        equal_time.append({"scene": "veach", "material": label, "kind": material.kind,
                           "exponent": material.exponent, "specular_weight": material.specular_weight,
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
    return {"results": results, "representation": representation, "equal_time": equal_time}


def run_kitchen(args, artefacts: Artefacts, cache: RenderCache, out: Path, notes: list[str]) -> dict:
    setup = KitchenSetup(args)
    module = setup.module
    names = sorted(set(setup.overrides["overrides"].values()))
    materials = {}
    for name in tqdm(names, desc="kitchen: materials", unit="material"):
        materials[name] = artefacts.get(name)
        for note in materials[name].notes:
            notes.append(f"{name}: {note}")
    has_phong = all(m.has_phong for m in materials.values())
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
    from render_utils import primary_hit_mask

    overridden = primary_hit_mask(probe, bsdf_ids=setup.overrides["overrides"].keys())
    rep = {"scene": "kitchen", "material": "14 overrides", "kind": "merl", "model": "nbrdf",
           "network": ",".join(sorted({m.network_source for m in materials.values()})), "spp": args.gt_spp,
           "region": "image", **metrics.all_metrics(ground_truth, nbrdf_ref),
           "relative_rmse": metrics.rmse(ground_truth, nbrdf_ref) / float(np.sqrt(np.mean(ground_truth ** 2)))}
    rep_overridden = {**rep, "region": "replaced materials", **metrics.all_metrics(ground_truth, nbrdf_ref, overridden),
                      "relative_rmse": metrics.rmse(ground_truth, nbrdf_ref, overridden)
                      / float(np.sqrt(np.mean(ground_truth[overridden] ** 2)))}
    strategies = {}
    for strategy in ("uniform", "cosine", "phong-fit"):
        if strategy == "phong-fit" and not has_phong:
            continue
        strategies[strategy] = {"scene": setup.load(bsdfs(NBRDF_SAMPLING[strategy])), "reference": nbrdf_ref,
                                "reference_name": "nbrdf"}
    save_dir = out / "renders" / "kitchen"
    rows = measure(strategies, levels, None, ground_truth, "kitchen", save_dir, {levels[0], levels[-1]})
    for row in rows:
        row.update(scene="kitchen", material="14 overrides", integrator="path", region="image")
    # Fireflies traceable to our BSDFs: the NBRDF and the table, Phong-sampled alike with the same
    # random numbers at the highest spp, counted against the ground truth.
    top = levels[-1]
    seed = 424242
    nbrdf_image, _ = timed_render(strategies["phong-fit" if has_phong else "cosine"]["scene"], top, seed=seed)
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
    plot_material(out / "plots" / "kitchen.png", "Kitchen (path tracing), 14 overrides replaced: error on the image",
                  rows, rep["rmse"])
    log("kitchen: " + ", ".join(f"{s} {v:.4g}" for s, v in summary["rmse"].items())
        + f" RMSE at {summary['seconds']:.2f} s; NBRDF vs ground truth RMSE {rep['rmse']:.4g}")
    return {"results": rows, "representation": [rep, rep_overridden],
            "equal_time": [{"scene": "kitchen", "material": "14 overrides", **summary}], "kitchen": checks}


# ---------------------------------------------------------------------------------------------
# Reports


def markdown(report: dict) -> str:
    lines = []
    scene = report["settings"]["scene"]
    if report["equal_time"]:
        strategies = [s for s in STRATEGIES if any(s in e["rmse"] for e in report["equal_time"])]
        lines += [f"RMSE (sampling error{', plates only' if scene == 'veach' else ''}) at equal render time "
                  f"({report['settings']['integrator_label']}, {report['settings']['resolution'][0]}x"
                  f"{report['settings']['resolution'][1]}):", ""]
        header = "| material | Phong n, w | time (s) | " + " | ".join(strategies) + " | phong-fit / cosine | phong-fit / uniform |"
        lines += [header, "|" + "---|" * (header.count("|") - 1)]
        for e in report["equal_time"]:
            r = e["rmse"]
            phong = e.get("exponent")
            lobe = f"{phong:.3g}, {e['specular_weight']:.2f}" if phong is not None else "-"
            cells = [f"{r[s]:.4g}" if s in r else "-" for s in strategies]
            ratio_c = f"{r['phong-fit'] / r['cosine']:.2f}" if "phong-fit" in r and "cosine" in r else "-"
            ratio_u = f"{r['phong-fit'] / r['uniform']:.3f}" if "phong-fit" in r and "uniform" in r else "-"
            lines.append(f"| {e['material']} | {lobe} | {e['seconds']:.2f} | " + " | ".join(cells)
                         + f" | {ratio_c} | {ratio_u} |")
        lines.append("")
    if report["representation"]:
        lines += [f"Representation error against the ground truth ({report['settings']['gt_spp']} spp, MIS/path, "
                  "same random numbers):", "",
                  "| material | model | network | region | MAE | RMSE | relative RMSE | MAPE | PSNR (dB) |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for r in report["representation"]:
            lines.append(f"| {r['material']} | {r['model']} | {r['network']} | {r['region']} | {r['mae']:.4g} | "
                         f"{r['rmse']:.4g} | {r['relative_rmse']:.3f} | {r['mape']:.4g} | {r['psnr']:.1f} |")
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
    keys = ["scene", "material", "strategy", "spp", "seconds", "mae", "rmse", "mape", "psnr"]
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
    parser.add_argument("--rgl", default=",".join(VEACH_RGL),
                        help="comma-separated RGL materials (../shared/data/rgl/NAME.bsdf) for the Veach scene; "
                             "empty for none (default: %(default)s)")
    parser.add_argument("--integrator", choices=["bsdf", "mis"], default="bsdf",
                        help="Veach: bsdf = pure BSDF sampling (direct, emitter_samples = 0), mis = MIS")
    parser.add_argument("--width", type=int, help="image width (Veach: 384, kitchen: from kitchen_materials.json)")
    parser.add_argument("--height", type=int, help="image height (default: 2/3 of the width, kitchen 9/16)")
    parser.add_argument("--max-spp", type=int, default=128, help="highest spp of the series 1, 2, 4, ...")
    parser.add_argument("--gt-spp", type=int, default=1024, help="spp of the ground truths and references")
    parser.add_argument("--spp-per-pass", type=int, default=64, help="spp per pass of the reference renders")
    parser.add_argument("--max-depth", type=int, help="kitchen: path length (default from kitchen_materials.json)")
    parser.add_argument("--kitchen", help="kitchen scene.xml or its folder (default ../shared/scenes/kitchen)")
    parser.add_argument("--kitchen-materials", default=str(REPO / "scenes" / "kitchen_materials.json"),
                        help="the override description")
    parser.add_argument("--train-args", default="", help="extra arguments of `nbrdf train`, e.g. '--epochs 30'")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--quick", action="store_true",
                        help="tiny images, few samples, one material, briefly trained networks (CI, checks)")
    parser.add_argument("--json", type=Path, help="write the results as JSON here as well")
    parser.add_argument("--out", type=Path, help="output folder (default out/convergence, quick: out/convergence-quick)")
    parser.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf command-line tool")
    parser.add_argument("--force", action="store_true", help="re-render cached references")
    parser.add_argument("--replot", action="store_true",
                        help="only redraw the plots and the summary of the last run's JSON (same --scene, --out, "
                             "--integrator)")
    args = parser.parse_args(argv)

    train_args = args.train_args.split()
    if args.quick:
        args.max_spp = min(args.max_spp, 4)
        args.gt_spp = min(args.gt_spp, 32)
        if args.scene == "veach":
            args.width = args.width or 64
            args.height = args.height or 43
            args.materials = args.materials if args.materials != ",".join(VEACH_MERL) else "blue-metallic-paint"
            args.rgl = args.rgl if args.rgl != ",".join(VEACH_RGL) else ""
        else:
            args.width = args.width or 48
            args.height = args.height or 27
            args.max_spp = min(args.max_spp, 2)
            args.gt_spp = min(args.gt_spp, 8)
            args.max_depth = args.max_depth or 3
        train_args = train_args or QUICK_TRAIN_ARGS
    if args.scene == "veach":
        args.width = args.width or 384
    out = args.out or REPO / "out" / ("convergence-quick" if args.quick else "convergence")
    scene_out = out / args.scene
    scene_out.mkdir(parents=True, exist_ok=True)
    suffix = "" if args.scene == "kitchen" or args.integrator == "bsdf" else "-mis"
    if args.replot:
        report = json.loads((scene_out / f"convergence{suffix}.json").read_text())
        replot(report, scene_out)
        (scene_out / f"summary{suffix}.md").write_text(markdown(report))
        print(markdown(report))
        return 0

    mi.set_variant(args.variant)
    nbrdf_mitsuba.register()
    artefacts = Artefacts(out if args.quick else REPO / "out", args.cli, train_args=train_args, log=log)
    cache = RenderCache(out / "references" if args.quick else REPO / "out" / "references", force=args.force)
    notes = []
    if artefacts.can_train():
        notes.append(f"NBRDFs trained with `nbrdf train` on the tables ({' '.join(train_args) or 'default recipe'})")
    else:
        notes.append("NBRDFs imported from the authors' Keras networks (`nbrdf train` is not available)")
    if not artefacts.can_fit_phong():
        notes.append("Blinn-Phong lobes: `nbrdf fit-phong` is not available, phong-fit skipped")
    if artefacts.predictor() is None:
        message = "phong-predicted skipped: no Blinn-Phong parameter predictor exists yet (the latent-space issue is not done)"
        print(f"note: {message}")
        notes.append(message)

    start = time.perf_counter()
    if args.scene == "veach":
        report = run_veach(args, artefacts, cache, scene_out, notes)
        resolution = VeachSetup(args).resolution
        integrator_label = "pure BSDF sampling" if args.integrator == "bsdf" else "MIS"
    else:
        report = run_kitchen(args, artefacts, cache, scene_out, notes)
        resolution = KitchenSetup(args).resolution
        integrator_label = "path tracing"
    report["notes"] = notes
    report["settings"] = {"scene": args.scene, "resolution": list(resolution), "max_spp": args.max_spp,
                          "gt_spp": args.gt_spp, "integrator": args.integrator if args.scene == "veach" else "path",
                          "integrator_label": integrator_label, "variant": args.variant, "quick": args.quick,
                          "train_args": train_args, "seconds": round(time.perf_counter() - start, 1),
                          "metrics": "MAE, RMSE, MAPE (eps 0.01), PSNR (peak 1) on linear RGB",
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
