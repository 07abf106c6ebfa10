"""The estimation report's headline: per set of truths, how the prior's estimate compares with the
best analytic model's on novel views.

Per material, the **ratio** is the prior's (``nbrdf``) mean novel-view RMSE over its seeds divided
by the lowest mean among the analytic models (``principled``, ``roughconductor``,
``roughplastic``). Over a set's materials: the mean, the median and the worst (largest) ratio,
the **wins** (materials whose ratio is below 1), the mean over the measured materials alone (RGL
and MERL, not Mitsuba BSDFs), the network without the prior's mean ratio, so that the prior is
seen to beat it or not, and the ceiling's (the network distilled from the truth), so that what
the network's form allows is seen beside what the estimate reaches. The test set is the headline;
the tuning set's figures are what the defaults were chosen on
(:mod:`nbrdf_tools.pages.estimation.truths`).
"""

from __future__ import annotations

import numpy as np

from nbrdf_tools.pages import estimation as report
from nbrdf_tools.pages.estimation import truths


def is_analytic(model: str) -> bool:
    return not model.startswith("nbrdf")


def per_material(cases: dict) -> dict[str, dict]:
    """material -> the means over seeds of the prior, of the network without it, of the ceiling
    and of the best analytic model (None where not measured), the ratios to that best, and the
    prior's seeds."""
    rows: dict[str, dict] = {}
    for material in dict.fromkeys(m for m, _ in cases):
        means = {model: float(np.mean(list(v.values()))) for (m, model), v in cases.items() if m == material}
        analytic = {model: v for model, v in means.items() if is_analytic(model)}
        best = min(analytic, key=analytic.get) if analytic else None
        row = {"nbrdf": means.get("nbrdf"), "no_prior": means.get("nbrdf-no-prior"), "ceiling": means.get(report.CEILING),
               "best_model": best, "best": analytic.get(best),
               "seeds": sorted(s for s in cases.get((material, "nbrdf"), {}) if s is not None)}
        for key in ("nbrdf", "no_prior", "ceiling"):
            row[f"{key}_ratio"] = row[key] / row["best"] if row[key] is not None and row["best"] else None
        rows[material] = row
    return rows


def summary(rows: dict[str, dict]) -> dict | None:
    """A set's figures over its materials with a prior's ratio (None where none has one)."""
    ratios = {m: r["nbrdf_ratio"] for m, r in rows.items() if r["nbrdf_ratio"] is not None}
    if not ratios:
        return None
    worst = max(ratios, key=ratios.get)
    measured = [v for m, v in ratios.items() if not m.startswith("mitsuba-")]
    def mean_over_all(key: str) -> float | None:
        # Over every material with a prior's ratio, or none: a mean over some would not compare.
        values = [rows[m][key] for m in ratios if rows[m][key] is not None]
        return float(np.mean(values)) if values and len(values) == len(ratios) else None

    seeds = sorted({s for m in ratios for s in rows[m]["seeds"]})
    return {"materials": len(ratios), "seeds": seeds, "mean": float(np.mean(list(ratios.values()))),
            "median": float(np.median(list(ratios.values()))), "worst": ratios[worst], "worst_material": worst,
            "wins": sum(v < 1 for v in ratios.values()), "measured_mean": float(np.mean(measured)) if measured else None,
            "measured": len(measured), "no_prior_mean": mean_over_all("no_prior_ratio"),
            "ceiling_mean": mean_over_all("ceiling_ratio")}


def seed_list(seeds) -> str:
    """Seeds as ranges (``0-5``, ``0-2, 4``); ``-`` where there are none."""
    runs: list[list[int]] = []
    for seed in sorted(seeds):
        if runs and seed == runs[-1][1] + 1:
            runs[-1][1] = seed
        else:
            runs.append([seed, seed])
    return ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs) or "-"


def _x(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}x"


def table(cases_by_set: dict[str, dict]) -> list[str]:
    """One row per set (the test set first): its materials, seeds, mean, median and worst ratio,
    wins, the measured materials' mean, and the network without the prior's and the ceiling's mean
    ratios."""
    lines = ["| set | materials | seeds | mean | median | worst | wins | mean, measured only | no prior: mean | "
             "ceiling: mean |", "|---|---|---|---|---|---|---|---|---|---|"]
    for which in truths.SETS:
        found = summary(per_material(cases_by_set.get(which, {})))
        if found is None:
            state = "no `nbrdf` estimate yet" if cases_by_set.get(which) else "not measured yet"
            lines.append(f"| {which} | - | - | {state} | - | - | - | - | - | - |")
            continue
        lines.append(f"| {which} | {found['materials']} | {seed_list(found['seeds'])} | {_x(found['mean'])} | "
                     f"{_x(found['median'])} | {_x(found['worst'])} ({found['worst_material']}) | "
                     f"{found['wins']} of {found['materials']} | "
                     + (f"{_x(found['measured_mean'])} ({found['measured']})" if found["measured"] else "-")
                     + f" | {_x(found['no_prior_mean'])} | {_x(found['ceiling_mean'])} |")
    return lines


def material_table(cases: dict) -> list[str]:
    """One row per material: the prior's, the network without it's and the best analytic model's
    mean novel-view RMSE, the ratios, the ceiling's RMSE and its ratio."""
    lines = ["| material | kind | seeds | nbrdf | no prior | best analytic | nbrdf / best | no prior / best | "
             "ceiling |", "|---|---|---|---|---|---|---|---|---|"]

    def cell(value: float | None) -> str:
        return "-" if value is None else f"{value:.4f}"

    for material, r in per_material(cases).items():
        best = "-" if r["best"] is None else f"{r['best']:.4f} ({r['best_model']})"
        lines.append(f"| {material} | {truths.kind_of(material)} | {seed_list(r['seeds'])} | {cell(r['nbrdf'])} | "
                     f"{cell(r['no_prior'])} | {best} | {_x(r['nbrdf_ratio'])} | {_x(r['no_prior_ratio'])} | "
                     f"{cell(r['ceiling'])}" + ("" if r["ceiling_ratio"] is None else f" ({_x(r['ceiling_ratio'])})")
                     + " |")
    return lines


def split_by_set(cases: dict, set_of) -> dict[str, dict]:
    """``cases`` ((material, model) -> {seed: RMSE}) per set, ``set_of(material)`` naming each's."""
    by_set: dict[str, dict] = {}
    for (material, model), values in cases.items():
        by_set.setdefault(set_of(material), {})[material, model] = values
    return by_set
