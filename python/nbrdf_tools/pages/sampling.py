"""Relative variance of BSDF sampling with cosine, one Blinn-Phong lobe and two lobes, per
material: synthesise the MERL material's table (``nbrdf synth --model sgd``), train its network
(``nbrdf train``), then ``nbrdf fit-phong --lobes 2 --json`` on the table and on the network,
which searches both on the same quadrature (``nbrdf-core/src/lobe_fit.rs``). Prints a Markdown table and writes the
rows as JSON.

    python -m nbrdf_tools sampling --materials black-oxidized-steel,red-specular-plastic
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from tqdm import tqdm

from nbrdf_tools.common.cli import nbrdf
from nbrdf_tools.common.paths import default_cli

#: The issue's materials with a diffuse base under small bright lights, and three others.
DEFAULT_MATERIALS = ("black-oxidized-steel", "green-metallic-paint", "red-specular-plastic",
                     "gold-metallic-paint", "gray-plastic", "blue-metallic-paint")


def _variances(cli: Path, material_file: Path, *extra) -> dict:
    report = json.loads(nbrdf(cli, "fit-phong", material_file, "--lobes", "2", "--json", *extra))
    variance, two = report["relative_variance"], report["two_lobe"]
    return {"cosine": variance["cosine"], "one_lobe": variance["variance_lobe"], "two_lobe": variance["two_lobe"],
            "tabulated": variance["tabulated"], "table_cosine_weight": report["table_cosine_weight"],
            "default": report["default_sampling"],
            "two_lobe_n": two["exponents"], "two_lobe_w": two["weights"]}


def measure(cli: Path, material: str, work: Path, train_args: list[str] | None) -> list[dict]:
    """Rows for the material's table and, unless ``train_args`` is None, its trained network."""
    table = work / f"{material}.binary"
    nbrdf(cli, "synth", "--model", "sgd", "--material", material, "-o", table)
    rows = [{"material": material, "of": "table", **_variances(cli, table)}]
    if train_args is not None:
        network = work / f"{material}.nbrdf.json"
        nbrdf(cli, "train", table, "-o", network, "-q", *train_args)
        rows.append({"material": material, "of": "network", **_variances(cli, network, "-o", work / "fit.json")})
    table.unlink()
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| material | of | cosine | one lobe | two lobes | tabulated (cosine weight) | two/one | tabulated/one "
             "| default | two lobes (n1, w1; n2, w2) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        n, w = r["two_lobe_n"], r["two_lobe_w"]
        lines.append(f"| {r['material']} | {r['of']} | {r['cosine']:.3g} | {r['one_lobe']:.3g} | {r['two_lobe']:.3g} | "
                     f"{r['tabulated']:.3g} ({r['table_cosine_weight']:.2g}) | {r['two_lobe'] / r['one_lobe']:.2f} | "
                     f"{r['tabulated'] / r['one_lobe']:.2f} | {r['default']} | "
                     f"{n[0]:.3g}, {w[0]:.2f}; {n[1]:.3g}, {w[1]:.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--materials", default=",".join(DEFAULT_MATERIALS), help="comma-separated MERL names")
    parser.add_argument("--cli", type=Path, default=None, help="the nbrdf binary (default: the build's)")
    parser.add_argument("--train-args", default="", help="extra `nbrdf train` options, e.g. '--samples 200000'")
    parser.add_argument("--no-train", action="store_true", help="measure the synthesised tables only")
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    args = parser.parse_args(argv)
    cli = args.cli or default_cli()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for material in tqdm(args.materials.split(","), desc="materials", file=sys.stderr):
            train_args = None if args.no_train else args.train_args.split()
            rows += measure(cli, material.strip(), Path(tmp), train_args)
    print(markdown(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
