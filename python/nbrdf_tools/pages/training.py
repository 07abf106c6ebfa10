"""Train an NBRDF for every table of a set and report how close the networks are.

    python -m nbrdf_tools training --stored-only --out docs/results/training.md
    python -m nbrdf_tools training [--set sgd|rgl|all] [--materials A,B,...] [--quick] [--work DIR] [--out PAGE]

Sets (docs/design.md sections 5, 8, 9, 11, 12):

* ``sgd``: the 100 MERL materials as tables synthesised from their published SGD fits
  (``nbrdf synth --model sgd``); the reference of the metrics is the table.
* ``rgl``: the real measurements ``SHARED/data/rgl/*.bsdf`` (or ``.bsdf`` paths given with
  ``--materials``), tabulated onto the MERL grid with
  ``python -m nbrdf_mitsuba.tabulate_rgl`` (``--rgl-fold mirror`` by default: the table keeps the
  measurement's non-reciprocity, and training folds phi_d the same way); the reference of the
  metrics is Mitsuba's ``measured`` BSDF itself, the ground truth. The authors' pretrained NBRDFs
  of the same materials (``../shared/data/reference-nbrdf/rgl-isotropic/NAME.h5``, imported with
  ``nbrdf_mitsuba.import_keras``) are compared against the same ground truth.

Every material is trained with adaptive and uniform sampling (``nbrdf train``, the paper's recipe
unless ``--samples``/``--epochs`` say otherwise), one network after the other (the trainer uses
every core). Metrics (nbrdf_tools.common.compare_materials, the images and directions of ``nbrdf compare``
through Mitsuba, for both sets alike): MAE, RMSE, relMSE, PSNR with peak = max(reference)
(``psnr_peak_ref``), HDR-FLIP (``flip_hdr``) of linear sphere images under five light elevations,
SSIM (scikit-image) of the tone-mapped images, and the log-space BRDF error.

The default set, ``all``, is ``sgd`` alone when the shared data (RGL measurements) is absent:
the SGD set runs on the fits embedded in the CLI.

Outputs in ``--work`` (default out/train_report): ``results.csv`` (one row per material and
method), ``report.md`` (means and standard deviations, adaptive against uniform, ours against the
authors, worst materials, trainer speed), ``report.png`` (plots), and ``results/SET/*.json`` (one
per trained network; a rerun skips those already done with the same recipe, so an interrupted run
resumes), ``networks/`` and ``tables/`` (SGD tables are deleted once both networks of a material
are done, unless ``--keep-tables``; they take 35 MB each and are re-synthesised in a second).
With ``--out PAGE`` a run also stores its summary table in the page's data file (``--data``) and
rewrites the results page; ``--stored-only --out PAGE`` writes the page from that file alone.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path


from nbrdf_tools.common import cli
from nbrdf_tools.common.paths import REPO, MissingDataError, default_cli, default_out, shared_dir

SAMPLINGS = ("adaptive", "uniform")
METHODS = SAMPLINGS + ("authors",)
QUICK_MATERIALS = {
    "sgd": ["white-paint", "chrome", "gold-metallic-paint", "blue-fabric", "alumina-oxide"],
    "rgl": ["paper_white_rgb", "colodur_napoli_4f_rgb", "cc_ibiza_sunset_rgb", "cc_iris_purple_gem_rgb"],
}
QUICK_SAMPLES, QUICK_EPOCHS = 100_000, 10
METRICS = ("mae", "rmse", "relmse", "psnr_peak_ref", "ssim", "flip_hdr", "log_error_adaptive", "log_error_uniform")
# Stored results made with other metric definitions are recomputed.
METRICS_VERSION = 2
CSV_COLUMNS = ["set", "material", "method", "reference", *METRICS, "train_seconds", "wall_seconds", "epochs",
               "best_epoch", "stopped_early", "best_validation_loss", "samples", "sample_epochs_per_second",
               "phi_fold", "network"]


@dataclass
class Recipe:
    samples: int | None  # None: the trainer's default (the paper's 800,000)
    epochs: int | None  # None: the trainer's default (300, adaptive budget)
    min_epochs: int | None  # None: the trainer's default (30)
    patience: int | None  # None: the trainer's default (20)
    seed: int
    resolution: int
    metric_samples: int
    rgl_fold: str
    fixed_budget: bool = False  # the trainer's --fixed-budget (the paper's, the defaults before 0.2)

    def key(self, set_name: str) -> dict:
        """What a stored result must match to be reused."""
        key = {"samples": self.samples, "epochs": self.epochs, "min_epochs": self.min_epochs,
               "patience": self.patience, "seed": self.seed, "budget": "fixed" if self.fixed_budget else "adaptive",
               "resolution": self.resolution, "metric_samples": self.metric_samples, "metrics": METRICS_VERSION}
        if set_name == "rgl":
            key["phi_fold"] = self.rgl_fold
        return {k: v for k, v in key.items() if v is not None or k not in ("min_epochs", "patience")}


# --------------------------------------------------------------------------------------------
# Materials and their tables


def list_materials(set_name: str, nbrdf: Path, shared: Path) -> list[str]:
    if set_name == "sgd":
        return cli.nbrdf(nbrdf, "list-materials").split()
    folder = shared / "data" / "rgl"
    names = sorted(p.name.removesuffix(".bsdf") for p in folder.glob("*.bsdf"))
    if not names:
        raise SystemExit(f"error: no RGL measurements (*.bsdf) in {folder}")
    return names


def measured_path(shared: Path, name: str) -> Path:
    """An RGL measurement: ``name`` is a ``.bsdf`` path or a name in ``SHARED/data/rgl``."""
    if name.endswith(".bsdf"):
        return Path(name)
    return shared / "data" / "rgl" / f"{name}.bsdf"


def material_name(name: str) -> str:
    """The name of a material given by name or as a ``.bsdf`` path."""
    return Path(name).name.removesuffix(".bsdf") if name.endswith(".bsdf") else name


def table_path(out: Path, set_name: str, name: str, recipe: Recipe) -> Path:
    suffix = f".{recipe.rgl_fold}" if set_name == "rgl" else ""
    return out / "tables" / set_name / f"{material_name(name)}{suffix}.binary"


def ensure_table(out: Path, set_name: str, name: str, recipe: Recipe, nbrdf: Path, shared: Path) -> Path:
    if set_name == "rgl" and recipe.rgl_fold == "direct":  # `nbrdf train` reads the measurement itself
        return measured_path(shared, name)
    path = table_path(out, set_name, name, recipe)
    if path.is_file():
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".partial")
    if set_name == "sgd":
        cli.run([nbrdf, "synth", "--model", "sgd", "--material", name, "-o", partial])
    else:
        cli.run([sys.executable, "-m", "nbrdf_mitsuba.tabulate_rgl", measured_path(shared, name), "-o", partial,
                 "--phi-fold", recipe.rgl_fold])
    partial.replace(path)
    return path


def authors_path(shared: Path, name: str) -> Path:
    """The authors' Keras network of an RGL material (in the shared data)."""
    return shared / "data" / "reference-nbrdf" / "rgl-isotropic" / f"{material_name(name)}.h5"


# --------------------------------------------------------------------------------------------
# Training and comparing one network


def result_path(out: Path, set_name: str, name: str, method: str) -> Path:
    return out / "results" / set_name / f"{material_name(name)}.{method}.json"


def load_result(path: Path, key: dict) -> dict | None:
    try:
        result = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return result if result.get("recipe") == key else None


def metrics_of(comparison: dict) -> dict:
    mean = comparison["mean"]
    values = {k: mean[k] for k in METRICS if k in mean}
    if values["psnr_peak_ref"] is None:  # infinite (no error), null in JSON
        values["psnr_peak_ref"] = math.inf
    return {**values, "log_error_adaptive": comparison["log_error_adaptive"],
            "log_error_uniform": comparison["log_error_uniform"]}


class GroundTruth:
    """The reference BSDF of one material (Mitsuba's measured BSDF of an RGL measurement, or the
    ``merl`` BSDF of a table) and its sphere images (rendered once)."""

    def __init__(self, path: Path, resolution: int):
        from nbrdf_tools.common import compare_materials as cm

        self.bsdf = cm.load_bsdf(path)
        self.images = cm.render_spheres(self.bsdf, resolution)

    def compare(self, network: Path, recipe: Recipe) -> dict:
        from nbrdf_tools.common import compare_materials as cm

        c = cm.compare(self.bsdf, network, recipe.resolution, recipe.metric_samples, reference_images=self.images)
        return c.to_json()


def train_one(nbrdf: Path, table: Path, network: Path, sampling: str, recipe: Recipe, fold: str,
              threads: int | None) -> dict:
    cmd = [nbrdf, "train", table, "-o", network, "--sampling", sampling, "--seed", recipe.seed, "--quiet"]
    if fold != "direct":
        cmd += ["--phi-fold", fold]
    if recipe.samples is not None:
        cmd += ["--samples", recipe.samples]
    if recipe.epochs is not None:
        cmd += ["--epochs", recipe.epochs]
    if recipe.min_epochs is not None:
        cmd += ["--min-epochs", recipe.min_epochs]
    if recipe.patience is not None:
        cmd += ["--patience", recipe.patience]
    if recipe.fixed_budget:
        cmd += ["--fixed-budget"]
    if threads is not None:
        cmd += ["--threads", threads]
    network.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    cli.run(cmd)
    wall = time.perf_counter() - start
    p = json.loads(network.read_text(encoding="utf-8"))["provenance"]
    return {"train_seconds": p["seconds"], "wall_seconds": wall, "epochs": p["epochs"], "best_epoch": p["best_epoch"],
            "stopped_early": p["epochs"] < p["max_epochs"], "best_validation_loss": p["best_validation_loss"],
            "samples": p["samples"], "sample_epochs_per_second": p["samples"] * p["epochs"] / p["seconds"]}


def process_material(set_name: str, name: str, out: Path, recipe: Recipe, nbrdf: Path, shared: Path,
                     threads: int | None, authors: bool, keep_tables: bool, progress) -> list[dict]:
    """Every method of one material; returns their result records (stored ones where valid)."""
    key = recipe.key(set_name)
    methods = list(SAMPLINGS) + (["authors"] if set_name == "rgl" and authors and authors_path(shared, name).is_file()
                                 else [])
    fold = recipe.rgl_fold if set_name == "rgl" else "reciprocal"
    results, truth = [], None
    for method in methods:
        path = result_path(out, set_name, name, method)
        stored = load_result(path, key)
        if stored is not None:
            results.append(stored)
            progress.update(1)
            continue
        progress.set_postfix_str(f"{material_name(name)} {method}")
        record = {"set": set_name, "material": material_name(name), "method": method, "recipe": key,
                  "reference": "measured" if set_name == "rgl" else "table", "phi_fold": fold}
        if method == "authors":
            from nbrdf_mitsuba import import_keras

            network = out / "networks" / set_name / f"{material_name(name)}.authors.nbrdf.json"
            import_keras.convert(authors_path(shared, name), network)
            record["phi_fold"] = ""
        else:
            table = ensure_table(out, set_name, name, recipe, nbrdf, shared)
            network = out / "networks" / set_name / f"{material_name(name)}.{method}.nbrdf.json"
            record.update(train_one(nbrdf, table, network, method, recipe, fold, threads))
        if truth is None:
            # The reference: the measurement itself (RGL) or the table (SGD; the `merl` BSDF reads
            # it with the reciprocal fold the networks were trained with).
            reference = (measured_path(shared, name) if set_name == "rgl"
                         else ensure_table(out, set_name, name, recipe, nbrdf, shared))
            truth = GroundTruth(reference, recipe.resolution)
        comparison = truth.compare(network, recipe)
        record.update(metrics_of(comparison))
        record["per_light"] = comparison["per_light"]
        record["network"] = str(network.relative_to(out))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        results.append(record)
        progress.update(1)
    if set_name == "sgd" and not keep_tables:
        table_path(out, set_name, name, recipe).unlink(missing_ok=True)
    return results


# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Page:
    """A results page written from stored results: its command, file, data file, the function that
    renders it and the data section a measuring run of ``set_name`` replaces."""
    command: str
    path: Path
    data: Path
    render: Callable[[dict], str]
    section: Callable[[str, argparse.Namespace], str]
    defaults: tuple[tuple[str, str], ...] = ()  # option defaults of its measuring run


def stored_table(stored: dict) -> list[str]:
    """A stored table (``columns``, ``rows`` of cells) in Markdown."""
    return (["| " + " | ".join(stored["columns"]) + " |", "|" + "---|" * len(stored["columns"])]
            + ["| " + " | ".join(row) + " |" for row in stored["rows"]])


def stored_notes(stored: dict) -> list[str]:
    """The stored remarks on a table, one bullet each (none once the table is measured anew)."""
    return [f"* {note}" for note in stored.get("notes", [])]


def store_run(page: Page, args, argv: list[str], results: list[dict], sets: list[str]) -> None:
    """Replaces the data sections of the measured sets with this run's summary, then the page."""
    from nbrdf_tools.pages import training_report  # imports this module's constants

    data = json.loads(args.data.read_text(encoding="utf-8"))
    for s in sets:
        lines = training_report.summary_table(results, [s])
        rows = [[c.strip() for c in line.strip().strip("|").split("|")] for line in lines[2:]]
        data[page.section(s, args)] = {
            "command": " ".join([f"python -m nbrdf_tools {page.command}", *argv]),
            "machine": f"{platform.machine()}, {os.cpu_count()} logical CPUs",
            "columns": [c.strip() for c in lines[0].strip().strip("|").split("|")], "rows": rows}
    args.data.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    args.out.write_text(page.render(data), encoding="utf-8")


TEMPLATE = """# Results: training NBRDFs

```sh
python -m nbrdf_tools training --stored-only --out docs/results/training.md
```

The command above writes this page from the stored results, `{data}`. To measure anew (each
command trains its set into `out/train_report/` and replaces its table in that file and this
page):

```sh
{sgd_command}
{rgl_command}
```

The tables of this page were measured with the paper's fixed budget (`--fixed-budget`); the
trainer's defaults are an adaptive budget, whose results on the RGL measurements, and on six
MERL tables against the fixed budget, are in [rgl-training.md](rgl-training.md).

The report trains every table of a set with adaptive and uniform sampling (`nbrdf train`, one
network after the other, every core each) and writes `results.csv`, `report.md` and `report.png`
to its work folder (`--work`, default `out/train_report/`): means and standard deviations of the
metrics below, adaptive vs uniform counts, ours vs the authors, the worst materials, seconds per
network and the trainer's samples per second. Options: `--set sgd|rgl|all`, `--materials A,B`,
`--samples`, `--epochs`, `--patience`, `--quick`; an interrupted run resumes.

Sets:

* `sgd`: the 100 MERL materials synthesised from their SGD fits; the reference is the table.
* `rgl`: the four real measurements of the shared data folder, tabulated with
  `python -m nbrdf_mitsuba.tabulate_rgl --phi-fold mirror`; the reference is Mitsuba's `measured`
  BSDF itself. The authors' networks of the same materials are compared on the same ground truth.

**Metrics** (names of `nbrdf_tools.common.metrics`, the columns of `results.csv`), on 128x128 sphere
images under lights at 0, 30, 45, 60 and 75 degrees: `mae`, `rmse`, `relmse` and `psnr_peak_ref`
(PSNR with the reference's maximum as peak) of the linear images, `ssim` (scikit-image, Wang et
al.'s settings) of the tone-mapped ones, `flip_hdr` (NVIDIA's HDR-FLIP) of the linear ones, and
the log-space BRDF error over adaptively and uniformly sampled directions, `log_error_adaptive`
and `log_error_uniform` (from `nbrdf compare`). The stored SGD and RGL tables predate `relmse`,
`flip_hdr` and SSIM by scikit-image; a run measures them.

`python -m nbrdf_tools compare A B [--json]` compares any two of a table, a network or
an RGL `.bsdf` the same way. PSNR here is relative to the reference's maximum (as `nbrdf
compare`). Metric definitions: [design.md section 11](../design.md#11-metrics-and-figures); the
paper's figures: [design.md section 12](../design.md#12-reference-figures-the-paper).

## Trainer speed

`nbrdf train` at its defaults, no other flag, on the four shared RGL measurements, measured
{speed_date} on {speed_machine}: the trainer of commit `2318a90` against that of `579fb03`, both
built there (`cargo build --release -p nbrdf-core --features cli`), each material by both one
after the other under `/usr/bin/time`, two series (the second in the reverse order):

```sh
nbrdf train ../shared/data/rgl/paper_white_rgb.bsdf -q -o paper_white_rgb.nbrdf.json
python -m nbrdf_tools compare ../shared/data/rgl/paper_white_rgb.bsdf paper_white_rgb.nbrdf.json --json
```

(the same for cc_ibiza_sunset_rgb, colodur_napoli_4f_rgb and cc_iris_purple_gem_rgb; `nbrdf
fit-phong` is not included, about 3 s more per material):

{speed_table}

{speed_notes}

What was tried to make it faster and did not pay: [experiments.md](../experiments.md#training).

## SGD tables

Measured on {sgd_machine} (recipe: {sgd_recipe}):

{sgd_table}

{sgd_notes}

## RGL: ours vs the authors

Image RMSE and SSIM against Mitsuba's `measured` BSDF. Both networks have 675 weights; the
authors' were trained on the measurement directly, ours on its MERL-grid tabulation. Real
measurements need a longer run than the analytic tables; the measured-data recipe is
{rgl_recipe}:

{rgl_table}

{rgl_notes}

Training settings that were tried and not kept: [experiments.md](../experiments.md#training).
"""


def render_training(data: dict) -> str:
    """docs/results/training.md from its stored results."""
    speed, sgd, rgl = data["speed"], data["sgd"], data["rgl"]
    text = TEMPLATE.format(
        data="docs/results/data/training.json", sgd_command=sgd["command"], rgl_command=rgl["command"],
        speed_date=speed["date"], speed_machine=speed["machine"], speed_table="\n".join(stored_table(speed)),
        speed_notes="\n".join(stored_notes(speed)), sgd_machine=sgd["machine"],
        sgd_recipe=sgd.get("recipe", "as in its command"), sgd_table="\n".join(stored_table(sgd)),
        sgd_notes="\n".join(stored_notes(sgd)), rgl_recipe=rgl.get("recipe", "that of its command"),
        rgl_table="\n".join(stored_table(rgl)), rgl_notes="\n".join(stored_notes(rgl)))
    return text.replace("\n\n\n", "\n\n")


TRAINING = Page("training", Path("docs/results/training.md"), Path("docs/results/data/training.json"),
                render_training, lambda set_name, args: set_name)


def parse_args(argv, page: Page = TRAINING):
    p = argparse.ArgumentParser(
        prog=f"python -m nbrdf_tools {page.command}",
        description="Train NBRDFs on every table of a set (SGD-synthesised MERL materials, tabulated RGL "
                    "measurements) with adaptive and uniform sampling and report image-space and log-space "
                    "errors, timings, and the comparison with the authors' networks on RGL.")
    p.add_argument("--set", choices=("sgd", "rgl", "all"), default="all",
                   help="which set (default: all; sgd alone when the shared data has no RGL measurements)")
    p.add_argument("--materials", help="comma-separated subset of material names (of either set); RGL materials "
                                       "may be paths of .bsdf measurements")
    p.add_argument("--samples", type=int, help="training samples per network (default: the trainer's, 800,000)")
    p.add_argument("--epochs", type=int, help="maximum epochs (default: the trainer's, 300 with early stopping)")
    p.add_argument("--min-epochs", type=int, help="no early stopping before this epoch (default: the trainer's, 30)")
    p.add_argument("--patience", type=int,
                   help="epochs without a 0.1 %% validation improvement before the learning rate drops or "
                        "training stops (default: the trainer's, 20)")
    p.add_argument("--fixed-budget", action="store_true",
                   help="train with the paper's fixed budget (nbrdf train --fixed-budget, the defaults before 0.2)")
    p.add_argument("--quick", action="store_true",
                   help=f"a check, not a result: 5 materials per set (unless --materials), {QUICK_SAMPLES:,} samples, "
                        f"{QUICK_EPOCHS} epochs, 64x64 spheres, 20,000 metric directions (unless given)")
    p.add_argument("--out", type=Path,
                   help=f"the results page to write ({page.path}); a measuring run then also replaces its tables "
                        "in --data")
    p.add_argument("--data", type=Path, default=REPO / page.data,
                   help=f"the page's stored results (default: {page.data})")
    p.add_argument("--stored-only", action="store_true",
                   help="write the page (--out) from the stored results alone, measuring nothing")
    p.add_argument("--work", type=Path, default=default_out("train_report"),
                   help="work folder: results, report, networks, tables (default: %(default)s)")
    p.add_argument("--resolution", type=int, help="sphere image size (default: 128, nbrdf compare's)")
    p.add_argument("--metric-samples", type=int, help="directions of the log-space error (default: 100,000)")
    p.add_argument("--rgl-fold", choices=("mirror", "reciprocal", "direct"), default="mirror",
                   help="how RGL tables fold phi_d: mirror keeps the measurement's non-reciprocity (default), "
                        "reciprocal is a standard MERL table; direct: no table, `nbrdf train X.bsdf` learns "
                        "the measurement itself")
    p.add_argument("--seed", type=int, default=0, help="training seed (default: 0)")
    p.add_argument("--threads", type=int, help="trainer threads (default: one per core)")
    p.add_argument("--no-authors", action="store_true", help="skip the authors' networks on RGL")
    p.add_argument("--keep-tables", action="store_true", help="keep the synthesised SGD tables (35 MB each)")
    p.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf tool (default: %(default)s)")
    p.add_argument("--shared", type=Path, default=shared_dir(),
                   help="the shared data folder with data/rgl and data/reference-nbrdf (default: %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(**dict(page.defaults))
    return p.parse_args(argv)


def main(argv: list[str] | None = None, page: Page = TRAINING) -> int:
    from nbrdf_tools.pages import training_report  # imports this module's constants

    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv, page)
    if args.stored_only:
        if args.out is None:
            print("error: --stored-only writes the page named by --out", file=sys.stderr)
            return 2
        args.out.write_text(page.render(json.loads(args.data.read_text(encoding="utf-8"))), encoding="utf-8")
        print(f"wrote {args.out}")
        return 0
    from tqdm import tqdm

    try:
        cli.check_cli(args.cli)
    except MissingDataError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    recipe = Recipe(
        samples=args.samples if args.samples is not None else (QUICK_SAMPLES if args.quick else None),
        epochs=args.epochs if args.epochs is not None else (QUICK_EPOCHS if args.quick else None),
        min_epochs=args.min_epochs,
        patience=args.patience,
        seed=args.seed,
        resolution=args.resolution or (64 if args.quick else 128),
        metric_samples=args.metric_samples or (20_000 if args.quick else 100_000),
        rgl_fold=args.rgl_fold,
        fixed_budget=args.fixed_budget,
    )
    wanted = [m.strip() for m in args.materials.split(",") if m.strip()] if args.materials else None
    have_rgl = (args.shared / "data" / "rgl").is_dir()
    sets = ["sgd", "rgl"] if args.set == "all" else [args.set]
    if args.set == "all" and not have_rgl and not any(m.endswith(".bsdf") for m in wanted or []):
        print(f"note: {args.shared}/data/rgl not found: the RGL set is left out (pass --shared or set NBRDF_SHARED)")
        sets = ["sgd"]
    plan: list[tuple[str, str]] = []
    requested = {}
    for s in sets:
        paths = [m for m in wanted or [] if m.endswith(".bsdf")] if s == "rgl" else []
        missing = [m for m in paths if not Path(m).is_file()]
        if missing:
            print(f"error: no such RGL measurement: {', '.join(missing)}", file=sys.stderr)
            return 1
        if s == "rgl" and not have_rgl and not paths:
            print(f"error: {args.shared}/data/rgl not found (pass --shared, set NBRDF_SHARED, or give .bsdf paths "
                  "with --materials)", file=sys.stderr)
            return 1
        try:
            available = (list_materials(s, args.cli, args.shared) if s == "sgd" or have_rgl else []) + paths
        except cli.CommandError as error:
            print(f"error: {error}", file=sys.stderr)
            return 1
        if wanted is not None:
            names = [m for m in wanted if m in available]
        elif args.quick:
            names = [m for m in QUICK_MATERIALS[s] if m in available][:5]
        else:
            names = available
        requested[s] = len(names)
        plan += [(s, n) for n in names]
    if wanted is not None:
        known = {n for _, n in plan}
        unknown = [m for m in wanted if m not in known]
        if unknown:
            print(f"error: unknown material(s) in the chosen set(s): {', '.join(unknown)}", file=sys.stderr)
            return 1
    if not plan:
        print("error: no materials to train", file=sys.stderr)
        return 1
    out = args.work
    out.mkdir(parents=True, exist_ok=True)
    steps = sum(len(SAMPLINGS) + (s == "rgl" and not args.no_authors and authors_path(args.shared, n).is_file())
                for s, n in plan)
    start = time.perf_counter()
    results: list[dict] = []
    with tqdm(total=steps, desc="train_report", unit="net", disable=args.no_progress) as progress:
        for s, name in plan:
            try:
                results += process_material(s, name, out, recipe, args.cli, args.shared, args.threads,
                                            not args.no_authors, args.keep_tables, progress)
            except (RuntimeError, OSError, ValueError) as error:  # CommandError included: its stderr shown
                print(f"error: {s} {name}: {error}", file=sys.stderr)
                return 1
    training_report.write_csv(out / "results.csv", results)
    training_report.write_report(out, results, sets, recipe, requested, time.perf_counter() - start)
    training_report.plot(out / "report.png", results, sets)
    print(f"wrote {out / 'results.csv'}, {out / 'report.md'} and {out / 'report.png'}")
    if args.out is not None:
        store_run(page, args, argv, results, sets)
        print(f"wrote {args.data} and {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
