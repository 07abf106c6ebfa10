"""The measuring run of the neural-textures page: every selected source, then the kitchen."""

from __future__ import annotations

import json
import os
import platform
from pathlib import Path

import numpy as np

from nbrdf_tools.common.progress import bar

from . import measure
from .sources import Source, bsdf, measurement_path, select

VARIANT = "llvm_ad_rgb"
#: The kitchen's textured BSDFs replaced by their neural textures in the kitchen comparison.
KITCHEN_BSDFS = ("TabletopBSDF", "SmallWorktopBSDF", "ChoppingBoardBSDF")
REFERENCE_SEED = 1000
#: The source converted at several texture sizes for the conversion-time table (a test source).
SCALING_SOURCE = "principled-wood"
SCALING_RESOLUTIONS = (256, 1024)
QUICK = {"resolution": 16, "size": 64, "spp": 8, "repeats": 1, "chi2_samples": 20_000,
         "distill": ["--samples", "20000", "--epochs", "3"]}


def settings_of(args) -> dict:
    settings = {"resolution": args.resolution, "channels": args.channels, "size": args.size, "spp": args.spp,
                "repeats": args.repeats, "chi2_samples": 1_000_000, "distill": [], "variant": VARIANT,
                "reference_factor": measure.REFERENCE_SPP_FACTOR, "quick": args.quick}
    if args.quick:
        settings.update(QUICK)
    return settings


def measure_all(args, figures: Path) -> dict:
    import nbrdf_mitsuba  # noqa: F401  (finds a libLLVM before Mitsuba's JIT starts)
    import mitsuba as mi

    mi.set_variant(VARIANT)
    settings = settings_of(args)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    sources = select(args.subset, args.sources)
    results, pictures = [], {}
    for source in bar(sources, desc="neural textures", unit="source"):
        result, images = measure_source(source, work / source.name, settings)
        results.append(result)
        pictures[source.name] = images
    data = {"settings": settings, "sources": results, "machine": machine()}
    _figure(pictures, figures / "neural-textures" / "sources.png")
    if not args.quick:
        data["scaling"] = conversion_by_size(work, settings)
    if not (args.no_kitchen or args.quick):
        data["kitchen"] = measure_kitchen(work / "kitchen", settings, figures / "neural-textures" / "kitchen.png")
    return data


def machine() -> str:
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"


def measure_source(source: Source, work: Path, settings: dict) -> tuple[dict, dict]:
    import mitsuba as mi

    mi.set_variant(VARIANT)
    work.mkdir(parents=True, exist_ok=True)
    source_bsdf = bsdf(source, work)
    source_file = work / "source.json"
    source_file.write_text(json.dumps(source_bsdf, indent=1))
    material = work / f"{source.name}.nbrdf.json"
    conversion = converted(source_file, material, settings)
    neural = {"type": "nbrdf", "filename": str(material)}
    size, spp = settings["size"], settings["spp"]
    reference = measure.render_image(source_bsdf, size, spp)
    images = {"neural": measure.render_image(neural, size, spp)}
    timed = {"source": source_bsdf, "neural": neural, "roughconductor": measure.ROUGHCONDUCTOR}
    if source.kind == "blend":
        route = per_material_route(source_bsdf, source, work.parent / "measurements", settings)
        images["per_material"] = measure.render_image(route, size, spp)
        timed["per_material"] = route
    errors = {k: measure.errors(reference, image) for k, image in images.items()}
    images["reference"] = reference
    memory = {**measure.neural_bytes(material), "source": measure.source_texture_bytes(source_bsdf)}
    result = {"name": source.name, "subset": source.subset, "kind": source.kind, "resolution": settings["resolution"],
              "channels": json.loads(material.read_text())["latent"]["channels"],
              "conversion_seconds": conversion["seconds"], "errors": errors, "memory": memory,
              "mrays_per_s": measure.rays_per_second(timed, size, spp, settings["repeats"]),
              "chi2": measure.chi2_at_texels(material, VARIANT, settings["chi2_samples"])}
    return result, images


def converted(source_file: Path, material: Path, settings: dict) -> dict:
    """The conversion of ``source_file``, run once per work folder and settings (kept beside the
    material, so an interrupted or repeated run reuses it)."""
    record = material.with_suffix(".conversion.json")
    asked = {"source": source_file.read_text(), "resolution": settings["resolution"],
             "channels": settings["channels"], "distill": settings["distill"]}
    if record.is_file() and material.is_file():
        kept = json.loads(record.read_text())
        if kept["asked"] == asked:
            return kept["conversion"]
    conversion = measure.distill(source_file, material, settings["resolution"], settings["channels"],
                                 settings["distill"])
    record.write_text(json.dumps({"asked": asked, "conversion": conversion}))
    return conversion


def conversion_by_size(work: Path, settings: dict) -> list[dict]:
    """Conversion seconds and sizes of :data:`SCALING_SOURCE` at each of
    :data:`SCALING_RESOLUTIONS` (the page's own resolution reuses its conversion)."""
    (source,) = select("all", [SCALING_SOURCE])
    rows = []
    for resolution in SCALING_RESOLUTIONS:
        folder = work / (source.name if resolution == settings["resolution"] else f"{source.name}-{resolution}")
        folder.mkdir(parents=True, exist_ok=True)
        source_file = folder / "source.json"
        source_file.write_text(json.dumps(bsdf(source, folder), indent=1))
        material = folder / f"{source.name}.nbrdf.json"
        conversion = converted(source_file, material, {**settings, "resolution": resolution})
        rows.append({"name": source.name, "resolution": resolution, "seconds": conversion["seconds"],
                     "memory": measure.neural_bytes(material)})
    return rows


def per_material_route(source_bsdf: dict, source: Source, folder: Path, settings: dict) -> dict:
    """The blend over per-material networks of its two measurements (distilled once, kept)."""
    folder.mkdir(parents=True, exist_ok=True)
    children = {}
    for key, name in zip(("bsdf_0", "bsdf_1"), source.measurements):
        network = folder / f"{name}.nbrdf.json"
        if not network.is_file():
            measure.distill_homogeneous(measurement_path(name), network, settings["distill"])
        children[key] = {"type": "nbrdf", "filename": str(network)}
    return {**source_bsdf, **children}


def measure_kitchen(work: Path, settings: dict, figure: Path) -> dict:
    """The kitchen rendered as it is and with :data:`KITCHEN_BSDFS` replaced by neural textures,
    both against a reference render of the original."""
    from nbrdf_tools.common.render import render_passes
    from nbrdf_tools.common.scenes.kitchen import load_kitchen

    from .sources import kitchen_bsdf

    work.mkdir(parents=True, exist_ok=True)
    replaced, seconds = {}, {}
    for bsdf_id in KITCHEN_BSDFS:
        source_file = work / f"{bsdf_id}.json"
        source_file.write_text(json.dumps(kitchen_bsdf(bsdf_id), indent=1))
        material = work / f"{bsdf_id}.nbrdf.json"
        seconds[bsdf_id] = converted(source_file, material, settings)["seconds"]
        replaced[bsdf_id] = {"type": "nbrdf", "filename": str(material)}
    size = {"resx": 2 * settings["size"], "resy": 2 * settings["size"] * 9 // 16}
    spp = settings["spp"]
    reference = render_passes(load_kitchen(None, spp=spp, **size), spp * measure.REFERENCE_SPP_FACTOR,
                              seed=REFERENCE_SEED, progress=False)
    original = render_passes(load_kitchen(None, spp=spp, **size), spp, progress=False)
    neural = render_passes(load_kitchen(replaced, spp=spp, **size), spp, progress=False)
    _figure({"kitchen": {"reference": reference, "original": original, "neural": neural}}, figure,
            ("original", "neural", "error"))
    return {"replaced": list(KITCHEN_BSDFS), "conversion_seconds": seconds,
            "errors": {"original (noise floor)": measure.errors(reference, original),
                       "neural textures": measure.errors(reference, neural)}}


def _figure(pictures: dict[str, dict], path: Path,
            columns: tuple[str, ...] = ("reference", "neural", "per_material", "error")) -> Path:
    """One row per source: its reference, the neural texture, the per-material route where there
    is one, and the neural texture's error (tone-mapped absolute difference, x4)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from nbrdf_tools.common.metrics import tone_map

    fig, axes = plt.subplots(len(pictures), len(columns), figsize=(3.2 * len(columns), 2.5 * len(pictures)),
                             squeeze=False)
    for row, (name, images) in zip(axes, pictures.items()):
        shown = {**images, "error": 4 * np.abs(tone_map(images["neural"]) - tone_map(images["reference"]))}
        for ax, column in zip(row, columns):
            ax.axis("off")
            if column in shown:
                image = shown[column] if column == "error" else tone_map(shown[column])
                ax.imshow(np.clip(image, 0, 1))
                ax.set_title(f"{name}: {column.replace('_', '-')}", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path

