"""Rendering the convergence series: the scenes, the references (cached), every strategy at every
spp level and seed, timed, for the Veach scene and the kitchen."""

from __future__ import annotations

import itertools
from pathlib import Path

import nbrdf_mitsuba  # noqa: F401  first: finds a libLLVM for Dr.Jit before Mitsuba starts its JIT
import numpy as np

from nbrdf_tools.common import cli, metrics
from nbrdf_tools.common import network as nbrdf_network
from nbrdf_tools.pages.scenes.metrics import cost_floor, equal_time_summary, representation_metrics, timing_repeats
from nbrdf_tools.pages.scenes.report import plot_material, plot_overview
from nbrdf_tools.pages.scenes.strategies import COST_FLOOR_BSDF, NBRDF_SAMPLING, STRATEGIES, kitchen_skip_reason
from nbrdf_tools.common.ground_truth import RenderCache, file_hash
from nbrdf_tools.common.materials import Artefacts, Material
from nbrdf_tools.common.paths import MissingDataError
from nbrdf_tools.common.progress import bar, log
from nbrdf_tools.common.render import primary_hit_mask, render_passes, timed_render, warm_up, write_exr, write_png

REFERENCE_SEED = 1_000_000  # references use seeds from here on; test renders stay far below

QUICK_TRAIN_ARGS = ["--samples", "40000", "--epochs", "3", "--min-epochs", "1"]


# ---------------------------------------------------------------------------------------------
# Scenes


class VeachSetup:
    name = "veach"

    def __init__(self, args):
        from nbrdf_tools.common.scenes.veach import VEACH_XML

        self.resolution = (args.width, args.height or round(args.width * 2 / 3))
        self.integrator = args.integrator
        self.xml = VEACH_XML

    def load(self, bsdf: dict, integrator: str | None = None):
        from nbrdf_tools.common.scenes.veach import load_veach_xml

        return load_veach_xml(bsdf, integrator=integrator or self.integrator, resolution=self.resolution)

    def mask(self, scene):
        from nbrdf_tools.common.scenes.veach import plate_mask

        return plate_mask(scene)

    def description(self, bsdf: dict, integrator: str) -> dict:
        return {"scene": "veach", "xml": file_hash(self.xml), "plates": bsdf, "integrator": integrator,
                "resolution": list(self.resolution)}


class KitchenSetup:
    name = "kitchen"

    def __init__(self, args):
        from nbrdf_tools.common.scenes import kitchen

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


def render_seed(level_index: int, scene_index: int, seed_index: int) -> int:
    """The seed of one render of a series: distinct per spp level, scene and repetition (seed
    index 0 keeps the random numbers of single-seed runs)."""
    return 1000 * (level_index + 1) + scene_index + 100_000 * seed_index


def fastest_render(scene, spp: int, seed: int, repeat: bool = True) -> tuple[np.ndarray, float]:
    """(image, seconds): short renders are timed again (same seed, same image) and the fastest
    run kept, since other processes on the machine disturb short timings the most; with
    ``repeat`` False (``--quick``, whose timings are not figures) each is rendered once."""
    image, seconds = timed_render(scene, spp, seed=seed)
    for _ in range(timing_repeats(spp) - 1 if repeat else 0):
        seconds = min(seconds, timed_render(scene, spp, seed=seed)[1])
    return image, seconds


def measure(strategies: dict, levels: list[int], mask, ground_truth, label: str, save_dir: Path | None,
            save_spp: set[int], seeds: int = 1, timing_only: dict | None = None,
            timings: list[dict] | None = None, repeat_timings: bool = True) -> list[dict]:
    """Renders every strategy at every spp level, ``seeds`` times with independent random numbers
    (interleaved, so that machine load hits them alike), and measures each against its reference
    and against the ground truth. Rows carry the seed's index (``seed``). The scenes of
    ``timing_only`` (name: scene) are rendered in the same interleaved order and only timed, into
    ``timings`` (rows of strategy, spp, seed and seconds); ``repeat_timings``: see
    :func:`fastest_render`."""
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
                                                render_seed(level_index, strategy_index, seed_index),
                                                repeat_timings)
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
                _, seconds = fastest_render(scene, spp, seed, repeat_timings)
                timings.append({"strategy": name, "spp": spp, "seed": seed_index, "seconds": seconds})
                renders.update()
    return rows


def material_specs(args) -> list[str]:
    """The Veach materials: MERL names, then RGL ones as ``rgl:NAME`` or ``.bsdf`` paths."""
    rgl = [m if m.endswith(".bsdf") else f"rgl:{m}" for m in (args.rgl or "").split(",") if m]
    return [m for m in args.materials.split(",") if m] + rgl


def stored_default_sampling(network: Path) -> str | None:
    """The network file's ``sampling.default`` (what the plugin samples with when the scene names
    no ``sampling``), None when it names none."""
    try:
        sampling = nbrdf_network.sampling_of(Path(network))
    except (OSError, ValueError):
        return None
    return sampling.get("default")


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
    sampling = nbrdf_network.read_document(target)["sampling"]
    return float(sampling["exponent"]), float(sampling["specular_weight"])


def _veach_references(args, setup: VeachSetup, cache: RenderCache, material: Material, settings: dict):
    """(ground truth, converged NBRDF, the scene with diffuse plates, the plates' mask, the
    representation rows). Both references use the same seeds: common random numbers."""
    label = material.name

    def converged(name: str, bsdf: dict, what: str) -> np.ndarray:
        return reference(cache, f"veach-{label}-{name}", setup.description(bsdf, "mis"), bsdf_files(bsdf), settings,
                         lambda: setup.load(bsdf, "mis"), args.gt_spp, args.spp_per_pass, f"{label}: {what}")

    ground_truth = converged("ground-truth", material.ground_truth_bsdf(), "ground truth")
    nbrdf_ref = converged("nbrdf", material.nbrdf("phong" if material.has_phong else "cosine"), "converged NBRDF")
    mask_scene = setup.load({"type": "diffuse"})
    mask = setup.mask(mask_scene)
    rep = {"scene": "veach", "material": label, "kind": material.kind, "model": "nbrdf",
           "network": material.network_source, "spp": args.gt_spp, "region": "plates",
           **representation_metrics(ground_truth, nbrdf_ref, mask)}
    representation = [rep]
    if material.kind == "rgl":
        table_ref = converged("table", material.table_bsdf("phong" if material.has_phong else None), "tabulated")
        representation.append({**rep, "model": "table", "network": "-",
                               **representation_metrics(ground_truth, table_ref, mask)})
    return ground_truth, nbrdf_ref, mask_scene, mask, representation


def _veach_strategies(args, setup: VeachSetup, material: Material, out: Path, ground_truth, nbrdf_ref,
                      predicted_lobes: dict) -> dict:
    """The scenes to render, by strategy, with the reference each is measured against: those of
    ``--strategies`` the material has what they sample with."""
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
                predicted_lobes[material.name] = lobe
            bsdf = material.nbrdf(NBRDF_SAMPLING[strategy], **extra)
            strategies[strategy] = {"scene": setup.load(bsdf), "reference": nbrdf_ref, "reference_name": "nbrdf"}
        elif strategy == "measured" and material.measured is not None:
            bsdf = {"type": "measured", "filename": str(material.measured)}
            strategies[strategy] = {"scene": setup.load(bsdf), "reference": ground_truth,
                                    "reference_name": "measured"}
    return strategies


def _veach_equal_time(material: Material, rows: list[dict], timings: list[dict], predicted_lobes: dict) -> dict:
    """The material's row of the equal-time summary: its lobes and the strategies' errors."""
    label = material.name
    summary = equal_time_summary(rows)
    floor_summary = cost_floor(rows, timings)
    if floor_summary is not None:
        summary["cost_floor"] = floor_summary
    return {"scene": "veach", "material": label, "kind": material.kind,
            "exponent": material.exponent, "specular_weight": material.specular_weight,
            "two_lobe_exponents": material.two_lobe_exponents,
            "two_lobe_weights": material.two_lobe_weights,
            "default_sampling": stored_default_sampling(material.network),
            **({"predicted_exponent": predicted_lobes[label][0],
                "predicted_specular_weight": predicted_lobes[label][1]}
               if label in predicted_lobes else {}),
            **summary}


def _veach_material(args, setup: VeachSetup, material: Material, cache: RenderCache, out: Path, settings: dict,
                    predicted_lobes: dict) -> dict:
    """One material's references, renders, plot and summary: ``rows``, ``representation``,
    ``equal_time`` (one entry) and ``timings``."""
    label = material.name
    levels = spp_levels(args.max_spp)
    tag = "" if setup.integrator == "bsdf" else f"-{setup.integrator}"  # keeps the two runs apart
    ground_truth, nbrdf_ref, mask_scene, mask, representation = _veach_references(args, setup, cache, material,
                                                                                  settings)
    strategies = _veach_strategies(args, setup, material, out, ground_truth, nbrdf_ref, predicted_lobes)
    save_dir = out / f"renders{tag}" / label
    save_spp = {levels[0], levels[len(levels) // 2], levels[-1]}
    # Beside measured, the plates in a BSDF that costs next to nothing: the scene's share of a
    # render, which bounds what any BSDF can gain on measured at equal time (cost_floor).
    floor = {COST_FLOOR_BSDF: mask_scene} if "measured" in strategies else {}
    timings = []
    rows = measure(strategies, levels, mask, ground_truth, label, save_dir, save_spp, args.seeds,
                   timing_only=floor, timings=timings, repeat_timings=not args.quick)
    for row in timings:
        row.update(scene="veach", material=label, integrator=setup.integrator)
    write_exr(save_dir / "ground-truth.exr", ground_truth)
    write_exr(save_dir / "nbrdf-converged.exr", nbrdf_ref)
    write_png(save_dir / "ground-truth.png", ground_truth)
    write_png(save_dir / "nbrdf-converged.png", nbrdf_ref)
    for row in rows:
        row.update(scene="veach", material=label, integrator=setup.integrator, region="plates")
    equal_time = _veach_equal_time(material, rows, timings, predicted_lobes)
    rep = representation[0]
    plot_material(out / "plots" / f"veach{tag}-{label}.png",
                  f"Veach ({'pure BSDF sampling' if setup.integrator == 'bsdf' else 'MIS'}), {label}: "
                  f"error on the plates", rows, rep["rmse"])
    log(f"{label}: " + ", ".join(f"{s} {v:.4g}" for s, v in equal_time["rmse"].items())
        + f" RMSE at {equal_time['seconds']:.2f} s; NBRDF vs ground truth RMSE {rep['rmse']:.4g}")
    return {"rows": rows, "representation": representation, "equal_time": equal_time, "timings": timings}


def run_veach(args, artefacts: Artefacts, cache: RenderCache, out: Path, notes: list[str]) -> dict:
    setup = VeachSetup(args)
    tag = "" if setup.integrator == "bsdf" else f"-{setup.integrator}"
    settings = {"spp": args.gt_spp, "resolution": list(setup.resolution), "integrator": "mis",
                "seed": REFERENCE_SEED, "spp_per_pass": args.spp_per_pass}
    results, representation, equal_time, timings, per_material, predicted_lobes = [], [], [], [], {}, {}
    for spec in bar(material_specs(args), desc="veach: materials", unit="material"):
        material: Material = artefacts.get(spec)
        notes += [f"{material.name}: {note}" for note in material.notes]
        done = _veach_material(args, setup, material, cache, out, settings, predicted_lobes)
        results += done["rows"]
        representation += done["representation"]
        equal_time.append(done["equal_time"])
        timings += done["timings"]
        per_material[material.name] = done["rows"]
    plot_overview(out / "plots" / f"veach{tag}-overview.png",
                  f"Veach scene, {'pure BSDF sampling' if setup.integrator == 'bsdf' else 'MIS'}: RMSE on the plates "
                  "against render time", per_material)
    return {"results": results, "representation": representation, "equal_time": equal_time, "timings": timings}


def default_counts(defaults: dict[str, str | None]) -> str:
    """The stored defaults of several materials as one cell, e.g. ``tabulated x9, cosine x4``."""
    counts: dict[str, int] = {}
    for default in defaults.values():
        counts[default or "none"] = counts.get(default or "none", 0) + 1
    return ", ".join(f"{d} x{n}" for d, n in sorted(counts.items(), key=lambda item: (-item[1], item[0])))


def _kitchen_materials(setup: KitchenSetup, artefacts: Artefacts, notes: list[str]) -> dict[str, Material]:
    materials = {}
    for name in bar(sorted(set(setup.overrides["overrides"].values())), desc="kitchen: materials", unit="material"):
        materials[name] = artefacts.get(name)
        notes += [f"{name}: {note}" for note in materials[name].notes]
    return materials


def _kitchen_strategies(args, setup: KitchenSetup, bsdfs, nbrdf_ref, has_phong: bool, has_two_lobes: bool,
                        notes: list[str]) -> dict:
    """The scenes to render, by strategy (each against the converged NBRDF); why others are skipped
    goes to ``notes``."""
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
    return strategies


def _kitchen_checks(top: int, images: dict[str, np.ndarray], ground_truth, nbrdf_ref, rows: list[dict],
                    overridden: np.ndarray) -> dict:
    """Non-finite pixels and fireflies of the NBRDF's and the table's render (``images``: nbrdf,
    merl) against the ground truth."""
    nbrdf_image, table_image = images["nbrdf"], images["merl"]
    return {
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


def run_kitchen(args, artefacts: Artefacts, cache: RenderCache, out: Path, notes: list[str]) -> dict:
    setup = KitchenSetup(args)
    module = setup.module
    materials = _kitchen_materials(setup, artefacts, notes)
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
    overridden = primary_hit_mask(setup.load(ref_bsdfs), bsdf_ids=setup.overrides["overrides"].keys())
    rep = {"scene": "kitchen", "material": label, "kind": "merl", "model": "nbrdf",
           "network": ",".join(sorted({m.network_source for m in materials.values()})), "spp": args.gt_spp,
           "region": "image", **representation_metrics(ground_truth, nbrdf_ref)}
    rep_overridden = {**rep, "region": "replaced materials",
                      **representation_metrics(ground_truth, nbrdf_ref, overridden)}
    strategies = _kitchen_strategies(args, setup, bsdfs, nbrdf_ref, has_phong, has_two_lobes, notes)
    save_dir = out / "renders" / "kitchen"
    rows = measure(strategies, levels, None, ground_truth, "kitchen", save_dir, {levels[0], levels[-1]}, args.seeds,
                   repeat_timings=not args.quick)
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
    checks = _kitchen_checks(top, {"nbrdf": nbrdf_image, "merl": table_image}, ground_truth, nbrdf_ref, rows,
                             overridden)
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
