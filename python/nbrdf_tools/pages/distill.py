"""Distil Mitsuba BSDFs at the trainer's defaults and report the time and the error.

    python -m nbrdf_tools distill --stored-only --out docs/results/distill.md
    python -m nbrdf_tools distill [--out docs/results/distill.md] [--data FILE] [--work out/distill]
                                  [--cases A,B] [--samples N] [--epochs N]

With ``--stored-only`` the page is written from the stored results (``--data``, default
``docs/results/data/distill.json``) alone; without it the BSDFs are distilled and measured anew,
and both the stored results and the page are rewritten.

Each case is a dictionary for ``mi.load_dict`` (:data:`CASES`), written to ``WORK/NAME.json`` and
distilled with ``python -m nbrdf_mitsuba.distill WORK/NAME.json -o WORK/NAME.nbrdf.json`` and no
other option (the trainer's adaptive defaults) unless ``--samples``/``--epochs`` are given. The
network is then compared with the BSDF itself by :func:`nbrdf_tools.common.compare_materials.compare`
(``nbrdf compare``'s sphere images and directions; metric names of :mod:`nbrdf_tools.common.metrics`).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from nbrdf_tools.common.paths import REPO, default_out

PAGE = Path("docs/results/distill.md")
DATA = Path("docs/results/data/distill.json")
OPENING = f"python -m nbrdf_tools distill --stored-only --out {PAGE}"

CASES = {
    "roughplastic-0.1": {"type": "roughplastic", "alpha": 0.1,
                         "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.27, 0.36]}},
    "principled": {"type": "principled", "base_color": {"type": "rgb", "value": [0.8, 0.3, 0.1]},
                   "metallic": 0.3, "roughness": 0.35},
}


def distill_case(name: str, spec: dict, work: Path, extra: list[str]) -> dict:
    source, network = work / f"{name}.json", work / f"{name}.nbrdf.json"
    source.write_text(json.dumps(spec, indent=2) + "\n")
    command = [sys.executable, "-m", "nbrdf_mitsuba.distill", str(source), "-o", str(network), "-q", *extra]
    start = time.perf_counter()
    result = subprocess.run(command, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if result.returncode != 0:
        raise SystemExit(f"distill_report: {' '.join(command)} failed:\n{result.stderr}")
    provenance = json.loads(network.read_text())["provenance"]
    return {"name": name, "spec": spec, "network": str(network), "wall": wall, "provenance": provenance,
            "command": " ".join(["python -m nbrdf_mitsuba.distill", f"{name}.json", "-o", f"{name}.nbrdf.json",
                                 *extra])}


def compare_case(case: dict) -> dict:
    import mitsuba as mi

    from nbrdf_tools.common.compare_materials import compare, set_variant

    set_variant()
    comparison = compare(mi.load_dict(case["spec"]), case["network"])
    return {"log_error_adaptive": comparison.log_error_adaptive,
            "log_error_uniform": comparison.log_error_uniform, **vars(comparison.mean)}


def report(data: dict) -> str:
    """The page, from the stored results alone."""
    cases = data["cases"]
    first = cases[0]["provenance"]
    machine = data["machine"] + (f" ({data['conditions']})" if data.get("conditions") else "")
    measured = f", measured {data['date']}" if data.get("date") else ""
    lines = [
        "# Distilling Mitsuba BSDFs into networks", "",
        "```sh", OPENING, "```", "",
        f"The command above writes this page from the stored results, `{DATA}`. To measure anew (distils and measures every "
        f"BSDF, then rewrites that file and this page): `{data['command']}`.", "",
        "Each network is `python -m nbrdf_mitsuba.distill NAME.json -o NAME.nbrdf.json` (the command below "
        "each row) on the dictionary shown, at the trainer's adaptive defaults: "
        f"{first['samples']:,} training pairs (+{first['validation_samples']:,} validation), "
        f"{first['sampling']} sampling, up to {first['max_epochs']} epochs with early stopping, seed {first['seed']}. "
        f"Mitsuba ({first['distilled_from']['renderer']}, `{first['distilled_from']['variant']}`) evaluates "
        "each BSDF at the trainer's directions; the network has 675 parameters (2.7 KB as float32).", "",
        f"Machine: {machine}{measured}.", "",
        "Errors against the BSDF itself (`nbrdf_tools.common.compare_materials`: `nbrdf compare`'s 128 x 128 "
        "spheres under five light elevations, means over the lights; log error = mean "
        "|ln(1 + f cos) - ln(1 + f_net cos)| over 100,000 directions, adaptive and uniform):", "",
        "| BSDF | Mitsuba eval | training | epochs | best validation loss | log error adaptive | "
        "log error uniform | RMSE | PSNR_ref | SSIM | HDR-FLIP |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for c in cases:
        p, e = c["provenance"], c["errors"]
        lines.append(
            f"| {c['name']} | {p['distilled_from']['evaluation_seconds']:.1f} s | {p['seconds']:.1f} s | "
            f"{p['epochs']} | {p['best_validation_loss']:.2e} | {e['log_error_adaptive']:.2e} | "
            f"{e['log_error_uniform']:.2e} | {e['rmse']:.2e} | {e['psnr_peak_ref']:.1f} | {e['ssim']:.4f} | "
            f"{e['flip_hdr']:.4f} |")
    lines += ["", f"Mitsuba's evaluation of all the pairs (vectorised, `{first['distilled_from']['variant']}`) takes "
              "about a second; the time is the trainer's, as for `nbrdf train` on a table "
              "([training.md](training.md)). The log errors are the training loss's measure on directions the "
              "trainer never saw.",
              "", "The sources and commands:", ""]
    for c in cases:
        lines += [f"* `{c['name']}.json`: `{json.dumps(c['spec'])}`; "
                  f"`{c['command']}` ({c['wall']:.1f} s wall clock, Python and Mitsuba start-up included)"]
    return "\n".join(lines) + "\n"


def measure(names: list[str], work: Path, extra: list[str]) -> list[dict]:
    cases = []
    for name in names:
        case = distill_case(name, CASES[name], work, extra)
        case["errors"] = compare_case(case)
        print(f"{name}: {case['provenance']['epochs']} epochs, {case['provenance']['seconds']:.1f} s, "
              f"log error {case['errors']['log_error_uniform']:.3e}", flush=True)
        cases.append(case)
    return cases


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m nbrdf_tools distill", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=REPO / PAGE, help=f"the Markdown page (default: {PAGE})")
    parser.add_argument("--data", type=Path, default=REPO / DATA,
                        help=f"the stored results, read with --stored-only, else rewritten (default: {DATA})")
    parser.add_argument("--stored-only", action="store_true",
                        help="write the page from the stored results, measuring nothing")
    parser.add_argument("--work", type=Path, default=default_out("distill"),
                        help="sources and networks (default: %(default)s)")
    parser.add_argument("--cases", help=f"comma-separated subset of: {', '.join(CASES)}")
    parser.add_argument("--samples", type=int, help="training pairs (default: the trainer's)")
    parser.add_argument("--epochs", type=int, help="most epochs (default: the trainer's)")
    args = parser.parse_args(argv)
    names = args.cases.split(",") if args.cases else list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        parser.error(f"unknown cases {unknown} (known: {', '.join(CASES)})")
    if args.stored_only:
        data = json.loads(args.data.read_text())
    else:
        extra = [*(["--samples", str(args.samples)] if args.samples else []),
                 *(["--epochs", str(args.epochs)] if args.epochs else [])]
        args.work.mkdir(parents=True, exist_ok=True)
        words = ["python -m nbrdf_tools distill", "--out", str(PAGE),
                 *(["--cases", args.cases] if args.cases else []), *extra]
        data = {"machine": f"{platform.machine()}, {os.cpu_count()} cores",
                "date": datetime.date.today().isoformat(), "command": " ".join(words),
                "cases": measure(names, args.work, extra)}
        args.data.parent.mkdir(parents=True, exist_ok=True)
        args.data.write_text(json.dumps(data, indent=2) + "\n")
        print(f"wrote {args.data}")
    args.out.write_text(report(data))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
