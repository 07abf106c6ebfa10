"""``python -m nbrdf_tools library SRC... -o OUT``: the command (see the package's docstring)."""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shlex
import sys
import time
from pathlib import Path

from tqdm import tqdm

from nbrdf_tools.common import cli, progress
from nbrdf_tools.library import executors, report, sources, store
from nbrdf_tools.library.task import Settings
from nbrdf_tools.common.paths import MissingDataError, default_cli

# Bump when what a material's outputs hold changes: every material is then redone.
FORMAT_VERSION = 1
EXIT_INTERRUPTED = 130


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="python -m nbrdf_tools library",
        description="Convert a library of materials (MERL tables .binary, RGL measurements .bsdf, Mitsuba BSDFs as "
                    "load_dict .json or scene .xml) into neural BRDFs with their fitted sampling, each measured "
                    "against its own source; writes OUT/index.json, index.csv, gallery.png and index.html. "
                    "Resumable: unchanged materials with unchanged settings are not redone. Exit status 1 when "
                    "any material failed.")
    p.add_argument("sources", nargs="+", type=Path, metavar="SRC",
                   help="a source file, or a folder searched (recursively) for .binary, .bsdf, .json and .xml")
    p.add_argument("-o", "--out", type=Path, required=True, help="the library's output folder")
    p.add_argument("--train-args", default="", metavar="ARGS",
                   help="options passed to `nbrdf train` (and to the distiller for Mitsuba BSDFs, which takes "
                        "--samples, --epochs, --hidden, --batch, --lr, --target-loss, --sampling, --seed, "
                        "--threads), one string, e.g. \"--epochs 50 --samples 200000\"")
    p.add_argument("--fit-args", default="", metavar="ARGS",
                   help="options passed to `nbrdf fit-phong`, one string, e.g. \"--lobes 1\"")
    p.add_argument("--only", action="append", metavar="PATTERN",
                   help="convert only the materials whose name matches this shell pattern (repeatable, or "
                        "comma-separated); the others keep what they have")
    p.add_argument("--force", action="store_true", help="redo the selected materials even when up to date")
    p.add_argument("--executor", choices=executors.EXECUTORS, default="local",
                   help="local: a process pool (default); dask: a Dask distributed cluster (--address, or a "
                        "local cluster of --jobs workers started and stopped here)")
    p.add_argument("--jobs", type=int, default=1,
                   help="materials at once: processes of the local pool, workers of a local Dask cluster "
                        "(default: %(default)s; the trainers share the cores)")
    p.add_argument("--address", help="the scheduler of a running Dask cluster, e.g. tcp://host:8786")
    p.add_argument("--resolution", type=int, default=128,
                   help="sphere image size of the metrics and the thumbnails (default: %(default)s)")
    p.add_argument("--metric-samples", type=int, default=100_000,
                   help="directions of the log-space error, each sampling (default: %(default)s)")
    p.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf tool (default: %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (for logs)")
    args = p.parse_args(argv)
    if args.jobs < 1 or args.resolution < 8 or args.metric_samples < 1:
        p.error("--jobs must be at least 1, --resolution at least 8 and --metric-samples at least 1")
    if args.address and args.executor != "dask":
        p.error("--address needs --executor dask")
    for option in ("train_args", "fit_args"):
        try:
            setattr(args, option, tuple(shlex.split(getattr(args, option))))
        except ValueError as error:
            p.error(f"--{option.replace('_', '-')}: {error}")
    args.only = [p for value in args.only or [] for p in value.split(",") if p]
    return args


def without_threads(args: tuple[str, ...]) -> list[str]:
    """The trainer options that change its result (``--threads`` does not)."""
    kept, skip = [], False
    for a in args:
        if skip:
            skip = False
        elif a == "--threads":
            skip = True
        elif not a.startswith("--threads="):
            kept.append(a)
    return kept


def material_key(source: sources.Source, settings: Settings, version: str) -> str:
    """What a material's outputs depend on: its source's content and kind, the trainer's options,
    the metrics' settings, the tool's version and this command's format."""
    parts = {"format": FORMAT_VERSION, "source_sha256": store.file_sha256(Path(source.path)), "kind": source.kind,
             "train_args": without_threads(settings.train_args), "fit_args": without_threads(settings.fit_args),
             "resolution": settings.resolution,
             "metric_samples": settings.metric_samples, "nbrdf": version}
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()


def _threads(args) -> int | None:
    """Trainer threads per task on this machine's cores; a remote cluster's trainers take theirs."""
    if args.address:
        return None
    return max(1, (os.cpu_count() or 1) // args.jobs)


def _refused_row(refused: sources.Refused) -> dict:
    return {"name": refused.name, "kind": None, "source": refused.path, "key": None, "status": "failed",
            "error": refused.error, "wall_seconds": None}


def _pending_row(source: sources.Source, key: str, why: str) -> dict:
    return {"name": source.name, "kind": source.kind, "source": source.path, "key": key, "status": "pending",
            "error": why, "wall_seconds": None}


class _Bar:
    """One bar over the materials; its postfix shows the latest epoch of a running material."""

    def __init__(self, total: int, initial: int):
        self.bar = progress.bar(total=total, initial=initial, desc="library", unit="material", dynamic_ncols=True)
        self.epochs: dict[str, str] = {}

    def event(self, event: dict) -> None:
        self.epochs[event["name"]] = f"epoch {event['epoch']}/{event['epochs']}"
        self.bar.set_postfix_str(f"{event['name']}: {self.epochs[event['name']]}", refresh=True)

    def done(self, row: dict) -> None:
        self.epochs.pop(row["name"], None)
        if row["status"] != "ok":
            tqdm.write(f"failed: {row['name']}: {row['error']}", file=sys.stderr)
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    progress.set_enabled(not args.no_progress)
    start = time.perf_counter()
    try:
        cli.check_cli(args.cli)
        version = cli.nbrdf(args.cli, "--version").strip()
        found, refused = sources.discover(args.sources, args.out)
    except (MissingDataError, FileNotFoundError, cli.CommandError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if not found and not refused:
        print("error: no sources found (.binary, .bsdf, .json, .xml)", file=sys.stderr)
        return 1
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    removed = store.remove_temporaries(out)
    if removed:
        progress.log(f"removed {removed} temporary file(s) of an interrupted run")
    settings = Settings(cli=str(args.cli.resolve()), train_args=args.train_args, fit_args=args.fit_args,
                        resolution=args.resolution,
                        metric_samples=args.metric_samples, threads=_threads(args), progress=not args.no_progress)
    library = store.Store(out)
    selected = sources.select([s.name for s in found], args.only)
    rows: dict[str, dict] = {r.name: _refused_row(r) for r in refused}
    jobs = []
    for source in found:
        key = material_key(source, settings, version)
        stored = library.done(source.name, key)
        if source.name in selected and (stored is None or args.force):
            jobs.append((source, settings, key))
            rows[source.name] = _pending_row(source, key, "not converted yet (interrupted)")
        elif stored is not None:
            rows[source.name] = stored
        elif (earlier := library.row(source.name)) and earlier.get("key") == key:
            rows[source.name] = earlier  # a failure of these settings, not retried (--only)
        else:
            rows[source.name] = _pending_row(source, key, "not converted (not selected by --only)")
    meta = {"command": "python -m nbrdf_tools library " + shlex.join(argv), "format": FORMAT_VERSION,
            "nbrdf": version, "train_args": list(args.train_args),
            "fit_args": list(args.fit_args), "resolution": args.resolution,
            "metric_samples": args.metric_samples}
    reused = sum(1 for s in found if s.name in selected) - len(jobs)
    bar = _Bar(total=len(jobs) + reused, initial=reused)
    interrupted = False
    try:
        if jobs:
            with executors.make(args.executor, args.jobs, args.address) as executor:
                for row in executor.run(jobs, bar.event):
                    rows[row["name"]] = library.put(row)
                    bar.done(row)
    except KeyboardInterrupt:
        interrupted = True
        # A Ctrl-C can land after a row was stored and before it was counted here: the index
        # says what the folder holds.
        for source, _, key in jobs:
            if rows[source.name]["status"] == "pending" and (stored := library.done(source.name, key)):
                rows[source.name] = stored
    finally:
        bar.close()
    ordered = [rows[name] for name in sorted(rows)]
    paths = report.write_all(out, ordered, meta)
    failed = [r for r in ordered if r["status"] == "failed"]
    converted = sum(1 for source, _, _ in jobs if rows[source.name].get("status") == "ok")
    print(f"{len(ordered)} materials: {converted} converted, {reused} up to date, {len(failed)} failed"
          f" ({time.perf_counter() - start:.1f} s); wrote {paths['html']}")
    if interrupted:
        print("interrupted: run the same command again to finish", file=sys.stderr)
        return EXIT_INTERRUPTED
    return 1 if failed else 0
