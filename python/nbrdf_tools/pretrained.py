"""The pretrained autoencoder and Phong predictor that the ``nbrdf`` command embeds
(``nbrdf-core/data/models/``), made from the authors' networks of the 100 real MERL materials.

    python -m nbrdf_tools.pretrained [--out out/pretrained] [--ae-seeds 3]

Steps (each skipped when its output is already in OUT, so an interrupted run goes on):

1. the authors' 100 Keras networks (../shared/data/reference-nbrdf/merl/) imported, tabulated
   (``nbrdf tabulate``) and re-learnt by ``nbrdf train`` from the common initialisation (seed 0)
   into OUT/nbrdfs/ (``latent_report.train_missing``, ~100 x 15 s on 2 free cores);
2. ``nbrdf ae train --seeds K`` on them (the fixed 80/20 split) -> OUT/ae.json;
3. ``nbrdf predictor train`` with its defaults (code + highlight profile) -> OUT/predictor.json;
4. both copied into nbrdf-core/data/models/ with their provenance completed: the source
   networks, this command, the git commit. Rebuild the CLI (``make build``) to embed them.
"""

from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys
from pathlib import Path

from nbrdf_tools import cli
from nbrdf_tools.latent_report import authors_merl, train_missing
from nbrdf_tools.paths import REPO, MissingDataError, default_cli, default_out, require_shared

MODELS = REPO / "nbrdf-core" / "data" / "models"
SAMPLES = 800_000
SEED = 0


def git_commit() -> str:
    result = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True)
    return result.stdout.strip() if result.returncode == 0 else "unknown"


def networks_record(nbrdfs: Path) -> dict:
    """``provenance.networks`` of the models: the family of their training networks in the form
    that ``nbrdf ae train`` writes and the CLI reads back to decide what to re-learn
    (``Family::record`` in nbrdf-core/src/latent/family.rs; the CLI test
    ``builtin_models_record_their_family`` holds the two together), and where they came from."""
    sample = json.loads(next(iter(sorted(nbrdfs.glob("*.nbrdf.json")))).read_text())["provenance"]
    return {
        "initialisation": "common: nbrdf train from one seed",
        "seed": SEED,
        "hidden": sample["hidden"],
        "trainer": sample["trainer"],
        "samples": sample["samples"],
        "materials": len(list(nbrdfs.glob("*.nbrdf.json"))),
        "source": "the authors' networks of the 100 MERL materials (Sztrajman et al. 2021, "
                  "shared data reference-nbrdf/merl/NAME.h5), imported with nbrdf_mitsuba.import_keras, "
                  "tabulated on the MERL grid (nbrdf tabulate) and re-learnt by nbrdf train",
    }


def package(model: Path, target: Path, record: dict, step: str, commit: str) -> None:
    """`model` with `record` and the command under its provenance, written compactly to `target`."""
    document = json.loads(model.read_text())
    provenance = document.get("provenance") or {}
    provenance["networks"] = record
    provenance["made_by"] = {
        "command": "python -m nbrdf_tools.pretrained",
        "step": step,
        "git_commit": commit,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d"),
    }
    document["provenance"] = provenance
    target.parent.mkdir(parents=True, exist_ok=True)
    # The CLI wrote the weights as the shortest decimals that round-trip float32; json keeps them.
    target.write_text(json.dumps(document, separators=(",", ":")) + "\n")
    print(f"wrote {target} ({target.stat().st_size / 1e6:.2f} MB)")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf tool (default: %(default)s)")
    p.add_argument("--out", type=Path, default=default_out("pretrained"),
                   help="working folder: networks and models (default: %(default)s)")
    p.add_argument("--ae-seeds", type=int, default=3, help="nbrdf ae train --seeds (default: %(default)s)")
    p.add_argument("--models", type=Path, default=MODELS, help="where the models go (default: %(default)s)")
    args = p.parse_args(argv)
    try:
        cli.check_cli(args.cli)
        require_shared("data", "reference-nbrdf", "merl", what="the authors' MERL networks")
    except MissingDataError as error:
        print(f"error: missing inputs, nothing done: {error}", file=sys.stderr)
        return 2
    nbrdfs = args.out / "nbrdfs"
    ae, predictor = args.out / "ae.json", args.out / "predictor.json"
    # The commit of the run's first step (a resumed run keeps it).
    commit_file = args.out / "git_commit"
    if not commit_file.exists():
        args.out.mkdir(parents=True, exist_ok=True)
        commit_file.write_text(git_commit() + "\n")
    commit = commit_file.read_text().strip()
    try:
        train_missing(args.cli, nbrdfs, SAMPLES, "authors")
        if not ae.exists():
            print(cli.run([args.cli, "ae", "train", "--nbrdfs", nbrdfs, "-o", ae, "--seed", SEED,
                           "--seeds", args.ae_seeds, "--quiet"]).stdout)
        if not predictor.exists():
            print(cli.run([args.cli, "predictor", "train", "--ae", ae, "--nbrdfs", nbrdfs, "-o", predictor]).stdout)
    except cli.CommandError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    record = networks_record(nbrdfs)
    record["from"] = str(authors_merl())
    package(ae, args.models / "autoencoder.json", record,
            f"nbrdf ae train --nbrdfs NBRDFS --seed {SEED} --seeds {args.ae_seeds}", commit)
    package(predictor, args.models / "predictor.json", record,
            "nbrdf predictor train --ae AE --nbrdfs NBRDFS (defaults: code + highlight profile)", commit)
    return 0


if __name__ == "__main__":
    sys.exit(main())
