"""The convergence runs' figures of merit: error against render time per strategy, the equal-time
summary over seeds, the cost floor, and the representation error of a converged render."""

from __future__ import annotations

import math

import numpy as np

from nbrdf_tools.common import metrics
from nbrdf_tools.pages.scenes.strategies import COST_FLOOR_BSDF, NBRDF_SAMPLING


def rmse_at_time(points: list[tuple[float, float]], seconds: float) -> float:
    """RMSE at a render time, interpolated log-log between measured (seconds, rmse) points;
    beyond them extrapolated with the Monte Carlo rate RMSE ~ t^(-1/2)."""
    points = sorted(points)
    ts = np.log([p[0] for p in points])
    es = np.log([p[1] for p in points])
    t = math.log(seconds)
    if t <= ts[0]:
        return float(math.exp(es[0] - 0.5 * (t - ts[0])))
    if t >= ts[-1]:
        return float(math.exp(es[-1] - 0.5 * (t - ts[-1])))
    return float(math.exp(np.interp(t, ts, es)))


def timing_repeats(spp: int) -> int:
    return 3 if spp <= 8 else 2 if spp <= 32 else 1


def series(rows: list[dict], strategy: str, metric: str = "rmse") -> dict[str, np.ndarray] | None:
    """A strategy's curve over its seeds: per spp level the median time and the median, lowest
    and highest error and the root mean square over seeds (``pooled``; for ``rmse`` the RMSE of
    all seeds' pixels together; arrays in spp order), or None when the strategy has no rows."""
    levels = sorted({r["spp"] for r in rows if r["strategy"] == strategy})
    if not levels:
        return None
    per_level = [[r for r in rows if r["strategy"] == strategy and r["spp"] == spp] for spp in levels]
    errors = [np.array([r[metric] for r in level]) for level in per_level]
    return {"spp": np.array(levels), "seconds": np.array([np.median([r["seconds"] for r in level])
                                                         for level in per_level]),
            "median": np.array([np.median(e) for e in errors]), "low": np.array([e.min() for e in errors]),
            "pooled": np.array([np.sqrt(np.mean(e ** 2)) for e in errors]),
            "high": np.array([e.max() for e in errors]), "seeds": min(len(level) for level in per_level)}


def equal_time_summary(rows: list[dict]) -> dict:
    """RMSE of every strategy at the longest render time that all strategies reached: the median
    over seeds (``rmse``) and the root mean square over seeds (``rmse_pooled``); with ``measured``
    among them, each strategy's median RMSE over measured's (``vs_measured``) and the best NBRDF
    strategy's; with ``phong-fit``, each other strategy's over the single lobe's (``vs_phong_fit``)."""
    curves = {strategy: series(rows, strategy) for strategy in dict.fromkeys(r["strategy"] for r in rows)}
    budget = min(float(curve["seconds"].max()) for curve in curves.values())
    summary = {"seconds": budget, "statistic": "median over seeds",
               "seeds": min(int(curve["seeds"]) for curve in curves.values()),
               "rmse": {s: rmse_at_time(list(zip(c["seconds"], c["median"])), budget) for s, c in curves.items()},
               "rmse_pooled": {s: rmse_at_time(list(zip(c["seconds"], c["pooled"])), budget)
                               for s, c in curves.items()}}
    if "measured" in summary["rmse"]:
        measured = summary["rmse"]["measured"]
        summary["vs_measured"] = {s: r / measured for s, r in summary["rmse"].items() if s != "measured"}
        nbrdf = {s: r for s, r in summary["vs_measured"].items() if s in NBRDF_SAMPLING}
        if nbrdf:
            best = min(nbrdf, key=nbrdf.get)
            summary.update(best_nbrdf=best, best_vs_measured=nbrdf[best])
    if "phong-fit" in summary["rmse"]:
        lobe = summary["rmse"]["phong-fit"]
        summary["vs_phong_fit"] = {s: r / lobe for s, r in summary["rmse"].items() if s != "phong-fit"}
    return summary


def cost_floor(rows: list[dict], timings: list[dict], floor: str = COST_FLOOR_BSDF) -> dict | None:
    """What the render time costs each NBRDF strategy against ``measured``, and the least any
    BSDF could cost: at the highest spp that all reached (median over seeds), each strategy's RMSE
    over measured's (``per_sample``: same samples, so the sampler's quality alone), its render
    time over measured's (``time``), and the plates rendered with ``floor`` (a BSDF that costs next
    to nothing, timed in the same runs; ``floor_time``). ``bound``: the equal-time ratio that each
    strategy's per-sample error would reach at the floor's time, i.e. if the BSDF's evaluation and
    sampling cost nothing (equal time: the RMSE ratio is the per-sample ratio times the square root
    of the time ratio). None without measured or the floor's timings."""
    floor_rows = [t for t in timings if t["strategy"] == floor]
    if not floor_rows or not any(r["strategy"] == "measured" for r in rows):
        return None
    strategies = list(dict.fromkeys(r["strategy"] for r in rows))
    spp = min(max(r["spp"] for r in rows + floor_rows if r["strategy"] == s) for s in strategies + [floor])

    def median(strategy: str, key: str, source: list[dict]) -> float:
        return float(np.median([r[key] for r in source if r["strategy"] == strategy and r["spp"] == spp]))

    measured_time, measured_rmse = median("measured", "seconds", rows), median("measured", "rmse", rows)
    if not (measured_time > 0 and measured_rmse > 0):
        return None  # nothing to compare with (a noiseless or untimed measured render)
    floor_time = median(floor, "seconds", floor_rows) / measured_time
    nbrdf = [s for s in strategies if s in NBRDF_SAMPLING]
    per_sample = {s: median(s, "rmse", rows) / measured_rmse for s in nbrdf}
    return {"bsdf": floor, "spp": spp, "statistic": "median over seeds", "floor_time": floor_time,
            "per_sample": per_sample, "time": {s: median(s, "seconds", rows) / measured_time for s in nbrdf},
            "bound": {s: r * math.sqrt(floor_time) for s, r in per_sample.items()}}


def representation_metrics(ground_truth: np.ndarray, image: np.ndarray, mask=None) -> dict:
    """The metrics of a converged render against the ground truth: the per-render ones (over the
    masked pixels), ``relative_rmse``, and ``ssim`` and ``flip_hdr`` over the whole image."""
    return {**metrics.render_metrics(ground_truth, image, mask),
            "relative_rmse": metrics.relative_rmse(ground_truth, image, mask),
            "ssim": metrics.ssim(ground_truth, image), "flip_hdr": metrics.flip_hdr(ground_truth, image)}
