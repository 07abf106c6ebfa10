"""The report of a training run (``python -m nbrdf_tools training --work WORK``): ``results.csv``,
``report.md`` (means and standard deviations, adaptive against uniform, ours against the
authors, the worst materials, the trainer's speed) and ``report.png``; and the summary table a
results page stores (:func:`summary_table`)."""

from __future__ import annotations

import csv
import math
import os
import platform
from pathlib import Path

import numpy as np

from nbrdf_tools.pages.training import CSV_COLUMNS, METHODS, METRICS, SAMPLINGS, Recipe


def write_csv(path: Path, results: list[dict]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=CSV_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for r in results:
            writer.writerow({k: r.get(k, "") for k in CSV_COLUMNS})


def _fmt(x: float, kind: str) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if kind in ("psnr_peak_ref",):
        return f"{x:.2f}"
    if kind in ("ssim", "flip_hdr"):
        return f"{x:.4f}"
    if kind in ("seconds", "epochs"):
        return f"{x:.1f}"
    return f"{x:.3e}"


def _mean_std(values: list[float], kind: str) -> str:
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if len(v) == 0:
        return "-"
    if len(v) == 1:
        return _fmt(float(v[0]), kind)
    return f"{_fmt(float(v.mean()), kind)} ± {_fmt(float(v.std(ddof=1)), kind)}"


def _by(results, set_name, method):
    return {r["material"]: r for r in results if r["set"] == set_name and r["method"] == method}


def summary_table(results: list[dict], sets: list[str]) -> list[str]:
    lines = ["| set | method | n | image MAE | image RMSE | image relMSE | PSNR, peak max(ref) (dB) | SSIM | "
             "HDR-FLIP | log error (adaptive dirs) | log error (uniform dirs) | seconds | epochs |",
             "|---|---|---:|---|---|---|---|---|---|---|---|---|---|"]
    for s in sets:
        for method in METHODS:
            rows = list(_by(results, s, method).values())
            if not rows:
                continue
            cell = {k: _mean_std([r[k] for r in rows], k) for k in METRICS}
            secs = _mean_std([r.get("wall_seconds") for r in rows], "seconds") if method != "authors" else "-"
            epochs = _mean_std([r.get("epochs") for r in rows], "epochs") if method != "authors" else "-"
            lines.append(f"| {s} | {method} | {len(rows)} | {cell['mae']} | {cell['rmse']} | {cell['relmse']} | "
                         f"{cell['psnr_peak_ref']} | {cell['ssim']} | {cell['flip_hdr']} | {cell['log_error_adaptive']} | "
                         f"{cell['log_error_uniform']} | {secs} | {epochs} |")
    return lines


def adaptive_vs_uniform(results: list[dict], set_name: str) -> list[str]:
    a, u = _by(results, set_name, "adaptive"), _by(results, set_name, "uniform")
    common = sorted(set(a) & set(u))
    if not common:
        return []
    n = len(common)
    lines = [f"Over the {n} {set_name.upper()} materials with both networks (lower is better except "
             "PSNR and SSIM):", "",
             "| metric | adaptive better | uniform better | mean adaptive | mean uniform |",
             "|---|---:|---:|---|---|"]
    for k in METRICS:
        higher = k in ("psnr_peak_ref", "ssim")
        wins = sum((a[m][k] > u[m][k]) if higher else (a[m][k] < u[m][k]) for m in common)
        losses = sum((a[m][k] < u[m][k]) if higher else (a[m][k] > u[m][k]) for m in common)
        ma = float(np.mean([a[m][k] for m in common if math.isfinite(a[m][k])]))
        mu = float(np.mean([u[m][k] for m in common if math.isfinite(u[m][k])]))
        lines.append(f"| {k} | {wins} / {n} | {losses} / {n} | {_fmt(ma, k)} | {_fmt(mu, k)} |")
    return lines


def ours_vs_authors(results: list[dict]) -> list[str]:
    a, u, au = _by(results, "rgl", "adaptive"), _by(results, "rgl", "uniform"), _by(results, "rgl", "authors")
    common = sorted(set(a) & set(au))
    if not common:
        return []
    lines = ["| material | RMSE ours (adaptive) | RMSE ours (uniform) | RMSE authors | RMSE margin | "
             "SSIM ours (adaptive) | SSIM ours (uniform) | SSIM authors | SSIM margin | at least as close |",
             "|---|---|---|---|---:|---|---|---|---:|---|"]
    wins = 0
    for m in common:
        ra, sa = a[m]["rmse"], a[m]["ssim"]
        rau, sau = au[m]["rmse"], au[m]["ssim"]
        ru = _fmt(u[m]["rmse"], "rmse") if m in u else "-"
        su = _fmt(u[m]["ssim"], "ssim") if m in u else "-"
        better = ra <= rau and sa >= sau
        wins += better
        lines.append(f"| {m} | {_fmt(ra, 'rmse')} | {ru} | {_fmt(rau, 'rmse')} | {100 * (rau - ra) / rau:+.1f} % | "
                     f"{_fmt(sa, 'ssim')} | {su} | {_fmt(sau, 'ssim')} | {sa - sau:+.4f} | "
                     f"{'yes' if better else 'no'} |")
    ma = np.mean([a[m]["rmse"] for m in common])
    mau = np.mean([au[m]["rmse"] for m in common])
    sa_mean = np.mean([a[m]["ssim"] for m in common])
    sau_mean = np.mean([au[m]["ssim"] for m in common])
    lines.append(f"| **mean** | {_fmt(ma, 'rmse')} | | {_fmt(mau, 'rmse')} | {100 * (mau - ma) / mau:+.1f} % | "
                 f"{_fmt(sa_mean, 'ssim')} | | {_fmt(sau_mean, 'ssim')} | {sa_mean - sau_mean:+.4f} | "
                 f"{wins} / {len(common)} |")
    lines += ["", "RMSE margin: how much lower our (adaptive) RMSE is than the authors', in percent of theirs; "
              "SSIM margin: our SSIM minus theirs. Both networks have 675 weights (6-21-21-3)."]
    return lines


def worst(results: list[dict], set_name: str, method: str = "adaptive", count: int = 5) -> list[str]:
    rows = list(_by(results, set_name, method).values())
    if not rows:
        return []
    by_rmse = sorted(rows, key=lambda r: -r["rmse"])[:count]
    by_ssim = sorted(rows, key=lambda r: r["ssim"])[:count]
    return [f"* {set_name.upper()} ({method}), highest image RMSE: "
            + ", ".join(f"{r['material']} ({_fmt(r['rmse'], 'rmse')})" for r in by_rmse),
            f"* {set_name.upper()} ({method}), lowest SSIM: "
            + ", ".join(f"{r['material']} ({_fmt(r['ssim'], 'ssim')})" for r in by_ssim)]


def throughput(results: list[dict]) -> list[str]:
    trained = [r for r in results if r["method"] in SAMPLINGS and r.get("train_seconds")]
    if not trained:
        return []
    sample_epochs = sum(r["samples"] * r["epochs"] for r in trained)
    seconds = sum(r["train_seconds"] for r in trained)
    per = [r["sample_epochs_per_second"] for r in trained]
    return [f"{len(trained)} networks, {sample_epochs / 1e6:.0f} M sample-epochs in {seconds:.0f} s of training: "
            f"**{sample_epochs / seconds / 1e6:.2f} M samples/s** overall (per network "
            f"{np.mean(per) / 1e6:.2f} ± {np.std(per, ddof=1) / 1e6 if len(per) > 1 else 0:.2f} M/s; drawing the "
            "samples and the validation passes are included in the time)."]


def plot(path: Path, results: list[dict], sets: list[str]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    has_authors = any(r["method"] == "authors" for r in results)
    panels = 2 + has_authors
    fig, axes = plt.subplots(1, panels, figsize=(5.2 * panels, 4.6))
    colours = {"sgd": "tab:blue", "rgl": "tab:orange"}
    for s in sets:
        a, u = _by(results, s, "adaptive"), _by(results, s, "uniform")
        common = sorted(set(a) & set(u))
        if not common:
            continue
        for ax, value in zip(axes[:2], (lambda r: r["rmse"], lambda r: max(1.0 - r["ssim"], 1e-7))):
            ax.scatter([value(u[m]) for m in common], [value(a[m]) for m in common], s=14, color=colours[s],
                       label=f"{s} ({len(common)})")
    for ax, k in zip(axes[:2], ("image RMSE", "1 - SSIM")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        lo = min(ax.get_xlim()[0], ax.get_ylim()[0])
        hi = max(ax.get_xlim()[1], ax.get_ylim()[1])
        ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
        ax.set_xlabel(f"{k}, uniform sampling")
        ax.set_ylabel(f"{k}, adaptive sampling")
        ax.set_title(f"{k} per material (below the diagonal: adaptive better)", fontsize=9)
        ax.legend(fontsize=8)
    if has_authors:
        ax = axes[2]
        a, u, au = (_by(results, "rgl", m) for m in ("adaptive", "uniform", "authors"))
        names = sorted(set(a) & set(au))
        x = np.arange(len(names))
        w = 0.27
        ax.bar(x - w, [a[n]["rmse"] for n in names], w, label="ours, adaptive")
        ax.bar(x, [u[n]["rmse"] if n in u else 0 for n in names], w, label="ours, uniform")
        ax.bar(x + w, [au[n]["rmse"] for n in names], w, label="authors")
        ax.set_xticks(x, [n.removesuffix("_rgb") for n in names], rotation=20, fontsize=7)
        ax.set_ylabel("image RMSE against Mitsuba's measured BSDF")
        ax.set_title("RGL: ours vs the authors' NBRDFs (675 weights each)", fontsize=9)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(out: Path, results: list[dict], sets: list[str], recipe: Recipe, requested: dict,
                 elapsed: float) -> None:
    lines = ["# Training report", "",
             f"Recipe: {recipe.samples or 800_000:,} training samples, at most {recipe.epochs or 100} epochs "
             f"(early stopping on a 10 % validation set after {recipe.patience or 10} epochs without a 0.1 % "
             f"improvement, not before epoch {recipe.min_epochs or 30}), Adam 5e-4, batch 512, seed {recipe.seed}"
             + (f"; RGL tables folded by {recipe.rgl_fold} symmetry" if "rgl" in sets else "")
             + f". Metrics: {recipe.resolution}x{recipe.resolution} spheres under "
             f"lights at 0, 30, 45, 60, 75 degrees (means over the five images), log-space error over "
             f"{recipe.metric_samples:,} directions. References: SGD: the synthesised table; RGL: Mitsuba's "
             "`measured` BSDF (the measurement itself).",
             "",
             f"Machine: {platform.machine()}, {os.cpu_count()} logical CPUs, {platform.system()}; "
             f"the networks took {sum(r.get('wall_seconds') or 0 for r in results):.0f} s of `nbrdf train` in all "
             f"(this invocation: {elapsed:.0f} s; results of earlier invocations with the same recipe are reused).", ""]
    for s in sets:
        got = len({r['material'] for r in results if r['set'] == s})
        lines.append(f"* {s.upper()}: {got} of {requested[s]} requested materials done.")
    lines += ["", "## Mean ± standard deviation over materials", ""] + summary_table(results, sets)
    lines += ["", "Seconds: wall time of `nbrdf train` per network.", ""]
    for s in sets:
        table = adaptive_vs_uniform(results, s)
        if table:
            lines += [f"## Adaptive vs uniform sampling ({s.upper()})", ""] + table + [""]
    if "rgl" in sets:
        table = ours_vs_authors(results)
        if table:
            lines += ["## Ours vs authors on RGL", "",
                      "Image-space errors against Mitsuba's `measured` BSDF (ground truth).", ""] + table + [""]
    lines += ["## Worst materials", ""]
    for s in sets:
        lines += worst(results, s) + worst(results, s, "uniform")
    lines += ["", "## Trainer speed", ""] + throughput(results)
    lines += ["", "![plots](report.png)", ""]
    (out / "report.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
