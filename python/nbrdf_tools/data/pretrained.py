"""The pretrained autoencoder and Phong predictor that the ``nbrdf`` command embeds
(``nbrdf-core/data/models/``), made from the authors' networks of the 100 real MERL materials.

    python -m nbrdf_tools pretrained [--out out/pretrained] [--ae-seeds 3]

Steps (each skipped when its output is already in OUT, so an interrupted run goes on):

1. the authors' 100 Keras networks (../shared/data/reference-nbrdf/merl/) imported, tabulated
   (``nbrdf tabulate``) and re-learnt by ``nbrdf train`` from the common initialisation (seed 0)
   into OUT/nbrdfs/ (``latent_report.train_missing``; docs/results/latent.md gives the time);
2. ``nbrdf ae train --seeds K`` on them (the fixed 80/20 split) -> OUT/ae.json;
3. ``nbrdf predictor train`` with its defaults (code + highlight profile) -> OUT/predictor.json;
4. their scores on the test split: ``nbrdf ae eval --refine 30`` -> OUT/ae_eval.json and
   ``nbrdf predictor eval`` -> OUT/predictor_eval.json (docs/results/latent.md, "Built-in models");
5. both models copied compactly into nbrdf-core/data/models/ with their provenance completed:
   the family and source of their networks, the scores, this command, the git commit of step 1.
   Rebuild the CLI (``make build``) to embed them.

``--check-sgd`` instead scores the models built into ``--cli`` on other materials than they
were trained on: the test split's materials as networks of their SGD fits (``nbrdf synth --model
sgd`` + ``nbrdf train``, seed 0, into OUT/sgd-test/), by ``nbrdf predictor eval`` with no model
flags -> OUT/predictor_eval_sgd.json. Needs no shared data.
"""

from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys
from pathlib import Path

from nbrdf_tools.common import cli
from nbrdf_tools.common.materials import authors_merl, train_missing
from nbrdf_tools.common.paths import REPO, MissingDataError, default_cli, default_out, require_shared

MODELS = REPO / "nbrdf-core" / "data" / "models"
SAMPLES = 800_000
SEED = 0


def git_commit() -> str:
    result = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True)
    return result.stdout.strip() if result.returncode == 0 else "unknown"


# provenance.networks.initialisation of a family (COMMON in nbrdf-core/src/latent/family.rs).
COMMON = "common: nbrdf train from one seed"


def networks_record(nbrdfs: Path) -> dict:
    """``provenance.networks`` of the models: the family of their training networks in the form
    that ``nbrdf ae train`` writes and the CLI reads back to decide what to re-learn
    (``Family::record`` in nbrdf-core/src/latent/family.rs; the CLI test
    ``builtin_models_record_their_family`` holds the two together), and where they came from.
    Raises unless every network was trained by ``nbrdf train`` from SEED at one width."""
    provenances = [json.loads(p.read_text())["provenance"] for p in sorted(nbrdfs.glob("*.nbrdf.json"))]
    sample = provenances[0]
    odd = [p for p in provenances
           if not str(p.get("trainer", "")).startswith("nbrdf-core ") or p.get("seed") != SEED
           or p.get("hidden") != sample.get("hidden")]
    if odd:
        raise ValueError(f"{len(odd)} networks in {nbrdfs} are not of one family (nbrdf train, seed {SEED})")
    return {
        "initialisation": COMMON,
        "seed": SEED,
        "hidden": sample["hidden"],
        "trainer": sample["trainer"],
        "samples": sample["samples"],
        "materials": len(provenances),
        "source": "the authors' networks of the 100 MERL materials (Sztrajman et al. 2021, "
                  "shared data reference-nbrdf/merl/NAME.h5), imported with nbrdf_mitsuba.import_keras, "
                  "tabulated on the MERL grid (nbrdf tabulate) and re-learnt by nbrdf train",
    }


def package(model: Path, target: Path, record: dict, made_by: dict, scores: dict) -> None:
    """`model` with `record`, `made_by` and the test-split `scores` in its provenance, written
    compactly to `target`. A family the model already records (``nbrdf ae train`` writes it)
    must be this one."""
    document = json.loads(model.read_text())
    provenance = document.get("provenance") or {}
    recorded = provenance.get("networks")
    if recorded and (recorded.get("initialisation"), recorded.get("seed")) != (COMMON, SEED):
        raise ValueError(f"{model} records the networks {recorded}, not the family of {record['source']}")
    provenance["networks"] = record
    provenance["made_by"] = made_by
    provenance["test_split_scores"] = scores
    # Where the working files lay on the machine that made them says nothing to a user.
    for key in ("nbrdfs", "extra_nbrdfs"):
        if key in provenance:
            provenance[key] = "OUT/nbrdfs" if key == "nbrdfs" else "OUT/extra"
    document["provenance"] = provenance
    target.parent.mkdir(parents=True, exist_ok=True)
    # The CLI wrote the weights as the shortest decimals that round-trip float32; json keeps them.
    target.write_text(json.dumps(document, separators=(",", ":")) + "\n")
    print(f"wrote {target} ({target.stat().st_size / 1e6:.2f} MB)")


def scores(ae_eval: dict, predictor_eval: dict) -> dict:
    """What the models' provenance keeps of `ae eval` and `predictor eval` on the test split."""
    return {
        "materials": len(ae_eval["materials"]),
        "ae_image_errors": {method: {metric: figures[metric]["mean"] for metric in ("mae", "rmse", "ssim")}
                            for method, figures in ae_eval["summary"].items()},
        "ae_eval": "nbrdf ae eval --refine 30 --pca-tables nbrdf (64x64 sphere, light at 45 degrees; "
                   "means over the test split)",
        "predictor_rmse_ratio": predictor_eval["rmse_ratio"],
        "predictor_eval": "nbrdf predictor eval (sampling RMSE of the predicted lobe over the fitted one's)",
    }


def check_sgd(nbrdf: Path, out: Path) -> int:
    """`predictor eval` of the built-in models on the SGD networks of their test split."""
    try:
        cli.check_cli(nbrdf)
        test = json.loads((MODELS / "autoencoder.json").read_text())["split"]["test"]
        folder = out / "sgd-test"
        train_missing(nbrdf, folder, SAMPLES, "sgd", only=test)
        report = cli.run([nbrdf, "predictor", "eval", "--nbrdfs", folder]).stdout
    except (MissingDataError, cli.CommandError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    (out / "predictor_eval_sgd.json").write_text(report)
    summary = json.loads(report)
    for row in summary["test"]:
        print(f"{row['name']:<26} fitted n {row['fitted']['exponent']:>8.1f} w {row['fitted']['specular_weight']:.2f}  "
              f"predicted n {row['predicted']['exponent']:>8.1f} w {row['predicted']['specular_weight']:.2f}  "
              f"rmse ratio {row['rmse_ratio']:.2f}")
    print(json.dumps(summary["rmse_ratio"]))
    print(f"wrote {out / 'predictor_eval_sgd.json'}")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf tool (default: %(default)s)")
    p.add_argument("--out", type=Path, default=default_out("pretrained"),
                   help="working folder: networks and models (default: %(default)s)")
    p.add_argument("--ae-seeds", type=int, default=3, help="nbrdf ae train --seeds (default: %(default)s)")
    p.add_argument("--models", type=Path, default=MODELS, help="where the models go (default: %(default)s)")
    p.add_argument("--check-sgd", action="store_true",
                   help="score the built-in models on networks of the test split's SGD fits instead")
    args = p.parse_args(argv)
    if args.check_sgd:
        return check_sgd(args.cli, args.out)
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
    ae_eval, predictor_eval = args.out / "ae_eval.json", args.out / "predictor_eval.json"
    try:
        train_missing(args.cli, nbrdfs, SAMPLES, "authors")
        if not ae.exists():
            print(cli.run([args.cli, "ae", "train", "--nbrdfs", nbrdfs, "-o", ae, "--seed", SEED,
                           "--seeds", args.ae_seeds, "--quiet"]).stdout)
        if not predictor.exists():
            print(cli.run([args.cli, "predictor", "train", "--ae", ae, "--nbrdfs", nbrdfs, "-o", predictor]).stdout)
        if not ae_eval.exists():
            ae_eval.write_text(cli.run([args.cli, "ae", "eval", "--ae", ae, "--nbrdfs", nbrdfs, "--refine", 30,
                                        "--pca-tables", "nbrdf"]).stdout)
        if not predictor_eval.exists():
            predictor_eval.write_text(cli.run([args.cli, "predictor", "eval", "--ae", ae, "--predictor", predictor,
                                               "--nbrdfs", nbrdfs]).stdout)
        version = cli.run([args.cli, "--version"]).stdout.strip()
    except cli.CommandError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    record = networks_record(nbrdfs)
    record["from"] = "../shared/" + str(authors_merl().relative_to(authors_merl().parents[2]))
    scored = scores(json.loads(ae_eval.read_text()), json.loads(predictor_eval.read_text()))
    made_by = {"command": "python -m nbrdf_tools pretrained", "ae_seeds": args.ae_seeds, "cli": version,
               "git_commit": commit, "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")}
    package(ae, args.models / "autoencoder.json", record,
            {**made_by, "step": f"nbrdf ae train --nbrdfs OUT/nbrdfs --seed {SEED} --seeds {args.ae_seeds}"},
            scored)
    package(predictor, args.models / "predictor.json", record,
            {**made_by, "step": "nbrdf predictor train --ae OUT/ae.json --nbrdfs OUT/nbrdfs (its defaults)"},
            scored)
    return 0


if __name__ == "__main__":
    sys.exit(main())
