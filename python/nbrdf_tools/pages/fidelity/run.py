"""The fidelity rows of a material: NBRDFs trained (or distilled) at each width, analytic fits,
the reference rows; each cached in OUT/rows/MATERIAL/NAME.json with the settings it was made with."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from nbrdf_tools.common import cli
from nbrdf_tools.common import network as nbrdf_network
from nbrdf_tools.pages.fidelity.metrics import Reference
from nbrdf_tools.pages.fidelity.settings import (ANISOTROPIC_MODELS, FITS_VERSION, FRAME_TURNS_DEG, Material, Settings,
                                                weight_count)


class RowCache:
    def __init__(self, out: Path):
        self.folder = out / "rows"

    def path(self, material: Material, name: str) -> Path:
        return self.folder / material.group / material.name / f"{name}.json"

    def get(self, material: Material, name: str, key: dict) -> dict | None:
        try:
            row = json.loads(self.path(material, name).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return row if row.get("key") == key else None

    def put(self, material: Material, name: str, row: dict) -> dict:
        path = self.path(material, name)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(row, indent=1) + "\n", encoding="utf-8")
        return row


def _base_row(material: Material, kind: str, method: str, label: str, key: dict) -> dict:
    return {"material": material.name, "source": material.source, "group": material.group, "kind": kind,
            "method": method, "label": label, "key": key}


def nbrdf_row(material: Material, hidden: int, sampling: str, settings: Settings, reference, out: Path,
              nbrdf: Path, threads: int | None, cache: RowCache) -> dict:
    from nbrdf_tools.common import compare_materials as cm

    name = f"nbrdf-{sampling}-h{hidden}"
    key = {**settings.training_key(), **settings.metric_key(), "hidden": hidden, "sampling": sampling,
           "input": str(material.path)}
    row = cache.get(material, name, key)
    if row is not None:
        return row
    network = out / "networks" / material.group / f"{material.name}.{sampling}.h{hidden}.nbrdf.json"
    network.parent.mkdir(parents=True, exist_ok=True)
    cmd = [nbrdf, "train", material.path, "-o", network, "--hidden", hidden, "--sampling", sampling,
           "--seed", settings.seed, "--quiet"]
    if settings.samples is not None:
        cmd += ["--samples", settings.samples]
    if settings.epochs is not None:
        cmd += ["--epochs", settings.epochs]
    if threads is not None:
        cmd += ["--threads", threads]
    start = time.perf_counter()
    cli.run(cmd)
    wall = time.perf_counter() - start
    provenance = json.loads(network.read_text(encoding="utf-8"))["provenance"]
    row = _base_row(material, "nbrdf", name, f"NBRDF {sampling}, {weight_count(hidden)} weights", key)
    row.update(hidden=hidden, sampling=sampling, stored_values=weight_count(hidden),
               memory_bytes=4 * weight_count(hidden), file_bytes=network.stat().st_size,
               seconds=provenance["seconds"], wall_seconds=wall, epochs=provenance["epochs"],
               best_epoch=provenance["best_epoch"], network=str(network.relative_to(out)))
    row["metrics"] = reference.measure(cm.load_bsdf(network))
    return cache.put(material, name, row)


def fit_row(material: Material, model_name: str, data, settings: Settings, reference, cache: RowCache) -> dict:
    from nbrdf_tools.common import analytic_fit as af

    key = {**settings.metric_key(), "fit_samples": settings.fit_samples, "seed": settings.seed,
           "input": str(material.path), "fits": FITS_VERSION}
    if material.group == "anisotropic":
        key.update(turns=list(FRAME_TURNS_DEG), spec=material.spec)
    row = cache.get(material, model_name, key)
    if row is not None:
        return row
    model = af.MODELS[model_name]()
    fit = af.fit_model(model, data)
    stored = af.STORED_PARAMETERS[model_name]
    row = _base_row(material, "fit", model_name, model.label, key)
    row.update(stored_values=stored, memory_bytes=4 * stored, file_bytes=None, seconds=fit.seconds,
               fit=fit.to_json(), notes=model.notes,
               rendered_by=("Mitsuba plugin" if model_name in ("roughconductor", "roughconductor_aniso", "roughplastic")
                            else "NumpyBSDF"))
    row["metrics"] = reference.measure(af.mitsuba_bsdf(model_name, fit.x))
    return cache.put(material, model_name, row)


def reference_rows(material: Material, settings: Settings, reference, out: Path, cache: RowCache) -> list[dict]:
    """The measurement itself (the reference: no error) and the MERL table."""
    from nbrdf_tools.common import compare_materials as cm

    rows = []
    if material.source == "rgl":
        row = _base_row(material, "reference", "measured", "Mitsuba `measured` (the reference)", {})
        row.update(stored_values=None, memory_bytes=material.path.stat().st_size,
                   file_bytes=material.path.stat().st_size, seconds=None, metrics=None)
        rows.append(row)
        if settings.tabulate:
            key = {**settings.metric_key(), "input": str(material.path), "fold": "reciprocal"}
            row = cache.get(material, "merl-table", key)
            if row is None:
                table = out / "tables" / f"{material.name}.binary"
                table.parent.mkdir(parents=True, exist_ok=True)
                start = time.perf_counter()
                cli.run([sys.executable, "-m", "nbrdf_mitsuba.tabulate_rgl", material.path, "-o", table,
                         "--phi-fold", "reciprocal"])
                seconds = time.perf_counter() - start
                row = _base_row(material, "reference", "merl-table", "MERL table (`merl` BSDF)", key)
                row.update(stored_values=3 * 90 * 90 * 180, memory_bytes=table.stat().st_size,
                           file_bytes=table.stat().st_size, seconds=seconds)
                row["metrics"] = reference.measure(cm.load_bsdf(table))
                cache.put(material, "merl-table", row)
                table.unlink()  # 35 MB, remade in seconds
            rows.append(row)
    else:
        row = _base_row(material, "reference", "merl-table", "MERL table (`merl` BSDF, the reference)", {})
        row.update(stored_values=3 * 90 * 90 * 180, memory_bytes=material.path.stat().st_size,
                   file_bytes=material.path.stat().st_size, seconds=None, metrics=None)
        rows.append(row)
    return rows


def distilled_row(material: Material, anisotropic: bool, settings: Settings, reference, out: Path,
                  threads: int | None, cache: RowCache) -> dict:
    """An NBRDF of the table's width distilled from the material by :mod:`nbrdf_mitsuba.distill`
    (``--anisotropy on`` or ``off``)."""
    from nbrdf_mitsuba import distill

    from nbrdf_tools.common import compare_materials as cm

    hidden = settings.table_hidden
    kind = "aniso" if anisotropic else "iso"
    name = f"nbrdf-{kind}-h{hidden}"
    key = {**settings.training_key(), **settings.metric_key(), "hidden": hidden, "anisotropic": anisotropic,
           "input": str(material.path), "spec": material.spec, "turns": list(FRAME_TURNS_DEG)}
    row = cache.get(material, name, key)
    if row is not None:
        return row
    network = out / "networks" / material.group / f"{material.name}.{kind}.h{hidden}.nbrdf.json"
    network.parent.mkdir(parents=True, exist_ok=True)
    argv = [str(material.path), "-o", str(network), "-q", "--anisotropy", "on" if anisotropic else "off",
            "--hidden", str(hidden), "--seed", str(settings.seed)]
    for option, value in (("--samples", settings.samples), ("--epochs", settings.epochs), ("--threads", threads)):
        if value is not None:
            argv += [option, str(value)]
    start = time.perf_counter()
    try:
        summary = distill.distill(distill.parser().parse_args(argv))
    except distill.DistillError as error:
        raise RuntimeError(f"distilling {material.path}: {error}") from None
    wall = time.perf_counter() - start
    document = nbrdf_network.read_document(network)
    provenance = document["provenance"]
    weights = nbrdf_network.parameter_count(network)
    label = f"NBRDF {'anisotropic' if anisotropic else 'isotropic'} (distilled), {weights} weights"
    row = _base_row(material, "nbrdf", name, label, key)
    row.update(hidden=hidden, sampling="adaptive", anisotropic=nbrdf_network.is_anisotropic(document),
               stored_values=weights, memory_bytes=4 * weights, file_bytes=network.stat().st_size,
               seconds=provenance["seconds"], wall_seconds=wall, epochs=provenance["epochs"],
               best_epoch=provenance["best_epoch"], samples=summary["pairs"] - summary["validation"],
               evaluation_seconds=summary["evaluation_seconds"], network=str(network.relative_to(out)))
    row["metrics"] = reference.measure(cm.load_bsdf(network))
    return cache.put(material, name, row)


def process_anisotropic(material: Material, settings: Settings, out: Path, threads: int | None,
                        progress) -> list[dict]:
    """The anisotropic table's rows of one material (the BSDF itself is the reference)."""
    from nbrdf_tools.common import analytic_fit as af
    from nbrdf_tools.common import compare_materials as cm

    cache = RowCache(out)
    reference = Reference(material, settings)
    label = f"Mitsuba `{material.plugin or material.path.name}` (the reference)"
    row = _base_row(material, "reference", "source", label, {})
    row.update(stored_values=None, memory_bytes=material.path.stat().st_size if material.source == "rgl" else None,
               file_bytes=None, seconds=None, metrics=None, bsdf=str(reference.bsdf).splitlines()[0])
    rows = [row]
    progress.update(1)
    view, light = af.fit_directions(settings.fit_samples, settings.seed, turned=True)
    data = af.FitData(view, light, cm.eval_cos(reference.bsdf, view, light))
    for model in anisotropic_models(settings):
        progress.set_postfix_str(f"{material.name} {model}")
        rows.append(fit_row(material, model, data, settings, reference, cache))
        progress.update(1)
    for anisotropic in (True, False):
        progress.set_postfix_str(f"{material.name} nbrdf {'anisotropic' if anisotropic else 'isotropic'}")
        rows.append(distilled_row(material, anisotropic, settings, reference, out, threads, cache))
        progress.update(1)
    return rows


def anisotropic_models(settings: Settings) -> list[str]:
    return list(dict.fromkeys([*ANISOTROPIC_MODELS, *settings.models]))


def process(material: Material, settings: Settings, out: Path, nbrdf: Path, threads: int | None,
            progress) -> list[dict]:
    from nbrdf_tools.common import analytic_fit as af
    from nbrdf_tools.common import compare_materials as cm

    if material.group == "anisotropic":
        return process_anisotropic(material, settings, out, threads, progress)
    cache = RowCache(out)
    reference = Reference(material, settings)
    rows = reference_rows(material, settings, reference, out, cache)
    progress.update(1)
    view, light = af.fit_directions(settings.fit_samples, settings.seed)
    data = af.FitData(view, light, cm.eval_cos(reference.bsdf, view, light))
    for model in settings.models:
        progress.set_postfix_str(f"{material.name} {model}")
        rows.append(fit_row(material, model, data, settings, reference, cache))
        progress.update(1)
    widths = list(settings.hidden) + ([settings.table_hidden] if settings.table_hidden not in settings.hidden else [])
    plan = [(h, "adaptive") for h in widths] + [(h, "uniform") for h in settings.uniform_hidden]
    for hidden, sampling in plan:
        progress.set_postfix_str(f"{material.name} nbrdf {sampling} h{hidden}")
        rows.append(nbrdf_row(material, hidden, sampling, settings, reference, out, nbrdf, threads, cache))
        progress.update(1)
    return rows
