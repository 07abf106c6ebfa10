"""The convergence runs' outputs: plots (error against time, log-log), the Markdown summary and
its tables, the CSV."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from nbrdf_tools.pages.scenes.metrics import series
from nbrdf_tools.pages.scenes.strategies import NBRDF_SAMPLING, STRATEGIES


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _power_of_two_axis(ax, levels) -> None:
    """spp on a log2 axis, ticks labelled 1, 2, 4, ... (every other one when crowded)."""
    from matplotlib.ticker import FixedLocator, NullLocator

    levels = sorted(levels)
    step = 1 if len(levels) <= 9 else 2
    ax.set_xscale("log", base=2)
    ax.xaxis.set_major_locator(FixedLocator(levels[::step]))
    ax.xaxis.set_minor_locator(NullLocator())
    ax.set_xticklabels([str(int(v)) for v in levels[::step]])


def _log_axes(ax) -> None:
    """Log-log axes; the x axis (render time) labelled at 1, 2, 5 x 10^k as plain numbers (the
    default minor labels such as 2x10^-1 overlap), the y axis at the decades."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())


def _curve(ax, x, curve, colour, label, ms=4):
    """Median over seeds (time order), with the min-max band when there are several seeds."""
    order = np.argsort(x)
    (line,) = ax.plot(x[order], curve["median"][order], "o-", ms=ms, color=colour, label=label)
    if curve["seeds"] > 1:
        ax.fill_between(x[order], curve["low"][order], curve["high"][order], color=colour, alpha=0.2, lw=0)
    return line


def save_figure(fig, path: Path, dpi: int = 150) -> None:
    """PNG and PDF side by side."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    fig.savefig(path.with_suffix(".pdf"))


def plot_material(path: Path, title: str, rows: list[dict], representation: float | None, metric: str = "rmse"):
    """Error against spp (power-of-two axis, with a 1/sqrt(spp) guide) and against render time
    (points in time order), one curve per strategy: the median over seeds with a min-max band."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    seeds, first = 1, []
    for i, strategy in enumerate(STRATEGIES):
        curve = series(rows, strategy, metric)
        if curve is None:
            continue
        seeds = max(seeds, curve["seeds"])
        _curve(axes[0], curve["spp"].astype(float), curve, f"C{i}", strategy)
        _curve(axes[1], curve["seconds"], curve, f"C{i}", strategy)
        first.append((curve["spp"][0], curve["median"][0]))
    levels = sorted({r["spp"] for r in rows})
    if first and len(levels) > 1:
        spp0, error0 = max(first, key=lambda p: p[1])
        guide = error0 * np.sqrt(spp0 / np.array(levels, dtype=float))
        axes[0].plot(levels, guide, color="black", ls=":", lw=1, label=r"$\propto 1/\sqrt{\mathrm{spp}}$")
    for ax, xlabel in zip(axes, ("samples per pixel", "render time (s)")):
        _log_axes(ax)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"{metric.upper()} (sampling error)")
        ax.grid(True, which="both", alpha=0.3)
        if representation is not None and representation > 0:
            ax.axhline(representation, color="grey", ls="--", lw=1, label="NBRDF vs ground truth")
    _power_of_two_axis(axes[0], levels)
    axes[0].legend(fontsize=8)
    band = f"; median of {seeds} seeds, band min-max" if seeds > 1 else ""
    fig.suptitle(title + band)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def plot_overview(path: Path, title: str, per_material: dict[str, list[dict]], metric: str = "rmse"):
    """Error against render time per material (small multiples)."""
    plt = _pyplot()
    names = list(per_material)
    cols = min(4, len(names))
    rows_n = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(3.6 * cols, 3.0 * rows_n), squeeze=False)
    colours = {s: f"C{i}" for i, s in enumerate(STRATEGIES)}
    handles = {}
    for ax, name in zip(axes.ravel(), names):
        for strategy in STRATEGIES:
            curve = series(per_material[name], strategy, metric)
            if curve is not None:
                handles[strategy] = _curve(ax, curve["seconds"], curve, colours[strategy], strategy, ms=3)
        _log_axes(ax)
        ax.set_title(name, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    fig.legend(list(handles.values()), list(handles), loc="lower right", fontsize=8)
    fig.supxlabel("render time (s)")
    fig.supylabel(f"{metric.upper()} (sampling error)")
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)


def vs_measured_table(equal_time: list[dict]) -> list[str]:
    """Markdown lines: per material with ``measured``, each NBRDF strategy's RMSE over
    measured's at equal time (median over seeds; the pooled RMSE's ratio in brackets) and the
    best; none without such materials (e.g. reports written before these fields)."""
    rows = [e for e in equal_time if "vs_measured" in e]
    if not rows:
        return []
    strategies = [s for s in STRATEGIES if s in NBRDF_SAMPLING and any(s in e["vs_measured"] for e in rows)]
    lines = ["RMSE of each NBRDF strategy over the RMSE of Mitsuba's `measured` (sampling the measurement) "
             "at the same render time, median over seeds (in brackets: root mean square over seeds); below 1 "
             "is better than `measured`:", "",
             "| material | time (s) | measured RMSE | " + " | ".join(f"{s} / measured" for s in strategies)
             + " | best |",
             "|" + "---|" * (len(strategies) + 4)]
    for e in rows:
        pooled = e.get("rmse_pooled", {})
        cells = []
        for s in strategies:
            if s not in e["vs_measured"]:
                cells.append("-")
                continue
            cell = f"{e['vs_measured'][s]:.2f}"
            if s in pooled and "measured" in pooled:
                cell += f" ({pooled[s] / pooled['measured']:.2f})"
            cells.append(cell)
        best = f"{e['best_nbrdf']} {e['best_vs_measured']:.2f}" if "best_nbrdf" in e else "-"
        lines.append(f"| {e['material']} | {e['seconds']:.2f} | {e['rmse']['measured']:.4g} | "
                     + " | ".join(cells) + f" | {best} |")
    return lines + [""]


def cost_floor_table(equal_time: list[dict]) -> list[str]:
    """Markdown lines: per material with a cost floor (``cost_floor``), each NBRDF strategy's RMSE
    and render time over measured's at the same spp, the floor BSDF's time, and the lowest
    equal-time ratio that any strategy's per-sample error allows at the floor's time; none
    without such materials."""
    rows = [e for e in equal_time if "cost_floor" in e]
    if not rows:
        return []
    floors = [e["cost_floor"] for e in rows]
    strategies = [s for s in STRATEGIES if any(s in f["per_sample"] for f in floors)]
    bsdf = floors[0]["bsdf"]
    lines = [f"Per sample and per render against `measured` at the same spp (median over seeds): RMSE / "
             f"render time, each over measured's; `{bsdf}`: the render time with `{bsdf}` plates, a BSDF that "
             "costs next to nothing (the scene's share of every render); bound: the lowest equal-time ratio "
             "to measured that a strategy's per-sample error allows if its BSDF cost nothing "
             f"(per-sample ratio x sqrt(`{bsdf}` time)), beside the best strategy's measured ratio:", "",
             "| material | spp | " + " | ".join(strategies) + f" | `{bsdf}` time | bound | best at equal time |",
             "|" + "---|" * (len(strategies) + 5)]
    for e, f in zip(rows, floors):
        cells = [f"{f['per_sample'][s]:.2f} / {f['time'][s]:.2f}" if s in f["per_sample"] else "-"
                 for s in strategies]
        lowest = min(f["bound"], key=f["bound"].get)
        best = f"{e['best_nbrdf']} {e['best_vs_measured']:.2f}" if "best_nbrdf" in e else "-"
        lines.append(f"| {e['material']} | {f['spp']} | " + " | ".join(cells)
                     + f" | {f['floor_time']:.2f} | {f['bound'][lowest]:.2f} ({lowest}) | {best} |")
    return lines + [""]


def vs_phong_fit_table(equal_time: list[dict]) -> list[str]:
    """Markdown lines: per material, each strategy's RMSE over the single lobe's (``phong-fit``)
    at equal time (median over seeds) and the file's stored default; none without phong-fit."""
    rows = [e for e in equal_time if "vs_phong_fit" in e]
    if not rows:
        return []
    strategies = [s for s in STRATEGIES if any(s in e["vs_phong_fit"] for e in rows)]
    lines = ["RMSE of each strategy over the single Blinn-Phong lobe's (`phong-fit`) at the same render time, "
             "median over seeds; below 1 is better than one lobe; `default` is the network file's "
             "`sampling.default`:", "",
             "| material | stored default | " + " | ".join(f"{s} / phong-fit" for s in strategies) + " |",
             "|" + "---|" * (len(strategies) + 2)]
    for e in rows:
        cells = [f"{e['vs_phong_fit'][s]:.2f}" if s in e["vs_phong_fit"] else "-" for s in strategies]
        lines.append(f"| {e['material']} | {e.get('default_sampling') or '-'} | " + " | ".join(cells) + " |")
    return lines + [""]


def markdown(report: dict) -> str:
    lines = []
    scene = report["settings"]["scene"]
    if report["equal_time"]:
        strategies = [s for s in STRATEGIES if any(s in e["rmse"] for e in report["equal_time"])]
        lines += [f"RMSE (sampling error{', plates only' if scene == 'veach' else ''}) at equal render time "
                  f"({report['settings']['integrator_label']}, {report['settings']['resolution'][0]}x"
                  f"{report['settings']['resolution'][1]}"
                  + (f", median of {report['settings']['seeds']} seeds" if report["settings"].get("seeds", 1) > 1 else "")
                  + "):", ""]
        header = ("| material | Phong n, w | two lobes n1, w1; n2, w2 | time (s) | " + " | ".join(strategies)
                  + " | phong-fit / cosine | phong-fit / uniform |")
        predicted = "phong-predicted" in strategies
        if predicted:
            header += " predicted n, w | phong-predicted / phong-fit |"
        lines += [header, "|" + "---|" * (header.count("|") - 1)]
        for e in report["equal_time"]:
            r = e["rmse"]
            phong = e.get("exponent")
            lobe = f"{phong:.3g}, {e['specular_weight']:.2f}" if phong is not None else "-"
            two = e.get("two_lobe_exponents")
            lobes = (f"{two[0]:.3g}, {e['two_lobe_weights'][0]:.2f}; {two[1]:.3g}, {e['two_lobe_weights'][1]:.2f}"
                     if two else "-")
            cells = [f"{r[s]:.4g}" if s in r else "-" for s in strategies]
            ratio_c = f"{r['phong-fit'] / r['cosine']:.2f}" if "phong-fit" in r and "cosine" in r else "-"
            ratio_u = f"{r['phong-fit'] / r['uniform']:.3f}" if "phong-fit" in r and "uniform" in r else "-"
            line = (f"| {e['material']} | {lobe} | {lobes} | {e['seconds']:.2f} | " + " | ".join(cells)
                    + f" | {ratio_c} | {ratio_u} |")
            if predicted:
                pn = e.get("predicted_exponent")
                plobe = f"{pn:.3g}, {e['predicted_specular_weight']:.2f}" if pn is not None else "-"
                ratio_p = (f"{r['phong-predicted'] / r['phong-fit']:.2f}"
                           if "phong-predicted" in r and "phong-fit" in r else "-")
                line += f" {plobe} | {ratio_p} |"
            lines.append(line)
        lines.append("")
        lines += vs_phong_fit_table(report["equal_time"])
        lines += vs_measured_table(report["equal_time"])
        lines += cost_floor_table(report["equal_time"])
    if report["representation"]:
        lines += [f"Representation error against the ground truth ({report['settings']['gt_spp']} spp, MIS/path, "
                  "same random numbers):", "",
                  "| material | model | network | region | MAE | RMSE | relative RMSE | relMSE | MAPE | "
                  "PSNR, peak 1 (dB) | SSIM (image) | HDR-FLIP (image) |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in report["representation"]:
            # (Reports written before relMSE, SSIM and FLIP were added show "-" there on --replot;
            # their "psnr" was the peak-1 one.)
            ssim = f"{r['ssim']:.4f}" if "ssim" in r else "-"
            flip = f"{r['flip_hdr']:.4f}" if "flip_hdr" in r else "-"
            relmse = f"{r['relmse']:.4g}" if "relmse" in r else "-"
            psnr = r.get("psnr_peak1", r.get("psnr"))
            lines.append(f"| {r['material']} | {r['model']} | {r['network']} | {r['region']} | {r['mae']:.4g} | "
                         f"{r['rmse']:.4g} | {r['relative_rmse']:.3f} | {relmse} | {r['mape']:.4g} | "
                         f"{psnr:.1f} | {ssim} | {flip} |")
        lines.append("")
    if report.get("kitchen"):
        k = report["kitchen"]
        nonfinite = k["nonfinite_pixels"]
        lines += [f"Kitchen checks: non-finite values: {nonfinite['all_strategy_renders']} in all strategy renders, "
                  f"{nonfinite['nbrdf_reference']} in the converged NBRDF, {nonfinite['nbrdf']} (NBRDF) and "
                  f"{nonfinite['merl']} (table) in the Phong-sampled {k['spp']} spp renders made with the same random "
                  f"numbers; fireflies there ({k['fireflies']['rule']}): NBRDF {k['fireflies']['nbrdf']}, table "
                  f"{k['fireflies']['merl']} of {k.get('pixels', 'all')} pixels; the replaced materials cover "
                  f"{k['overridden_pixels_percent']:.1f} % of the image.", ""]
    for note in report["notes"]:
        lines.append(f"* {note}")
    return "\n".join(lines) + "\n"


def replot(report: dict, scene_out: Path) -> None:
    """The plots of a finished run (from its JSON), e.g. after changing the plotting code."""
    per_material: dict[str, list[dict]] = {}
    for row in report["results"]:
        per_material.setdefault(row["material"], []).append(row)
    representation = {r["material"]: r["rmse"] for r in report["representation"] if r["model"] == "nbrdf"}
    scene = report["settings"]["scene"]
    label = report["settings"]["integrator_label"]
    if scene == "veach":
        integrator = report["settings"]["integrator"]
        tag = "" if integrator == "bsdf" else f"-{integrator}"
        for name, rows in per_material.items():
            plot_material(scene_out / "plots" / f"veach{tag}-{name}.png", f"Veach ({label}), {name}: error on the plates",
                          rows, representation.get(name))
        plot_overview(scene_out / "plots" / f"veach{tag}-overview.png",
                      f"Veach scene, {label}: RMSE on the plates against render time", per_material)
    else:
        for name, rows in per_material.items():
            plot_material(scene_out / "plots" / "kitchen.png",
                          f"Kitchen ({label}), {name} replaced: error on the image", rows, representation.get(name))


def write_csv(path: Path, rows: list[dict]) -> None:
    if not rows:
        return
    keys = ["scene", "material", "strategy", "spp", "seconds", "mae", "rmse", "relmse", "mape", "psnr_peak1"]
    keys += [k for k in rows[0] if k not in keys]
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
