"""How faithful is an NBRDF, against the analytic models a Mitsuba user has and against the
measured data itself, and how does its error fall with its size?

    python -m nbrdf_tools.fidelity_report [--rgl A.bsdf,B.bsdf] [--merl X.binary,...]
        [--anisotropic C.bsdf,...] [--mitsuba roughconductor_aniso,principled_aniso]
        [--mitsuba NAME=SCENE.xml|NAME=BSDF.json|NAME={"type": ...}] [--hidden 6,8,12,21,32,48,64]
        [--samples N] [--epochs N] [--report docs/results/fidelity.md] [--out out/fidelity]

For every material (RGL measurements read by Mitsuba's ``measured`` BSDF, the reference; MERL-
format tables read by the project's ``merl`` BSDF, the reference):

* **NBRDF**: ``nbrdf train`` with adaptive sampling at each width of ``--hidden`` (the size
  sweep, ``7h + h^2 + h + 3h + 3`` weights, about 100 to 5,000) and with uniform sampling at
  the paper's width 21 (675 weights), all with the same training settings; memory = the weights
  as float32 (and the size of the ``.nbrdf.json`` file);
* **analytic fits** (:mod:`nbrdf_tools.analytic_fit`): GGX ``roughconductor`` and
  ``roughplastic``, Blinn-Phong (7 parameters), ABC and SGD, fitted in log space to the same
  material, timed; memory = their parameters as float32;
* **references**: Mitsuba's ``measured`` (the size of its ``.bsdf`` file) and the MERL table
  (for RGL measurements tabulated with ``python -m nbrdf_mitsuba.tabulate_rgl``, reciprocal
  fold, and rendered with the ``merl`` BSDF; 33.4 MiB).

Anisotropic materials (``--mitsuba``: Mitsuba BSDFs, the built-in ones of :data:`BUILTIN` or
any scene XML / ``mi.load_dict`` JSON; ``--anisotropic``: anisotropic RGL measurements) make a
table of their own, with the BSDF itself as the reference: an anisotropic and an isotropic
NBRDF of the table's width, both distilled from it by :mod:`nbrdf_mitsuba.distill` (``--anisotropy
on`` and ``off``, the same budget), the anisotropic GGX ``roughconductor`` fit (``alpha_u``,
``alpha_v``) and the isotropic fits, all fitted on directions turned about the normal. Their
spheres are rendered with the tangent frame turned by each of :data:`FRAME_TURNS_DEG` as well, and
their log-space error's adaptive directions are turned by a random azimuth each (an adaptive pair
has ``phi_h = 0``), so the metrics see the anisotropy.

Metrics of each against the reference (:mod:`nbrdf_tools.metrics`; images and directions of
:mod:`nbrdf_tools.compare_materials`: spheres under five light elevations, means over the five):
tone-mapped MAE and RMSE, SSIM, HDR-FLIP, linear RMSE, and the log-space BRDF error
``|ln(1 + f cos) - ln(1 + f_ref cos)|`` over adaptive and uniform directions.

Outputs: the report ``--report`` (markdown, default ``OUT/fidelity.md``) and next to it
``NAME.json`` (every number) and ``NAME.png`` (error against memory, log x); work files
(networks, tables, per-row results reused by a rerun with the same settings) in ``--out``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nbrdf_tools import cli
from nbrdf_tools.paths import MissingDataError, default_cli, default_out, shared_dir

PAPER_HIDDEN = 21
DEFAULT_HIDDEN = (6, 8, 12, 21, 32, 48, 64)
DEFAULT_MODELS = ("roughconductor", "roughplastic", "blinn_phong", "abc", "sgd")
MERL_TABLE_BYTES = 12 + 3 * 90 * 90 * 180 * 8
METRICS = ("mae_tonemapped", "rmse_tonemapped", "ssim", "flip_hdr", "rmse", "log_error_adaptive",
           "log_error_uniform")
# Lower is better for all but SSIM.
HIGHER_IS_BETTER = {"ssim"}
METRICS_VERSION = 1
# Stored fits made by other fitting code are redone.
FITS_VERSION = 2
# Anisotropic materials: the tangent frame turns of their sphere images (degrees).
FRAME_TURNS_DEG = (0.0, 45.0, 90.0)
# The built-in anisotropic Mitsuba BSDFs of --mitsuba (alpha_u along the tangent).
BUILTIN = {
    "roughconductor_aniso": {"type": "roughconductor", "distribution": "ggx", "material": "Au",
                             "alpha_u": 0.05, "alpha_v": 0.3},
    "principled_aniso": {"type": "principled", "base_color": {"type": "rgb", "value": [0.75, 0.4, 0.2]},
                         "metallic": 0.7, "roughness": 0.35, "anisotropic": 0.8, "specular": 0.5},
}
# Analytic models of the anisotropic table (before --models' isotropic ones).
ANISOTROPIC_MODELS = ("roughconductor_aniso",)


def weight_count(hidden: int) -> int:
    """Weights and biases of the 6-h-h-3 network."""
    return 6 * hidden + hidden + hidden * hidden + hidden + 3 * hidden + 3


@dataclass
class Settings:
    hidden: tuple[int, ...]
    uniform_hidden: tuple[int, ...]
    samples: int | None
    epochs: int | None
    seed: int
    models: tuple[str, ...]
    fit_samples: int
    resolution: int
    metric_samples: int
    tabulate: bool
    table_hidden: int = PAPER_HIDDEN  # the width of the representation table

    def training_key(self) -> dict:
        return {"samples": self.samples, "epochs": self.epochs, "seed": self.seed}

    def metric_key(self) -> dict:
        return {"resolution": self.resolution, "metric_samples": self.metric_samples, "metrics": METRICS_VERSION}


@dataclass
class Material:
    name: str
    path: Path
    source: str  # "rgl", "merl" or "mitsuba"
    group: str  # "isotropic" or "anisotropic"
    spec: str = ""  # what the user named (--mitsuba)
    plugin: str = ""  # the Mitsuba plugin of a --mitsuba source, when known


# --------------------------------------------------------------------------------------------
# The reference and the metrics


def load_reference(material: Material):
    """The reference BSDF: the material's file through its plugin, or the Mitsuba source."""
    from nbrdf_tools import compare_materials as cm

    if material.source != "mitsuba":
        return cm.load_bsdf(material.path)
    from nbrdf_mitsuba import distill

    cm.set_variant()
    try:
        bsdf, _ = distill.load_bsdf(material.path)
    except distill.DistillError as error:
        raise ValueError(str(error)) from None
    return bsdf


class Reference:
    """A material's reference BSDF and its sphere images (anisotropic materials: under each
    light and each tangent frame turn of :data:`FRAME_TURNS_DEG`)."""

    def __init__(self, material: Material, settings: Settings):
        self.bsdf = load_reference(material)
        self.anisotropic = material.group == "anisotropic"
        self.settings = settings
        self.images = self.render(self.bsdf)

    def render(self, bsdf) -> np.ndarray:
        from nbrdf_tools import compare_materials as cm

        turns = FRAME_TURNS_DEG if self.anisotropic else (0.0,)
        return np.concatenate([cm.render_spheres(bsdf, self.settings.resolution, frame_turn_deg=t) for t in turns])

    def measure(self, bsdf) -> dict:
        from nbrdf_tools import compare_materials as cm
        from nbrdf_tools import metrics

        images = self.render(bsdf)
        per_light = []
        for i in range(images.shape[0]):
            r = np.moveaxis(self.images[i].astype(np.float64), 0, -1)
            t = np.moveaxis(images[i].astype(np.float64), 0, -1)
            per_light.append({"mae_tonemapped": metrics.mae_tonemapped(r, t),
                              "rmse_tonemapped": metrics.rmse_tonemapped(r, t), "ssim": metrics.ssim(r, t),
                              "flip_hdr": metrics.flip_hdr(r, t), "rmse": metrics.rmse(r, t)})
        values = {k: float(np.mean([p[k] for p in per_light])) for k in per_light[0]}
        for sampling in ("adaptive", "uniform"):
            values[f"log_error_{sampling}"] = cm.log_error(self.bsdf, bsdf, sampling, self.settings.metric_samples,
                                                           turned=self.anisotropic)
        return values


# --------------------------------------------------------------------------------------------
# Rows (each cached in OUT/rows/MATERIAL/NAME.json with the settings it was made with)


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
    from nbrdf_tools import compare_materials as cm

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
    from nbrdf_tools import analytic_fit as af

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
    from nbrdf_tools import compare_materials as cm

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

    from nbrdf_tools import compare_materials as cm

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
    document = json.loads(network.read_text(encoding="utf-8"))
    provenance = document["provenance"]
    weights = sum(len(layer["weights"]) + len(layer["bias"]) for layer in document["layers"])
    label = f"NBRDF {'anisotropic' if anisotropic else 'isotropic'} (distilled), {weights} weights"
    row = _base_row(material, "nbrdf", name, label, key)
    row.update(hidden=hidden, sampling="adaptive", anisotropic=bool(document.get("anisotropic", False)),
               stored_values=weights, memory_bytes=4 * weights, file_bytes=network.stat().st_size,
               seconds=provenance["seconds"], wall_seconds=wall, epochs=provenance["epochs"],
               best_epoch=provenance["best_epoch"], samples=summary["pairs"] - summary["validation"],
               evaluation_seconds=summary["evaluation_seconds"], network=str(network.relative_to(out)))
    row["metrics"] = reference.measure(cm.load_bsdf(network))
    return cache.put(material, name, row)


def process_anisotropic(material: Material, settings: Settings, out: Path, threads: int | None,
                        progress) -> list[dict]:
    """The anisotropic table's rows of one material (the BSDF itself is the reference)."""
    from nbrdf_tools import analytic_fit as af
    from nbrdf_tools import compare_materials as cm

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
    from nbrdf_tools import analytic_fit as af
    from nbrdf_tools import compare_materials as cm

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


# --------------------------------------------------------------------------------------------
# Report


def _fmt(x, kind: str = "e") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if kind == "f4":
        return f"{x:.4f}"
    if kind == "s":
        return f"{x:.1f}"
    return f"{x:.3e}"


def _bytes(n) -> str:
    if n is None:
        return "-"
    if n >= 1 << 20:
        return f"{n / (1 << 20):.1f} MiB"
    if n >= 1 << 10:
        return f"{n / (1 << 10):.1f} KiB"
    return f"{n} B"


METRIC_COLUMNS = [("mae_tonemapped", "tone-mapped MAE", "e"), ("rmse_tonemapped", "tone-mapped RMSE", "e"),
                  ("ssim", "SSIM", "f4"), ("flip_hdr", "HDR-FLIP", "f4"),
                  ("log_error_adaptive", "log error (adaptive dirs)", "e"),
                  ("log_error_uniform", "log error (uniform dirs)", "e")]


def _metric_cells(row: dict) -> list[str]:
    if row.get("metrics") is None:
        return ["0 (reference)" if i == 0 else "" for i in range(len(METRIC_COLUMNS))]
    return [_fmt(row["metrics"][k], kind) for k, _, kind in METRIC_COLUMNS]


ANISOTROPIC_LABELS = {"log_error_adaptive": "log error (adaptive dirs, turned)"}


def representation_table(rows: list[dict], material: str, table_hidden: int, labels: dict | None = None) -> list[str]:
    mine = [r for r in rows if r["material"] == material]
    chosen = [r for r in mine if r["kind"] == "nbrdf" and r["hidden"] == table_hidden]
    chosen += [r for r in mine if r["kind"] == "fit"] + [r for r in mine if r["kind"] == "reference"]
    labels = labels or {}
    lines = ["| representation | stored values | memory | fit / train s | "
             + " | ".join(labels.get(k, label) for k, label, _ in METRIC_COLUMNS) + " |",
             "|---|---:|---:|---:|" + "---:|" * len(METRIC_COLUMNS)]
    for r in chosen:
        stored = f"{r['stored_values']:,}" if r.get("stored_values") else "-"
        seconds = _fmt(r.get("seconds"), "s")
        if r["method"] == "merl-table" and r.get("seconds") is not None:
            seconds += " (tabulation)"
        lines.append(f"| {r['label']} | {stored} | {_bytes(r['memory_bytes'])} | {seconds} | "
                     + " | ".join(_metric_cells(r)) + " |")
    return lines


def sweep_rows(rows: list[dict], material: str) -> list[dict]:
    return sorted((r for r in rows if r["material"] == material and r["kind"] == "nbrdf"
                   and r["sampling"] == "adaptive"), key=lambda r: r["hidden"])


def sweep_table(rows: list[dict], materials: list[str]) -> list[str]:
    lines = ["| material | hidden | weights | float32 memory | JSON file | train s | epochs | tone-mapped RMSE | "
             "SSIM | HDR-FLIP | log error (adaptive dirs) | log error (uniform dirs) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for m in materials:
        for r in sweep_rows(rows, m):
            x = r["metrics"]
            lines.append(f"| {m} | {r['hidden']} | {r['stored_values']:,} | {_bytes(r['memory_bytes'])} | "
                         f"{_bytes(r['file_bytes'])} | {_fmt(r['seconds'], 's')} | {r['epochs']} | "
                         f"{_fmt(x['rmse_tonemapped'])} | {_fmt(x['ssim'], 'f4')} | {_fmt(x['flip_hdr'], 'f4')} | "
                         f"{_fmt(x['log_error_adaptive'])} | {_fmt(x['log_error_uniform'])} |")
    return lines


def _spearman(x, y) -> float:
    rx = np.argsort(np.argsort(x)).astype(float)
    ry = np.argsort(np.argsort(y)).astype(float)
    if rx.std() == 0 or ry.std() == 0:
        return float("nan")
    return float(np.corrcoef(rx, ry)[0, 1])


def sweep_trend(rows: list[dict], materials: list[str]) -> list[str]:
    """Per material: does the error fall with size? (Spearman rank correlation, increases)."""
    lines = []
    for m in materials:
        s = sweep_rows(rows, m)
        if len(s) < 2:
            continue
        parts = []
        for key, label in (("log_error_adaptive", "log error"), ("rmse_tonemapped", "tone-mapped RMSE")):
            e = [r["metrics"][key] for r in s]
            ups = [f"{s[i]['stored_values']} -> {s[i + 1]['stored_values']}" for i in range(len(s) - 1)
                   if e[i + 1] > e[i]]
            parts.append(f"{label} from {_fmt(e[0])} to {_fmt(e[-1])} (x{e[0] / max(e[-1], 1e-300):.1f}), "
                         f"rank correlation with size {_spearman([r['stored_values'] for r in s], e):+.2f}"
                         + (f", rises at {', '.join(ups)}" if ups else ", never rises"))
        lines.append(f"* {m}: " + "; ".join(parts) + ".")
    return lines


def fit_verdicts(rows: list[dict], materials: list[str], table_hidden: int) -> tuple[list[str], list[str]]:
    """A table of NBRDF-675 (adaptive) against each fit per material (which wins each metric),
    and sentences naming every metric a fit wins."""
    lines = ["| material | fit | " + " | ".join(label for _, label, _ in METRIC_COLUMNS) + " |",
             "|---|---|" + "---|" * len(METRIC_COLUMNS)]
    wins = []
    for m in materials:
        net = [r for r in rows if r["material"] == m and r["kind"] == "nbrdf" and r["hidden"] == table_hidden
               and r["sampling"] == "adaptive"]
        if not net:
            continue
        net = net[0]["metrics"]
        for r in (r for r in rows if r["material"] == m and r["kind"] == "fit"):
            cells, won = [], []
            for k, label, kind in METRIC_COLUMNS:
                a, b = net[k], r["metrics"][k]
                fit_better = b > a if k in HIGHER_IS_BETTER else b < a
                cells.append(("**fit**" if fit_better else "NBRDF") + f" ({_fmt(b, kind)})")
                if fit_better:
                    won.append(f"{label} ({_fmt(b, kind)} against {_fmt(a, kind)})")
            lines.append(f"| {m} | {r['label']} | " + " | ".join(cells) + " |")
            if won:
                wins.append(f"* {m}: {r['label']} beats NBRDF-{weight_count(table_hidden)} in " + ", ".join(won) + ".")
    return lines, wins


def summary(rows: list[dict], materials: list[str], table_hidden: int) -> list[str]:
    """Per material: the best fit against NBRDF-n in log error and FLIP, the smallest network that
    beats the best fit, and the network against the MERL table."""
    n = weight_count(table_hidden)
    lines = []
    for m in materials:
        mine = [r for r in rows if r["material"] == m]
        net = [r for r in mine if r["kind"] == "nbrdf" and r["hidden"] == table_hidden and r["sampling"] == "adaptive"]
        fits = [r for r in mine if r["kind"] == "fit"]
        if not net or not fits:
            continue
        net = net[0]["metrics"]
        parts = []
        for key, name in (("log_error_adaptive", "log error"), ("flip_hdr", "HDR-FLIP")):
            best = min(fits, key=lambda r: r["metrics"][key])
            b, a = best["metrics"][key], net[key]
            verdict = (f"NBRDF-{n} is {b / a:.1f}x lower" if a < b else f"**the fit is {a / b:.2f}x lower**")
            parts.append(f"best fit in {name}: {best['label']} ({_fmt(b, 'e' if key.startswith('log') else 'f4')} "
                         f"against {_fmt(a, 'e' if key.startswith('log') else 'f4')}: {verdict})")
        best = min(fits, key=lambda r: r["metrics"]["log_error_adaptive"])["metrics"]["log_error_adaptive"]
        smaller = [r for r in sweep_rows(rows, m) if r["metrics"]["log_error_adaptive"] < best]
        parts.append("the smallest network below the best fit's log error: "
                     + (f"{smaller[0]['stored_values']} weights" if smaller else "none of the sweep"))
        table = [r for r in mine if r["method"] == "merl-table" and r.get("metrics")]
        if table:
            t = table[0]["metrics"]["log_error_adaptive"]
            parts.append(f"MERL table log error {_fmt(t)} ({'above' if t > net['log_error_adaptive'] else 'below'} "
                         f"NBRDF-{n}'s, in {table[0]['memory_bytes'] / (4 * n):,.0f}x the memory)")
        lines.append(f"* **{m}**: " + "; ".join(parts) + ".")
    return lines


def fits_against_small_networks(rows: list[dict], materials: list[str], table_hidden: int) -> list[str]:
    """Per material: the fits that beat the sweep's networks smaller than the table's, in log
    error and in HDR-FLIP (where the fits do win)."""
    lines = []
    for m in materials:
        fits = [r for r in rows if r["material"] == m and r["kind"] == "fit"]
        parts = []
        for r in sweep_rows(rows, m):
            if r["hidden"] >= table_hidden:
                continue
            for key, name in (("log_error_adaptive", "log error"), ("flip_hdr", "HDR-FLIP")):
                winners = [f["label"] for f in fits if f["metrics"][key] < r["metrics"][key]]
                if winners:
                    parts.append(f"{', '.join(winners)} beat the {r['stored_values']}-weight network in {name}")
        if parts:
            lines.append(f"* {m}: " + "; ".join(parts) + ".")
    return lines


def fit_summary(rows: list[dict], materials: list[str], table_hidden: int) -> list[str]:
    """One sentence per fitted model: on how many materials it beats the network, per metric."""
    lines = []
    n = weight_count(table_hidden)
    for model in dict.fromkeys(r["method"] for r in rows if r["kind"] == "fit"):
        counts = []
        label = None
        for k, name, _ in METRIC_COLUMNS:
            won, total = [], 0
            for m in materials:
                net = [r for r in rows if r["material"] == m and r["kind"] == "nbrdf" and r["hidden"] == table_hidden
                       and r["sampling"] == "adaptive"]
                fit = [r for r in rows if r["material"] == m and r["method"] == model]
                if not net or not fit:
                    continue
                label = fit[0]["label"]
                total += 1
                a, b = net[0]["metrics"][k], fit[0]["metrics"][k]
                if (b > a) if k in HIGHER_IS_BETTER else (b < a):
                    won.append(m)
            counts.append(f"{name} {len(won)}/{total}" + (f" ({', '.join(won)})" if won else ""))
        if label:
            lines.append(f"* {label} beats NBRDF-{n} on: " + "; ".join(counts) + ".")
    return lines


def uniform_table(rows: list[dict], materials: list[str]) -> list[str]:
    lines = ["| material | weights | sampling | " + " | ".join(label for _, label, _ in METRIC_COLUMNS) + " |",
             "|---|---:|---|" + "---:|" * len(METRIC_COLUMNS)]
    for m in materials:
        uniform = [r for r in rows if r["material"] == m and r["kind"] == "nbrdf" and r["sampling"] == "uniform"]
        for u in uniform:
            for r in rows:
                if (r["material"] == m and r["kind"] == "nbrdf" and r["hidden"] == u["hidden"]
                        and r["sampling"] == "adaptive"):
                    lines.append(f"| {m} | {r['stored_values']} | adaptive | " + " | ".join(_metric_cells(r)) + " |")
            lines.append(f"| {m} | {u['stored_values']} | uniform | " + " | ".join(_metric_cells(u)) + " |")
    return lines


def _better(key: str, a: float, b: float) -> bool:
    """Whether value ``a`` of metric ``key`` is better than ``b``."""
    return a > b if key in HIGHER_IS_BETTER else a < b


# Fits whose model is a source plugin's own (up to its Fresnel term): their wins are expected.
OWN_MODEL = {"roughconductor_aniso": "roughconductor"}


def anisotropic_summary(rows: list[dict], materials: list[str], plugins: dict | None = None) -> list[str]:
    """Per anisotropic material: the anisotropic NBRDF against the isotropic one, and every
    metric in which a fit beats the anisotropic NBRDF (``plugins``: material -> Mitsuba plugin,
    to say when the fit is the source's own model)."""
    plugins = plugins or {}
    lines = []
    for m in materials:
        mine = [r for r in rows if r["material"] == m]
        nets = {r["anisotropic"]: r for r in mine if r["kind"] == "nbrdf" and "anisotropic" in r}
        if True not in nets:
            continue
        a = nets[True]["metrics"]
        parts = []
        if False in nets:
            i = nets[False]["metrics"]
            la, li = a["log_error_adaptive"], i["log_error_adaptive"]
            parts.append(f"the anisotropic NBRDF against the isotropic one: turned log error {_fmt(la)} "
                         f"against {_fmt(li)} (x{li / max(la, 1e-300):.1f} lower), "
                         f"HDR-FLIP {_fmt(a['flip_hdr'], 'f4')} against {_fmt(i['flip_hdr'], 'f4')}, SSIM "
                         f"{_fmt(a['ssim'], 'f4')} against {_fmt(i['ssim'], 'f4')}")
            worse = [label for k, label, _ in METRIC_COLUMNS if not _better(k, a[k], i[k])]
            if worse:
                parts.append("**the isotropic NBRDF is as good or better in " + ", ".join(worse) + "**")
        winners = 0
        for r in (r for r in mine if r["kind"] == "fit"):
            won = [f"{ANISOTROPIC_LABELS.get(k, label)} ({_fmt(r['metrics'][k], kind)} against {_fmt(a[k], kind)})"
                   for k, label, kind in METRIC_COLUMNS if _better(k, r["metrics"][k], a[k])]
            if won:
                winners += 1
                if r["metrics"]["log_error_adaptive"] < 1e-4:
                    exact = " (the source is of this model's own family, and the fit recovers it: expected)"
                elif OWN_MODEL.get(r["method"]) == plugins.get(m):
                    exact = (f" (expected: it is the source's own `{plugins[m]}` model, up to the Fresnel term, which "
                             "the fit holds as a constant RGB specular_reflectance)")
                else:
                    exact = ""
                parts.append(f"**{r['label']} beats the anisotropic NBRDF** in " + ", ".join(won) + exact)
        if not winners:
            parts.append("no fit beats the anisotropic NBRDF in any metric")
        fits = [r for r in mine if r["kind"] == "fit"]
        if fits:
            best = min(fits, key=lambda r: r["metrics"]["log_error_adaptive"])
            parts.append(f"best fit in turned log error: {best['label']} ({_fmt(best['metrics']['log_error_adaptive'])})")
        lines.append(f"* **{m}**: " + "; ".join(parts) + ".")
    return lines


MARKERS = {"roughconductor": "s", "roughplastic": "D", "blinn_phong": "^", "abc": "v", "sgd": "P",
           "merl-table": "*"}


def plot(path: Path, rows: list[dict], materials: list[str]) -> None:
    """Error against memory (log-log), one column per material: the NBRDF sweep as a line, the
    fits and the MERL table as markers, the sizes of the measured file and the MERL table."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metrics = (("log_error_adaptive", "log-space BRDF error"), ("rmse_tonemapped", "tone-mapped image RMSE"))
    cols = max(len(materials), 1)
    fig, axes = plt.subplots(len(metrics), cols, figsize=(3.6 * cols + 0.6, 6.8), squeeze=False)
    colours = dict(zip(MARKERS, plt.rcParams["axes.prop_cycle"].by_key()["color"][1:]))
    for j, m in enumerate(materials):
        for i, (key, label) in enumerate(metrics):
            ax = axes[i][j]
            s = sweep_rows(rows, m)
            if s:
                ax.plot([r["memory_bytes"] for r in s], [r["metrics"][key] for r in s], "o-", color="k", ms=4,
                        label="NBRDF (adaptive), 6-h-h-3")
            for r in rows:
                if r["material"] == m and r.get("metrics") and r["method"] in MARKERS:
                    ax.scatter([r["memory_bytes"]], [r["metrics"][key]], marker=MARKERS[r["method"]],
                               color=colours[r["method"]], edgecolor="k", linewidths=0.4, s=50, zorder=3,
                               label=r["label"].replace("`", ""))
                if r["material"] == m and r["method"] == "measured":
                    ax.axvline(r["memory_bytes"], color="0.6", ls=":", lw=0.9, label="measured .bsdf file")
            ax.axvline(MERL_TABLE_BYTES, color="0.4", ls="--", lw=0.9, label="MERL table")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(True, which="both", alpha=0.25)
            if i == 0:
                ax.set_title(m, fontsize=9)
            if i == len(metrics) - 1:
                ax.set_xlabel("memory, bytes", fontsize=8)
            if j == 0:
                ax.set_ylabel(label, fontsize=8)
            ax.tick_params(labelsize=7)
    handles = {}
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=min(len(handles), 5), fontsize=7,
               frameon=False)
    fig.suptitle("Error against memory (float32 parameters; file sizes for the references)", fontsize=9)
    fig.tight_layout(rect=(0, 0.08, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(report: Path, rows: list[dict], materials: list[Material], settings: Settings, command: str,
                 elapsed: float) -> None:
    iso = [m.name for m in materials if m.group == "isotropic"]
    aniso = [m.name for m in materials if m.group == "anisotropic"]
    training = (f"{settings.samples:,} samples" if settings.samples else "the trainer's default samples (800,000)")
    training += f", at most {settings.epochs} epochs" if settings.epochs else ", the trainer's default epoch budget"
    if settings.samples or settings.epochs:
        training += (" (a reduced budget: the trainer's defaults are 800,000 samples and up to 300 epochs; "
                     "[rgl-training.md](rgl-training.md) has the 675-weight networks at the defaults)")
    lines = [
        "# Fidelity: NBRDF against analytic fits and the measured data", "",
        "```sh", command, "```", "",
        f"Regenerated by the command above ({datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d}, "
        f"{platform.machine()}, {os.cpu_count()} logical CPUs shared with other jobs; {elapsed:.0f} s for this "
        f"invocation, whose rows of earlier invocations with the same settings are reused; the rows took "
        f"{sum(r.get('seconds') or 0 for r in rows if r['kind'] == 'nbrdf'):.0f} s of training and "
        f"{sum(r.get('seconds') or 0 for r in rows if r['kind'] == 'fit'):.0f} s of fitting). Every number is in "
        f"[{report.with_suffix('.json').name}]({report.with_suffix('.json').name}).", "",
        "## How the numbers are made", "",
        "* **Reference**: Mitsuba's `measured` BSDF on the RGL `.bsdf` file (the `merl` BSDF for MERL-format "
        "tables). Every other row is measured against it.",
        f"* **Metrics** (`nbrdf_tools.metrics`): {settings.resolution}x{settings.resolution} sphere images under "
        "lights at 0, 30, 45, 60 and 75 degrees (`nbrdf_tools.compare_materials`: each pixel is the BSDF's "
        "`eval`, no Monte Carlo noise), averaged over the five: MAE and RMSE of the tone-mapped images "
        "(`min(x^(1/2.2), 1)`), SSIM (scikit-image) of the tone-mapped images, HDR-FLIP (NVIDIA "
        "`flip-evaluator`) of the linear ones; the log-space BRDF error `|ln(1 + f cos) - ln(1 + f_ref cos)|` over "
        f"{settings.metric_samples:,} adaptive (uniform in theta_h, theta_d, phi_d) and as many uniform directions.",
        f"* **NBRDF**: `nbrdf train IN --hidden H --sampling adaptive|uniform --seed {settings.seed}` with "
        f"{training}, the same for every size; widths {', '.join(map(str, settings.hidden))} "
        f"({', '.join(str(weight_count(h)) for h in settings.hidden)} weights); uniform sampling at width "
        f"{', '.join(map(str, settings.uniform_hidden)) or '-'}. Memory: the weights as float32; the JSON file "
        "is larger (text). Seconds: the trainer's own time.",
        f"* **Analytic fits** (`nbrdf_tools.analytic_fit`): each model's parameters minimise the squared "
        f"log residual `ln(1 + f cos) - ln(1 + f_ref cos)` over {settings.fit_samples:,} directions (half "
        "adaptive, half uniform; not the metric's directions) with `scipy.optimize.least_squares` (bounded "
        "trust region, several starts). GGX `roughconductor` (specular_reflectance RGB in [0, 1], alpha; "
        "`material none`) and `roughplastic` (diffuse RGB, specular_reflectance, alpha; int_ior 1.5, "
        "`nonlinear false`) are rendered by Mitsuba's own plugins (the roughplastic fit evaluates the plugin "
        "itself); Blinn-Phong (`kd/pi + ks (n+2)/(2pi) cos^n theta_h`), ABC and SGD by a small Python "
        "`mi.BSDF` whose `eval` is the NumPy form (the twins of the Rust forms, held together by "
        "tests/test_fidelity_report.py), at the same pixels. ABC and SGD start from the best three of the 100 "
        "published MERL fits; SGD keeps `kap`, `c`, `k` of its start. Memory: the parameters as float32 "
        "(SGD: 11 per channel). Seconds: the fit's wall time.",
        "* **MERL table**: the measurement tabulated on the MERL grid (`python -m nbrdf_mitsuba.tabulate_rgl "
        "--phi-fold reciprocal`, what Mitsuba's `merl`-style readers take) and rendered with the `merl` BSDF.",
        "",
    ]
    lines += ["## Summary", ""] + summary(rows, iso, settings.table_hidden) + [""]
    lines += [f"## Representation table: NBRDF at {weight_count(settings.table_hidden)} weights against each fit", ""]
    for m in iso:
        lines += [f"### {m}", ""] + representation_table(rows, m, settings.table_hidden) + [""]
    verdict_table, wins = fit_verdicts(rows, iso, settings.table_hidden)
    n = weight_count(settings.table_hidden)
    lines += [f"## Material by material: who wins each metric, NBRDF-{n} (adaptive) or the fit", "",
              "Each cell names the winner and gives the fit's value.", ""] + verdict_table + [""]
    lines += ["### Where a fit wins", ""] + fit_summary(rows, iso, settings.table_hidden) + [""]
    lines += (wins or [f"No fit beats NBRDF-{n} on any metric of any material."]) + [""]
    small = fits_against_small_networks(rows, iso, settings.table_hidden)
    if small:
        lines += ["Against the smaller networks of the size sweep, fits do win:", ""] + small + [""]
    iso_rows = [r for r in rows if r["group"] == "isotropic"]
    net_s = [r["seconds"] for r in iso_rows if r["kind"] == "nbrdf" and r["hidden"] == settings.table_hidden]
    fit_s = {r["label"]: [] for r in iso_rows if r["kind"] == "fit"}
    for r in iso_rows:
        if r["kind"] == "fit":
            fit_s[r["label"]].append(r["seconds"])
    if net_s and fit_s:
        lines += [f"Time: training NBRDF-{n} took {np.mean(net_s):.0f} s on average; the fits "
                  + ", ".join(f"{k} {np.mean(v):.0f} s" for k, v in fit_s.items())
                  + " (wall times on the shared machine; the NumPy fits run on one thread, the trainer on all cores).", ""]
    lines += ["## Size sweep: error against memory", ""]
    lines += [f"![error against memory]({report.with_suffix('.png').name})", ""] if iso else []
    lines += sweep_table(rows, iso) + [""]
    lines += sweep_trend(rows, iso) + [""]
    if settings.uniform_hidden:
        lines += ["## Adaptive against uniform sampling", ""] + uniform_table(rows, iso) + [""]
    lines += ["## Anisotropic materials", ""]
    if aniso:
        by_name = {m.name: m for m in materials}
        sources = []
        for m in aniso:
            spec = by_name[m].spec
            what = (f"`{json.dumps(BUILTIN[spec])}`" if spec in BUILTIN else f"`{spec}`" if spec.startswith("{")
                    else f"`{by_name[m].path}`")
            sources.append(f"`{m}` = {what}")
        lines += [
            "The reference is the BSDF itself: " + "; ".join(sources) + ". (No anisotropic measurement is in the "
            "shared data of this checkout: RGL's four are isotropic.)", "",
            f"* **NBRDF**: `python -m nbrdf_mitsuba.distill SOURCE --hidden {settings.table_hidden} --anisotropy on` "
            f"and `--anisotropy off` (its library call), seed {settings.seed}, "
            + (f"{settings.samples:,} samples" if settings.samples else
               "the distiller's default samples (800,000; 4,000,000 for the anisotropic network)")
            + (f", at most {settings.epochs} epochs" if settings.epochs else ", the trainer's default epoch budget")
            + ". Both have the same 6-h-h-3 shape and weight count; the anisotropic one's input carries the half "
            "vector's azimuth `phi_h`. Seconds: the trainer's own time (Mitsuba's evaluation of the training "
            "directions is in the JSON, `evaluation_seconds`).",
            "* **Analytic fits**: the anisotropic GGX `roughconductor` (specular_reflectance RGB, alpha_u along the "
            "tangent, alpha_v across it; `material none`; rendered by Mitsuba's plugin; its NumPy twin is held to "
            "Mitsuba's by tests/test_fidelity_report.py) and the isotropic models above, fitted the same way on "
            f"{settings.fit_samples:,} directions each turned about the normal by a random azimuth.",
            "* **Metrics**: as above, but the spheres are rendered with every pixel's tangent frame turned by "
            + ", ".join(f"{t:g}" for t in FRAME_TURNS_DEG)
            + f" degrees under each of the five lights ({5 * len(FRAME_TURNS_DEG)} images, averaged), and the "
            "adaptive directions of the log error are each turned about the normal by a random azimuth (an adaptive "
            "pair's half vector has `phi_h = 0`, which would hide the anisotropy); the uniform directions already "
            "cover every azimuth.", "",
            "### Verdict", ""] + anisotropic_summary(rows, aniso, {m.name: m.plugin for m in materials}) + [""]
        for m in aniso:
            lines += [f"### {m}", ""] + representation_table(rows, m, settings.table_hidden, ANISOTROPIC_LABELS) + [""]
    else:
        lines += ["No anisotropic material was given (`--mitsuba` or `--anisotropic`): none is available in the "
                  "shared data of this checkout, so this table is empty.", ""]
    report.write_text("\n".join(lines) + "\n", encoding="utf-8")


# --------------------------------------------------------------------------------------------


def _list(text: str | None) -> list[str]:
    return [t.strip() for t in (text or "").split(",") if t.strip()]


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="python -m nbrdf_tools.fidelity_report",
        description="Fidelity tables: NBRDFs of several sizes (adaptive and uniform sampling), analytic fits "
                    "(GGX roughconductor/roughplastic, Blinn-Phong, ABC, SGD) and the MERL table against "
                    "measured materials; sphere-image and log-space errors, memory, fitting time; a plot of "
                    "error against memory.")
    p.add_argument("--rgl", help="comma-separated RGL .bsdf measurements (default: SHARED/data/rgl/*.bsdf when "
                                 "neither --rgl nor --merl is given)")
    p.add_argument("--merl", help="comma-separated MERL-format tables (.binary); their reference is the table")
    p.add_argument("--anisotropic", help="comma-separated anisotropic .bsdf measurements (the anisotropic table)")
    p.add_argument("--mitsuba", action="append", metavar="SOURCE",
                   help="anisotropic Mitsuba BSDFs for the anisotropic table, the BSDF itself the reference "
                        "(repeatable): comma-separated built-in names (" + ", ".join(BUILTIN) + "), or one "
                        "NAME=FILE (a scene .xml holding one BSDF or a mi.load_dict .json) or NAME=JSON "
                        "(a mi.load_dict dictionary)")
    p.add_argument("--hidden", default=",".join(map(str, DEFAULT_HIDDEN)),
                   help="network widths of the size sweep, adaptive sampling (default: %(default)s)")
    p.add_argument("--uniform-hidden", default=str(PAPER_HIDDEN),
                   help="widths also trained with uniform sampling (default: %(default)s; '' for none)")
    p.add_argument("--table-hidden", type=int, default=PAPER_HIDDEN,
                   help="the width of the NBRDF in the representation table (default: %(default)s, 675 weights)")
    p.add_argument("--samples", type=int, help="training samples of every network (default: the trainer's)")
    p.add_argument("--epochs", type=int, help="maximum epochs of every network (default: the trainer's)")
    p.add_argument("--models", default=",".join(DEFAULT_MODELS),
                   help="analytic models to fit (default: %(default)s)")
    p.add_argument("--fit-samples", type=int, default=20_000, help="fitting directions (default: %(default)s)")
    p.add_argument("--resolution", type=int, default=128, help="sphere image size (default: %(default)s)")
    p.add_argument("--metric-samples", type=int, default=100_000,
                   help="directions of the log-space error, each sampling (default: %(default)s)")
    p.add_argument("--no-tabulate", action="store_true", help="no MERL-table row for RGL measurements")
    p.add_argument("--seed", type=int, default=0, help="training and fitting seed (default: 0)")
    p.add_argument("--threads", type=int, help="trainer threads (default: one per core)")
    p.add_argument("--out", type=Path, default=default_out("fidelity"),
                   help="work folder: networks, per-row results (default: %(default)s)")
    p.add_argument("--report", type=Path,
                   help="the markdown report; NAME.json and NAME.png are written next to it (default: OUT/fidelity.md)")
    p.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf tool (default: %(default)s)")
    p.add_argument("--shared", type=Path, default=shared_dir(), help="the shared data folder (default: %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p.parse_args(argv)


def _mitsuba_materials(values: list[str] | None, out: Path) -> list[Material]:
    """The materials of ``--mitsuba``: built-in names (written to OUT/sources/NAME.json, the
    distiller's input), NAME=FILE or NAME=JSON."""
    materials = []
    for value in values or []:
        if "=" not in value:
            for name in _list(value):
                if name not in BUILTIN:
                    raise ValueError(f"--mitsuba {name}: not a built-in BSDF ({', '.join(BUILTIN)}); "
                                     "give NAME=FILE or NAME=JSON for others")
                path = out / "sources" / f"{name}.json"
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps(BUILTIN[name], indent=1) + "\n", encoding="utf-8")
                materials.append(Material(name=name, path=path, source="mitsuba", group="anisotropic", spec=name,
                                          plugin=BUILTIN[name]["type"]))
            continue
        name, _, spec = value.partition("=")
        name, spec = name.strip(), spec.strip()
        if not name or not name.replace("_", "").replace("-", "").isalnum():
            raise ValueError(f"--mitsuba {value}: NAME must be letters, digits, '_' or '-'")
        if spec.startswith("{"):
            try:
                parsed = json.loads(spec)
            except json.JSONDecodeError as error:
                raise ValueError(f"--mitsuba {name}: not a JSON dictionary: {error}") from None
            path = out / "sources" / f"{name}.json"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(parsed, indent=1) + "\n", encoding="utf-8")
        else:
            path = Path(spec)
            if not path.is_file():
                raise MissingDataError(f"--mitsuba {name}: no such file {path}")
            if path.suffix.lower() not in (".xml", ".json"):
                raise ValueError(f"--mitsuba {name}: {path} is not a scene .xml or a .json dictionary")
        plugin = ""
        if path.suffix.lower() == ".json":
            try:
                plugin = str(json.loads(path.read_text(encoding="utf-8")).get("type", ""))
            except (ValueError, AttributeError):
                pass  # the distiller says what is wrong with it
        materials.append(Material(name=name, path=path, source="mitsuba", group="anisotropic", spec=spec,
                                  plugin=plugin))
    return materials


def _materials(args) -> list[Material]:
    rgl, merl, aniso = _list(args.rgl), _list(args.merl), _list(args.anisotropic)
    mitsuba = _mitsuba_materials(args.mitsuba, args.out)
    if not rgl and not merl and not aniso and not mitsuba:
        folder = args.shared / "data" / "rgl"
        rgl = [str(p) for p in sorted(folder.glob("*.bsdf"))]
        if not rgl:
            raise MissingDataError(f"no materials given and no RGL measurements in {folder} (pass --rgl or --merl, "
                                   "or set NBRDF_SHARED)")
    materials = []
    for paths, source, group in ((rgl, "rgl", "isotropic"), (merl, "merl", "isotropic"),
                                 (aniso, "rgl", "anisotropic")):
        for p in paths:
            path = Path(p)
            if not path.is_file():
                raise MissingDataError(f"no such material file: {path}")
            name = path.name.removesuffix(".bsdf").removesuffix(".binary")
            materials.append(Material(name=name, path=path, source=source, group=group))
    materials += mitsuba
    names = [m.name for m in materials]
    if len(set(names)) != len(names):
        raise ValueError(f"two materials share a name: {', '.join(sorted({n for n in names if names.count(n) > 1}))}")
    return materials


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    from tqdm import tqdm

    from nbrdf_tools import analytic_fit as af

    try:
        args.out.mkdir(parents=True, exist_ok=True)
        cli.check_cli(args.cli)
        materials = _materials(args)
        settings = Settings(hidden=tuple(int(h) for h in _list(args.hidden)),
                            uniform_hidden=tuple(int(h) for h in _list(args.uniform_hidden)),
                            samples=args.samples, epochs=args.epochs, seed=args.seed,
                            models=tuple(_list(args.models)), fit_samples=args.fit_samples,
                            resolution=args.resolution, metric_samples=args.metric_samples,
                            tabulate=not args.no_tabulate, table_hidden=args.table_hidden)
    except (MissingDataError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    unknown = [m for m in settings.models if m not in af.MODELS]
    if unknown:
        print(f"error: unknown model(s) {', '.join(unknown)} (known: {', '.join(af.MODELS)})", file=sys.stderr)
        return 1
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    report = args.report or out / "fidelity.md"
    report.parent.mkdir(parents=True, exist_ok=True)
    iso_steps = 1 + len(settings.models) + len(set(settings.hidden) | {settings.table_hidden}) + len(settings.uniform_hidden)
    steps = sum(iso_steps if m.group == "isotropic" else 3 + len(anisotropic_models(settings)) for m in materials)
    start = time.perf_counter()
    rows: list[dict] = []
    with tqdm(total=steps, desc="fidelity_report", unit="row", disable=args.no_progress) as progress:
        for material in materials:
            try:
                rows += process(material, settings, out, args.cli, args.threads, progress)
            except (RuntimeError, OSError, ValueError) as error:  # CommandError included
                print(f"error: {material.name}: {error}", file=sys.stderr)
                return 1
    elapsed = time.perf_counter() - start
    command = "python -m nbrdf_tools.fidelity_report " + shlex.join(argv)
    document = {"command": command, "settings": settings.__dict__, "machine": platform.machine(),
                "cpus": os.cpu_count(), "seconds": elapsed,
                "materials": [{"name": m.name, "path": str(m.path), "source": m.source, "group": m.group,
                               "spec": m.spec} for m in materials],
                "rows": [{k: v for k, v in r.items() if k != "key"} for r in rows]}
    report.with_suffix(".json").write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
    isotropic = [m.name for m in materials if m.group == "isotropic"]
    if isotropic:
        plot(report.with_suffix(".png"), [r for r in rows if r["group"] == "isotropic"], isotropic)
    write_report(report, rows, materials, settings, command, elapsed)
    print(f"wrote {report}, {report.with_suffix('.json')}" + (f" and {report.with_suffix('.png')}" if isotropic else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
