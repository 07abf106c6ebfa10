"""``python -m nbrdf_tools fidelity``: the options, the materials they name, the run and
its report."""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shlex
import sys
import time
from pathlib import Path

from nbrdf_tools.common import cli
from nbrdf_tools.common.paths import REPO, MissingDataError, default_cli, default_out, shared_dir
from nbrdf_tools.pages.fidelity.report import plot, write_report
from nbrdf_tools.pages.fidelity.run import anisotropic_models, process
from nbrdf_tools.pages.fidelity.settings import BUILTIN, DEFAULT_HIDDEN, DEFAULT_MODELS, PAPER_HIDDEN, Material, Settings

PAGE = Path("docs/results/fidelity.md")
DATA = PAGE.with_suffix(".json")


def _list(text: str | None) -> list[str]:
    return [t.strip() for t in (text or "").split(",") if t.strip()]


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="python -m nbrdf_tools fidelity",
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
    p.add_argument("--out", type=Path, default=REPO / PAGE,
                   help=f"the Markdown page; a measuring run writes NAME.json and NAME.png next to it (default: {PAGE})")
    p.add_argument("--work", type=Path, default=default_out("fidelity"),
                   help="work folder: networks, per-row results (default: %(default)s)")
    p.add_argument("--stored-only", action="store_true",
                   help="write the page from the stored results (--data) alone, measuring nothing")
    p.add_argument("--data", type=Path, help=f"the stored results --stored-only reads (default: {DATA})")
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
    mitsuba = _mitsuba_materials(args.mitsuba, args.work)
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
    if args.stored_only:
        write_report(args.out, json.loads((args.data or REPO / DATA).read_text(encoding="utf-8")))
        print(f"wrote {args.out}")
        return 0
    from tqdm import tqdm

    from nbrdf_tools.common import analytic_fit as af

    try:
        args.work.mkdir(parents=True, exist_ok=True)
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
    out = args.work
    report = args.out
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
    data = report.with_suffix(".json")
    regenerate = ["python -m nbrdf_tools fidelity", "--stored-only",
                  *([] if data.resolve() == (REPO / DATA).resolve() else ["--data", str(data)]), "--out", str(report)]
    document = {"command": "python -m nbrdf_tools fidelity " + shlex.join(argv), "regenerate": " ".join(regenerate),
                "page": str(report), "date": f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d}",
                "settings": settings.__dict__, "machine": platform.machine(), "cpus": os.cpu_count(),
                "seconds": elapsed,
                "materials": [{"name": m.name, "path": str(m.path), "source": m.source, "group": m.group,
                               "spec": m.spec, "plugin": m.plugin} for m in materials],
                "rows": [{k: v for k, v in r.items() if k != "key"} for r in rows]}
    data.write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
    isotropic = [m.name for m in materials if m.group == "isotropic"]
    if isotropic:
        plot(report.with_suffix(".png"), [r for r in rows if r["group"] == "isotropic"], isotropic)
    write_report(report, document)
    print(f"wrote {report}, {report.with_suffix('.json')}" + (f" and {report.with_suffix('.png')}" if isotropic else ""))
    return 0
