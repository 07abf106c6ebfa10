"""What a measuring run of ``python -m nbrdf_tools scenes`` adds to the stored data of
docs/results/scenes.md: the run's tables in the page's layout and its settings, under the key of
the comparison it measured (the Veach scene with pure BSDF sampling or MIS, the kitchen with the
three basic strategies or with the lobes and the table)."""

from __future__ import annotations

import datetime
import os
import platform

import numpy as np

from nbrdf_tools.pages.scenes.strategies import STRATEGIES

# Strategies of the kitchen's basic comparison; a kitchen run with any other is the comparison of
# the lobes, the table and the stored default.
KITCHEN_BASIC = {"uniform", "cosine", "phong-fit"}


def run_key(report: dict) -> str:
    settings = report["settings"]
    if settings["scene"] == "veach":
        return "veach" if settings["integrator"] == "bsdf" else "veach_mis"
    strategies = {r["strategy"] for r in report["results"]}
    return "kitchen" if strategies <= KITCHEN_BASIC else "kitchen_strategies"


def _strategies(equal_time: list[dict]) -> list[str]:
    return [s for s in STRATEGIES if any(s in e["rmse"] for e in equal_time)]


def _ratio(r: dict, a: str, b: str, digits: int) -> str:
    return f"{r[a] / r[b]:.{digits}f}" if a in r and b in r else "-"


def equal_time_table(equal_time: list[dict], lobes: bool = True) -> dict:
    """RMSE of each strategy at equal render time, with phong-fit's ratios to cosine and
    uniform (and the fitted lobe's ``n, w`` where ``lobes``)."""
    strategies = _strategies(equal_time)
    columns = ["material", *(["Phong n, w"] if lobes else []), "time (s)", *strategies,
               "phong-fit / cosine", "phong-fit / uniform"]
    rows = []
    for e in equal_time:
        r = e["rmse"]
        lobe = f"{e['exponent']:.3g}, {e['specular_weight']:.2f}" if e.get("exponent") is not None else "-"
        rows.append([e["material"], *([lobe] if lobes else []), f"{e['seconds']:.2f}",
                     *(f"{r[s]:.4g}" if s in r else "-" for s in strategies),
                     _ratio(r, "phong-fit", "cosine", 2), _ratio(r, "phong-fit", "uniform", 3)])
    return {"columns": columns, "align": "l" * len(columns), "rows": rows}


def vs_phong_fit_table(equal_time: list[dict]) -> dict:
    """RMSE of each strategy at equal render time and its ratio to the single lobe's."""
    strategies = _strategies(equal_time)
    others = [s for s in strategies if s != "phong-fit"]
    columns = ["material", "stored default", "time (s)", *strategies, *(f"{s} / phong-fit" for s in others)]
    rows = [[e["material"], e.get("default_sampling") or "-", f"{e['seconds']:.2f}",
             *(f"{e['rmse'][s]:.4g}" if s in e["rmse"] else "-" for s in strategies),
             *(_ratio(e["rmse"], s, "phong-fit", 2) for s in others)] for e in equal_time]
    return {"columns": columns, "align": "l" * len(columns), "rows": rows}


def equal_spp_table(results: list[dict]) -> dict:
    """At the highest spp: each strategy's median RMSE over seeds, its ratio to phong-fit's and
    its median render time."""
    top = max(r["spp"] for r in results)
    at_top = [r for r in results if r["spp"] == top]
    rows, median = [], {}
    for s in STRATEGIES:
        mine = [r for r in at_top if r["strategy"] == s]
        if mine:
            median[s] = (float(np.median([r["rmse"] for r in mine])), float(np.median([r["seconds"] for r in mine])))
    for s, (rmse, seconds) in median.items():
        ratio = f"{rmse / median['phong-fit'][0]:.2f}" if "phong-fit" in median else "-"
        rows.append([s, f"{rmse:.3g}", ratio, f"{seconds:.2f}"])
    columns = ["strategy", f"RMSE at {top} spp", "/ phong-fit", "time (s)"]
    return {"columns": columns, "align": "l" * len(columns), "rows": rows}


def representation_table(representation: list[dict]) -> dict:
    columns = ["material", "model", "network", "region", "MAE", "RMSE", "relative RMSE", "MAPE", "PSNR (dB)"]
    rows = [[r["material"], r["model"], r["network"], r["region"], f"{r['mae']:.4g}", f"{r['rmse']:.4g}",
             f"{r['relative_rmse']:.3f}", f"{r['mape']:.4g}", f"{r.get('psnr_peak1', r.get('psnr')):.1f}"]
            for r in representation]
    return {"columns": columns, "align": "l" * len(columns), "rows": rows}


def machine() -> str:
    return f"{os.cpu_count()}-core CPU ({platform.machine()}, {platform.system()})"


def run_settings(report: dict) -> dict:
    """The settings a run was measured under, as the page states them."""
    s = report["settings"]
    return {"date": datetime.date.today().isoformat(), "machine": machine(), "variant": s["variant"],
            "resolution": list(s["resolution"]), "spp": [1, s["max_spp"]], "gt_spp": s["gt_spp"],
            "seeds": s.get("seeds", 1), "training": " ".join(s["train_args"]) or "default recipe",
            "seconds": s["seconds"]}


def update(data: dict, report: dict) -> str:
    """Put the run's tables and settings into ``data`` (the stored data of the page); the key of
    the comparison replaced."""
    key = run_key(report)
    tables, run = data.setdefault("tables", {}), run_settings(report)
    if key == "kitchen_strategies":
        tables[key] = vs_phong_fit_table(report["equal_time"])
        tables[f"{key}_equal_spp"] = equal_spp_table(report["results"])
        rep = next(r for r in report["representation"] if r["region"] == "image")
        run["representation"] = {"rmse": round(rep["rmse"], 4), "relative_rmse": round(rep["relative_rmse"], 4)}
    else:
        tables[key] = equal_time_table(report["equal_time"], lobes=key != "kitchen")
        if key != "veach_mis":
            tables[f"{key}_representation"] = representation_table(report["representation"])
    if report.get("kitchen"):
        k = report["kitchen"]
        run["checks"] = {"spp": k["spp"], "pixels": k["pixels"],
                         "nonfinite": sum(v for v in k["nonfinite_pixels"].values()),
                         "fireflies_nbrdf": k["fireflies"]["nbrdf"], "fireflies_table": k["fireflies"]["merl"],
                         "replaced_percent": round(k["overridden_pixels_percent"])}
    data.setdefault("runs", {})[key] = run
    return key
