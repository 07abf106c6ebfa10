"""The estimation report over several seeds: the stored results of one run per seed, together.

    python -m nbrdf_tools estimation-seeds --work out/estimation out/estimation-seed1 ...
        [--out seeds.md] [--stored docs/results/estimation/stored.json]

Each ``--work`` folder holds the stored results of one run of :mod:`nbrdf_tools.pages.estimation`
(same images, steps and samples; its own ``--seed``). Per material and model, the novel-view RMSE
of each seed, their mean and spread; then the report's summary of the means (the lowest model per
material, the prior over the best analytic model, the prior against no prior). A single seed's
margin of a few percent is within the estimates' spread over seeds; the mean is what compares
models. Nothing is estimated or measured here: run each seed's report first. ``--stored FILE``
writes the folders' results as the stored figures of the results page
(:mod:`nbrdf_tools.pages.estimation.page`).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from nbrdf_tools.pages import estimation as report
from nbrdf_tools.pages.estimation import truths


def stored_results(work: Path) -> list[dict]:
    """The results stored in one report's work folder, each with the folder it came from."""
    results = []
    for path in sorted(work.glob("*/*.result.json")):
        result = json.loads(path.read_text())
        result["work"] = str(work)
        results.append(result)
    return results


def seed_of(result: dict) -> int | None:
    """The estimate's seed (None for the ceiling, which is distilled, not estimated)."""
    return (result.get("settings") or {}).get("seed")


#: What a result records of its novel renders (the pairs, the estimates' and the truth's samples):
#: the keys of the report's own record, so that a key it adds is compared here too.
NOVEL_KEYS = tuple(report.novel_record(report.FULL))


def comparable(results: list[dict]) -> None:
    """Refuses results that differ in anything but their seed (views, steps, samples, the novel
    pairs and their renders' samples) and two folders holding the same seed."""
    kinds = {json.dumps({**{k: v for k, v in r["settings"].items() if k != "seed"},
                         **{k: r.get(k) for k in NOVEL_KEYS}}, sort_keys=True)
             for r in results if r.get("settings")}
    if len(kinds) > 1:
        raise SystemExit("the folders' results differ in more than their seed: " + "; ".join(sorted(kinds)))
    folders: dict[int, set[str]] = {}
    for r in results:
        if seed_of(r) is not None:
            folders.setdefault(seed_of(r), set()).add(r["work"])
    twice = {seed: works for seed, works in folders.items() if len(works) > 1}
    if twice:
        raise SystemExit("one seed in several folders: "
                         + "; ".join(f"seed {s}: {', '.join(sorted(w))}" for s, w in sorted(twice.items())))


def report_order(case: tuple[str, str]) -> tuple:
    """The report's order: its truths (the test set's, then the tuning set's), then any other by
    name; within a material its models, the ceiling last."""
    materials = truths.names("all")
    models = [*report.MODELS, report.CEILING]
    material, model = case
    return (materials.index(material) if material in materials else len(materials), material,
            models.index(model) if model in models else len(models), model)


def by_case(results: list[dict]) -> dict[tuple[str, str], dict]:
    """(material, model) -> {seed: novel-view RMSE}, in the report's order. The ceiling, which
    has no seed, counts once (the first folder holding it)."""
    cases: dict[tuple[str, str], dict] = {}
    for r in results:
        cell = cases.setdefault((r["material"], r["model"]), {})
        cell.setdefault(seed_of(r), r["rmse_tonemapped"])
    return {case: cases[case] for case in sorted(cases, key=report_order)}


def mean_results(cases: dict) -> list[dict]:
    """One result per case whose novel-view RMSE is the mean over its seeds (what
    :func:`nbrdf_tools.pages.estimation.summary` reads)."""
    return [{"material": material, "model": model, "rmse_tonemapped": float(np.mean(list(values.values())))}
            for (material, model), values in cases.items()]


def table(cases: dict, seeds: list[int]) -> list[str]:
    lines = ["| material | model | " + " | ".join(f"seed {s}" for s in seeds) + " | mean | sd |",
             "|---|---|" + "---|" * len(seeds) + "---|---|"]
    for (material, model), values in cases.items():
        if None in values:  # the ceiling: one distillation, no seed
            cells = [f"{values[None]:.4f}"] + [""] * (len(seeds) - 1)
        else:
            cells = [f"{values[s]:.4f}" if s in values else "-" for s in seeds]
        spread = np.std(list(values.values()), ddof=1) if len(values) > 1 else float("nan")
        lines.append(f"| {material} | {model} | {' | '.join(cells)} | {np.mean(list(values.values())):.4f} | "
                     + ("-" if np.isnan(spread) else f"{spread:.4f}") + " |")
    return lines


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m nbrdf_tools estimation-seeds",
                                description=__doc__.split("\n")[0])
    p.add_argument("--work", type=Path, nargs="+", required=True,
                   help="the work folders of the seeds' runs of the report, one seed each")
    p.add_argument("--out", type=Path, help="the Markdown page (default: print it, unless --stored is given)")
    p.add_argument("--stored", type=Path, metavar="FILE",
                   help="also write the folders' results as the stored figures the results page is written from "
                        "(python -m nbrdf_tools estimation --stored-only; the checked-in file is "
                        "docs/results/estimation/stored.json); where FILE exists, the figures of a set (test, "
                        "tuning) the folders hold none of are kept")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    results = []
    for work in args.work:
        found = stored_results(work)
        if not found:
            raise SystemExit(f"{work}: no stored results (run python -m nbrdf_tools estimation --work {work})")
        results += found
    comparable(results)
    cases = by_case(results)
    seeds = sorted({s for r in results if (s := seed_of(r)) is not None})
    incomplete = [f"{material} {model} ({len(v)} of {len(seeds)})" for (material, model), v in cases.items()
                  if None not in v and len(v) < len(seeds)]
    command = "python -m nbrdf_tools estimation-seeds " + " ".join(argv if argv is not None else sys.argv[1:])
    lines = ["```sh", command.strip(), "```", "",
             f"Novel-view RMSE (tone-mapped, the mean of the novel pairs) of each estimate over {len(seeds)} seeds "
             f"({', '.join(map(str, seeds))}), their mean and sample standard deviation (sd); `{report.CEILING}` has no "
             "seed. The summary below reads the means.", "",
             *table(cases, seeds), "", *report.summary(mean_results(cases)), "",
             *([f"Not run at every seed (means over fewer): {', '.join(incomplete)}.", ""] if incomplete else [])]
    text = "\n".join(lines)
    if args.stored:
        from nbrdf_tools.pages.estimation import page

        args.stored.parent.mkdir(parents=True, exist_ok=True)
        collected = page.from_results(results, args.work)
        if args.stored.is_file():  # the other set's stored figures stay
            collected = page.merged(page.load(args.stored), collected)
        args.stored.write_text(page.dump(collected))
        print(f"wrote {args.stored}")
    if args.out:
        args.out.write_text(text)
        print(f"wrote {args.out}")
    elif not args.stored:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
