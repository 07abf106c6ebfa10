"""The results page, docs/results/estimation.md, written whole from the figures stored beside it.

    python -m nbrdf_tools estimation --stored-only [--stored FILE] [--out docs/results/estimation.md]

The stored file (default ``docs/results/estimation/stored.json``) holds every estimate's figures
(per material, model and seed: the novel-view RMSE, and where measured the other metrics and the
seconds) and the settings they were measured under. ``python -m nbrdf_tools estimation-seeds
--work ... --stored FILE`` writes it from the work folders of one report run per seed. The page is
a template filled from that file alone: nothing is estimated, rendered or read from a work folder,
so the page is exactly what its opening command writes. Its figure is the stored file's
``figure``, a path relative to the page and the seed of the report run that drew it.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
from pathlib import Path

import numpy as np

from nbrdf_tools.common.paths import REPO
from nbrdf_tools.pages import estimation as report
from nbrdf_tools.pages.estimation import headline, seeds, truths

#: The page and its stored figures, relative to the repository (the page's opening command).
PAGE = "docs/results/estimation.md"
STORED = "docs/results/estimation/stored.json"
#: What a stored result keeps of a work folder's result besides material, model and seed.
METRICS = ("rmse_tonemapped", "rmse_per_pair", "ssim", "flip_hdr", "log_error", "seconds", "cpu_seconds", "cores")


def default_stored() -> Path:
    return REPO / STORED


def load(path: Path) -> dict:
    stored = json.loads(path.read_text())
    missing = {"sets", "settings", "results"} - set(stored)
    if missing:
        raise SystemExit(f"{path}: not a stored estimation file (no {', '.join(sorted(missing))})")
    return stored


def dump(stored: dict) -> str:
    """The stored file's text, one setting, note or result per line (readable diffs)."""
    def block(value, open_, close, items) -> str:
        return open_ + "\n" + ",\n".join("  " + item for item in items) + "\n " + close if value else open_ + close

    fields = []
    for key, value in stored.items():
        if isinstance(value, dict):
            text = block(value, "{", "}", [f"{json.dumps(k)}: {json.dumps(v)}" for k, v in value.items()])
        elif isinstance(value, list):
            text = block(value, "[", "]", [json.dumps(v) for v in value])
        else:
            text = json.dumps(value)
        fields.append(f" {json.dumps(key)}: {text}")
    return "{\n" + ",\n".join(fields) + "\n}\n"


def results_of(stored: dict) -> list[dict]:
    """The stored results in the shape of a work folder's ``*.result.json`` (what :mod:`seeds`
    reads): an estimate's seed in its ``settings``; the ceiling, distilled, has none."""
    keys = ("views", "steps", "spp", "train_resolution")
    common = {k: stored["settings"][k] for k in keys if k in stored["settings"]}
    results = []
    for r in stored["results"]:
        result = {k: v for k, v in r.items() if k != "seed"}
        if "seed" in r:
            result["settings"] = {**common, "seed": r["seed"]}
        results.append(result)
    return results


def from_results(results: list[dict], works: list[Path]) -> dict:
    """The stored form of work folders' results (the report's run settings, today's machine)."""
    settings = next(r["settings"] for r in results if r.get("settings"))
    record = next((r for r in results if r.get("novel_pairs")), {})
    full = report.FULL
    stored_settings = {
        "training_views": report.VIEWS[: settings["views"]], "lights": [list(light) for light in report.LIGHTS],
        "views": settings["views"], "resolution": full["resolution"],
        **({"train_resolution": settings["train_resolution"]} if "train_resolution" in settings else {}),
        "reference_spp": full["reference_spp"], "steps": settings["steps"], "spp": settings["spp"], "max_depth": 3,
        "novel_pairs": record.get("novel_pairs", report.novel_setup()),
        "novel_spp": record.get("novel_spp"), "truth_spp": record.get("truth_spp"), "log_samples": 50000,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores"}
    rows, seen = [], set()
    for r in sorted(results, key=lambda r: (*seeds.report_order((r["material"], r["model"])), seeds.seed_of(r) or 0)):
        case = (r["material"], r["model"], seeds.seed_of(r))
        if case in seen:  # the ceiling, distilled once without a seed, may be in several folders
            continue
        seen.add(case)
        row = {"material": r["material"], "model": r["model"], "set": r.get("set", truths.set_of(r["material"]))}
        if seeds.seed_of(r) is not None:
            row["seed"] = seeds.seed_of(r)
        if r.get("novel"):
            r = {**r, "rmse_per_pair": [pair["rmse_tonemapped"] for pair in r["novel"]]}
        rows.append({**row, **{k: r[k] for k in METRICS if k in r}})
    first = min((seeds.seed_of(r) for r in results if seeds.seed_of(r) is not None), default=0)
    about = {"about": f"collected by python -m nbrdf_tools estimation-seeds from {', '.join(map(str, works))}.",
             "date": datetime.date.today().isoformat(), "notes": []}
    return {"sets": {which: dict(about) for which in truths.SETS if any(r["set"] == which for r in rows)},
            "figure": {"path": "images/estimation.png", "seed": first}, "settings": stored_settings, "results": rows}


def merged(earlier: dict, collected: dict) -> dict:
    """``collected`` (:func:`from_results`) with ``earlier``'s results and record of every set it
    has none of, so that measuring one set keeps the other's figures; refused where the two were
    measured under other settings (the page has one setup)."""
    def same(settings: dict) -> dict:
        return {k: v for k, v in settings.items() if k != "machine"}

    kept = [which for which in earlier["sets"] if which not in collected["sets"]]
    if kept and same(earlier["settings"]) != same(collected["settings"]):
        raise SystemExit(f"the stored {', '.join(kept)} set's figures were measured with {same(earlier['settings'])}, "
                         f"the folders' with {same(collected['settings'])}: measure every set alike")
    sets = {which: earlier["sets"][which] if which in kept else collected["sets"][which]
            for which in truths.SETS if which in kept or which in collected["sets"]}
    results = [r for r in earlier["results"] if r["set"] in kept] + collected["results"]
    figure = earlier["figure"] if "tuning" in kept else collected["figure"]
    return {**collected, "sets": sets, "figure": figure, "results": results}


def seed_list(values: dict) -> str:
    """A case's seeds as ranges (``0-5``, ``0-2, 4``); ``-`` for the ceiling, which has none."""
    return headline.seed_list(s for s in values if s is not None)


def best_analytic(cases: dict, material: str) -> float | None:
    means = [np.mean(list(v.values())) for (m, model), v in cases.items()
             if m == material and not model.startswith("nbrdf")]
    return min(means) if means else None


def prior_lower(cases: dict, material: str, model: str) -> str:
    """At how many of the seeds both were measured at the prior's RMSE is lower than ``model``'s."""
    prior = cases.get((material, "nbrdf"))
    if model in ("nbrdf", report.CEILING) or prior is None:
        return "-"
    shared = [s for s in cases[material, model] if s in prior]
    return f"{sum(prior[s] < cases[material, model][s] for s in shared)} of {len(shared)}" if shared else "-"


def table(cases: dict) -> list[str]:
    lines = ["| material | model | seeds | mean | sd | range | / best analytic | prior lower at |",
             "|---|---|---|---|---|---|---|---|"]
    for (material, model), values in cases.items():
        figures = list(values.values())
        several = len(figures) > 1
        best = best_analytic(cases, material)
        lines.append(f"| {material} | {model} | {seed_list(values)} | {np.mean(figures):.4f} | "
                     + (f"{np.std(figures, ddof=1):.4f}" if several else "-") + " | "
                     + (f"{min(figures):.4f}-{max(figures):.4f}" if several else "-") + " | "
                     + (f"{np.mean(figures) / best:.2f}x" if best else "-") + f" | {prior_lower(cases, material, model)} |")
    return lines


def seconds(results: list[dict]) -> list[str]:
    """Per set, model and seed (one report run each, whose machine load the set's notes give), the
    wall and CPU seconds of its estimates (the ceiling: its distillation, no seed), and the cores
    they ran on (where recorded)."""
    timed = [r for r in results if "seconds" in r]
    lines = ["| set | model | seed | wall seconds | median wall seconds | CPU seconds | runs | cores |",
             "|---|---|---|---|---|---|---|---|"]
    for which in truths.SETS:
        for model in [*report.MODELS, report.CEILING]:
            of_model = [r for r in timed if r["model"] == model and r["set"] == which]
            for seed in sorted({seeds.seed_of(r) for r in of_model}, key=lambda s: -1 if s is None else s):
                rows = [r for r in of_model if seeds.seed_of(r) == seed]
                wall, cpu = [r["seconds"] for r in rows], [r["cpu_seconds"] for r in rows]
                cores = sorted({r["cores"] for r in rows if "cores" in r})
                lines.append(f"| {which} | {model} | {'-' if seed is None else seed} | {min(wall):.0f}-{max(wall):.0f} | "
                             f"{np.median(wall):.0f} | {min(cpu):.0f}-{max(cpu):.0f} | {len(rows)} | "
                             f"{', '.join(map(str, cores)) or '-'} |")
    return lines


def test_set_unmeasured() -> list[str]:
    """What the page says while no test-set figure is stored: the truths, and how to measure them."""
    merl = ", ".join(f"{m} ({fit.upper()})" for m, fit, _ in truths.TEST_MERL)
    mitsuba = ", ".join(f"`{name}`" for name in truths.TEST_MITSUBA)
    return [f"**The test set has not been measured yet**: every figure on this page is the tuning set's. Its "
            f"{len(truths.heldout_names())} truths: {mitsuba}; the MERL tables of {merl}; and any RGL "
            "measurement given with `--rgl`. Measure it with the commands under "
            "[Measuring again](#measuring-again)."]


def test_set_incomplete(cases: dict) -> list[str]:
    """The test set's truths without a prior's estimate yet, where some are stored: the headline's
    figures are over the others."""
    estimated = {m for (m, model) in cases if model == "nbrdf"}
    missing = [name for name in truths.heldout_names() if name not in estimated]
    if not missing:
        return []
    partial = [name for name in missing if any(m == name for m, _ in cases)]
    over = (f"the headline is over the {len(estimated)} of its {len(truths.heldout_names())} truths with a "
            "prior's estimate" if estimated else "none of its truths has a prior's estimate")
    return [f"**The test set is measured in part**: {over}. Without one yet: "
            + ", ".join(f"`{name}`" + (" (the other models measured)" if name in partial else "") for name in missing)
            + ". Measure them with the commands under [Measuring again](#measuring-again).", ""]


def render(stored: dict, stored_arg: str | None) -> str:
    s = stored["settings"]
    results = results_of(stored)
    cases = seeds.by_case(results)
    by_set = headline.split_by_set(cases, lambda m: next(r["set"] for r in results if r["material"] == m))
    tuning_cases = by_set.get("tuning", {})
    figure = stored["figure"]
    side = s.get("train_resolution", s["resolution"])
    command = "python -m nbrdf_tools estimation --stored-only" + (f" --stored {stored_arg}" if stored_arg else "")
    pairs = "; ".join(f"({view}; {light} at {intensity:g})" for view, light, intensity in s["novel_pairs"])
    stored_link = f"[{Path(STORED).relative_to('docs/results')}]({Path(STORED).relative_to('docs/results')})"

    def record(which: str) -> str:
        found = stored["sets"].get(which)
        return f"({found['date']}): {found['about']}" if found else "(none)"

    def notes(which: str) -> list[str]:
        found = [f"* {note}" for note in stored["sets"].get(which, {}).get("notes", [])]
        return [*found, ""] if found else []

    test = ([*test_set_incomplete(by_set["test"]), f"The test set's figures {record('test')}", "",
             *headline.material_table(by_set["test"]), "", *notes("test")]
            if "test" in by_set else [*test_set_unmeasured(), ""])
    lines = [
        "```sh", f"{command} --out {PAGE}", "```", "",
        "# Material estimation from images", "",
        "How well `python -m nbrdf_mitsuba.estimate` ([estimation.md](../estimation.md)) recovers a material "
        "from a few images: every model fitted to the same images of a sphere, each estimate judged on views "
        "and lights that no image showed. The truths are split once "
        "([how estimation is judged](../estimation.md#how-estimation-is-judged)): the **test set** is the "
        "judgement, nothing was chosen on it; the **tuning set** is what the estimator's defaults were chosen on, "
        f"so its figures flatter it. This page is written from the figures stored in {stored_link}.", "",
        "## The headline: the test set", "",
        "Per material, the prior's (`nbrdf`) mean novel-view RMSE over its seeds divided by the best analytic "
        "model's mean; per set, the mean, median and worst of these ratios, the wins (ratios below 1), the "
        "mean over the measured materials alone (RGL, MERL) and the same mean for the network without the "
        f"prior and for the ceiling (`{report.CEILING}`, the network distilled from the truth: what the network's "
        "form allows).", "",
        *headline.table(by_set), "", *test,
        "## Setup", "",
        f"A sphere, {s['views']} training views ({side}x{side}, {s['reference_spp']} spp references) under "
        f"{len(s['lights'])} point lights and a dim sky. Every model is fitted to the same images: "
        f"{s['steps']} steps, {s['spp']} spp per render, prb depth {s['max_depth']}, one seed per run (the seed "
        f"changes the renders' samples, not the images). Each estimate is rendered at {len(s['novel_pairs'])} "
        f"novel (view; light) pairs, {pairs}, {s['resolution']}x{s['resolution']} at {s['novel_spp']} spp against "
        f"the truth's {s['truth_spp']} (at 128 spp the renders' own noise was most of the ceiling's error on the "
        "MERL truths). The error is the RMSE of the tone-mapped images (`x^(1/2.2)`), the mean over the pairs.", "",
        "The models: `nbrdf` (the prior), "
        "`nbrdf-no-prior` (the same network from the common initialisation), and the analytic `principled`, "
        f"`roughconductor` and `roughplastic`. `{report.CEILING}` is no estimate: the same network distilled from "
        "the truth's BRDF, not from images; its error is what the network's form leaves. "
        f"Machine: {s['machine']}.", "",
        "## The tuning set: results over seeds", "",
        "The tuning set's truths: the four shared RGL measurements (`rgl-`), two MERL tables of the "
        "autoencoder's test split, which the prior never saw (`merl-`), and a `roughplastic` (`mitsuba-`). "
        f"Its figures {record('tuning')}", "",
        "Novel-view RMSE of each material and model over the seeds it was measured at: the mean, the sample "
        "standard deviation (sd), the range, the mean over the best analytic model's mean, and at how many of "
        "the seeds both were measured at the prior's RMSE is lower than this model's. The stored figures have "
        "four decimals, so ratios of the smallest errors carry a few percent of rounding.", "",
        *table(tuning_cases), "",
        *notes("tuning"),
        f"![truth and every estimate at seed {figure['seed']}, the first novel pair]({figure['path']})",
        "",
        "From the means over seeds:", "",
        *report.summary(seeds.mean_results(tuning_cases)), "",
        "## Seconds per estimate", "",
        "Wall and CPU seconds of each estimate, over the materials, per report run (a seed; the sets' notes say "
        f"how loaded the machine was). Every model runs the same {s['steps']} steps; a step of an analytic model "
        "costs a fraction of a network's, and the prior runs more phases than the network without it. The first "
        "network estimate of a run includes compiling Mitsuba's kernels (cached afterwards).", "",
        *seconds(results), "",
        "## Measuring again", "",
        "One report run per set and seed, each in its own work folder (resumable), the folders collected into "
        "the stored file (a set the folders hold none of keeps its stored figures), then this page:", "",
        "```sh",
        "python -m nbrdf_tools estimation --set test --work out/estimation-test-seed0 --seed 0  # and seeds 1, 2",
        "python -m nbrdf_tools estimation-seeds --work out/estimation-test-seed0 out/estimation-test-seed1 "
        f"out/estimation-test-seed2 --stored {STORED}",
        f"python -m nbrdf_tools estimation --stored-only --out {PAGE}",
        "```", "",
        "`--set tuning` measures the tuning set the same way. A run's own page (`WORK/estimation.md`) adds "
        "SSIM, HDR-FLIP, the BRDF log error and the candidates the prior chose; the figure is that run's "
        "(`WORK/images/estimation.png`). For seconds of estimates alone on the machine, render the truths' "
        "images first (`--models , --no-ceiling`, in the same work folder) and run nothing else beside the "
        "estimates.", ""]
    return "\n".join(lines)


def write(stored_path: Path, out: Path, stored_arg: str | None) -> int:
    out.write_text(render(load(stored_path), stored_arg))
    print(f"wrote {out}")
    return 0
