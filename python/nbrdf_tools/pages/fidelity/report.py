"""The fidelity report: its tables, verdicts and summaries, the plot of error against memory,
and the Markdown page."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from nbrdf_tools.pages.fidelity.settings import (BUILTIN, FRAME_TURNS_DEG, HIGHER_IS_BETTER, MERL_TABLE_BYTES, Material,
                                                Settings, weight_count)


def _fmt(x, kind: str = "e") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if kind == "f4":
        return f"{x:.4f}"
    if kind == "s":
        return f"{x:.1f}"
    return f"{x:.3e}"


def _bytes(n) -> str:
    if n is None:
        return "-"
    if n >= 1 << 20:
        return f"{n / (1 << 20):.1f} MiB"
    if n >= 1 << 10:
        return f"{n / (1 << 10):.1f} KiB"
    return f"{n} B"

METRIC_COLUMNS = [("mae_tonemapped", "tone-mapped MAE", "e"), ("rmse_tonemapped", "tone-mapped RMSE", "e"),
                  ("ssim", "SSIM", "f4"), ("flip_hdr", "HDR-FLIP", "f4"),
                  ("log_error_adaptive", "log error (adaptive dirs)", "e"),
                  ("log_error_uniform", "log error (uniform dirs)", "e")]


def _metric_cells(row: dict) -> list[str]:
    if row.get("metrics") is None:
        return ["0 (reference)" if i == 0 else "" for i in range(len(METRIC_COLUMNS))]
    return [_fmt(row["metrics"][k], kind) for k, _, kind in METRIC_COLUMNS]

ANISOTROPIC_LABELS = {"log_error_adaptive": "log error (adaptive dirs, turned)"}


def representation_table(rows: list[dict], material: str, table_hidden: int, labels: dict | None = None) -> list[str]:
    mine = [r for r in rows if r["material"] == material]
    chosen = [r for r in mine if r["kind"] == "nbrdf" and r["hidden"] == table_hidden]
    chosen += [r for r in mine if r["kind"] == "fit"] + [r for r in mine if r["kind"] == "reference"]
    labels = labels or {}
    lines = ["| representation | stored values | memory | fit / train s | "
             + " | ".join(labels.get(k, label) for k, label, _ in METRIC_COLUMNS) + " |",
             "|---|---:|---:|---:|" + "---:|" * len(METRIC_COLUMNS)]
    for r in chosen:
        stored = f"{r['stored_values']:,}" if r.get("stored_values") else "-"
        seconds = _fmt(r.get("seconds"), "s")
        if r["method"] == "merl-table" and r.get("seconds") is not None:
            seconds += " (tabulation)"
        lines.append(f"| {r['label']} | {stored} | {_bytes(r['memory_bytes'])} | {seconds} | "
                     + " | ".join(_metric_cells(r)) + " |")
    return lines


def sweep_rows(rows: list[dict], material: str) -> list[dict]:
    return sorted((r for r in rows if r["material"] == material and r["kind"] == "nbrdf"
                   and r["sampling"] == "adaptive"), key=lambda r: r["hidden"])


def sweep_table(rows: list[dict], materials: list[str]) -> list[str]:
    lines = ["| material | hidden | weights | float32 memory | JSON file | train s | epochs | tone-mapped RMSE | "
             "SSIM | HDR-FLIP | log error (adaptive dirs) | log error (uniform dirs) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for m in materials:
        for r in sweep_rows(rows, m):
            x = r["metrics"]
            lines.append(f"| {m} | {r['hidden']} | {r['stored_values']:,} | {_bytes(r['memory_bytes'])} | "
                         f"{_bytes(r['file_bytes'])} | {_fmt(r['seconds'], 's')} | {r['epochs']} | "
                         f"{_fmt(x['rmse_tonemapped'])} | {_fmt(x['ssim'], 'f4')} | {_fmt(x['flip_hdr'], 'f4')} | "
                         f"{_fmt(x['log_error_adaptive'])} | {_fmt(x['log_error_uniform'])} |")
    return lines


def _spearman(x, y) -> float:
    rx = np.argsort(np.argsort(x)).astype(float)
    ry = np.argsort(np.argsort(y)).astype(float)
    if rx.std() == 0 or ry.std() == 0:
        return float("nan")
    return float(np.corrcoef(rx, ry)[0, 1])


def sweep_trend(rows: list[dict], materials: list[str]) -> list[str]:
    """Per material: does the error fall with size? (Spearman rank correlation, increases)."""
    lines = []
    for m in materials:
        s = sweep_rows(rows, m)
        if len(s) < 2:
            continue
        parts = []
        for key, label in (("log_error_adaptive", "log error"), ("rmse_tonemapped", "tone-mapped RMSE")):
            e = [r["metrics"][key] for r in s]
            ups = [f"{s[i]['stored_values']} -> {s[i + 1]['stored_values']}" for i in range(len(s) - 1)
                   if e[i + 1] > e[i]]
            parts.append(f"{label} from {_fmt(e[0])} to {_fmt(e[-1])} (x{e[0] / max(e[-1], 1e-300):.1f}), "
                         f"rank correlation with size {_spearman([r['stored_values'] for r in s], e):+.2f}"
                         + (f", rises at {', '.join(ups)}" if ups else ", never rises"))
        lines.append(f"* {m}: " + "; ".join(parts) + ".")
    return lines


def fit_verdicts(rows: list[dict], materials: list[str], table_hidden: int) -> tuple[list[str], list[str]]:
    """A table of NBRDF-675 (adaptive) against each fit per material (which wins each metric),
    and sentences naming every metric a fit wins."""
    lines = ["| material | fit | " + " | ".join(label for _, label, _ in METRIC_COLUMNS) + " |",
             "|---|---|" + "---|" * len(METRIC_COLUMNS)]
    wins = []
    for m in materials:
        net = [r for r in rows if r["material"] == m and r["kind"] == "nbrdf" and r["hidden"] == table_hidden
               and r["sampling"] == "adaptive"]
        if not net:
            continue
        net = net[0]["metrics"]
        for r in (r for r in rows if r["material"] == m and r["kind"] == "fit"):
            cells, won = [], []
            for k, label, kind in METRIC_COLUMNS:
                a, b = net[k], r["metrics"][k]
                fit_better = b > a if k in HIGHER_IS_BETTER else b < a
                cells.append(("**fit**" if fit_better else "NBRDF") + f" ({_fmt(b, kind)})")
                if fit_better:
                    won.append(f"{label} ({_fmt(b, kind)} against {_fmt(a, kind)})")
            lines.append(f"| {m} | {r['label']} | " + " | ".join(cells) + " |")
            if won:
                wins.append(f"* {m}: {r['label']} beats NBRDF-{weight_count(table_hidden)} in " + ", ".join(won) + ".")
    return lines, wins


def summary(rows: list[dict], materials: list[str], table_hidden: int) -> list[str]:
    """Per material: the best fit against NBRDF-n in log error and FLIP, the smallest network that
    beats the best fit, and the network against the MERL table."""
    n = weight_count(table_hidden)
    lines = []
    for m in materials:
        mine = [r for r in rows if r["material"] == m]
        net = [r for r in mine if r["kind"] == "nbrdf" and r["hidden"] == table_hidden and r["sampling"] == "adaptive"]
        fits = [r for r in mine if r["kind"] == "fit"]
        if not net or not fits:
            continue
        net = net[0]["metrics"]
        parts = []
        for key, name in (("log_error_adaptive", "log error"), ("flip_hdr", "HDR-FLIP")):
            best = min(fits, key=lambda r: r["metrics"][key])
            b, a = best["metrics"][key], net[key]
            verdict = (f"NBRDF-{n} is {b / a:.1f}x lower" if a < b else f"**the fit is {a / b:.2f}x lower**")
            parts.append(f"best fit in {name}: {best['label']} ({_fmt(b, 'e' if key.startswith('log') else 'f4')} "
                         f"against {_fmt(a, 'e' if key.startswith('log') else 'f4')}: {verdict})")
        best = min(fits, key=lambda r: r["metrics"]["log_error_adaptive"])["metrics"]["log_error_adaptive"]
        smaller = [r for r in sweep_rows(rows, m) if r["metrics"]["log_error_adaptive"] < best]
        parts.append("the smallest network below the best fit's log error: "
                     + (f"{smaller[0]['stored_values']} weights" if smaller else "none of the sweep"))
        table = [r for r in mine if r["method"] == "merl-table" and r.get("metrics")]
        if table:
            t = table[0]["metrics"]["log_error_adaptive"]
            parts.append(f"MERL table log error {_fmt(t)} ({'above' if t > net['log_error_adaptive'] else 'below'} "
                         f"NBRDF-{n}'s, in {table[0]['memory_bytes'] / (4 * n):,.0f}x the memory)")
        lines.append(f"* **{m}**: " + "; ".join(parts) + ".")
    return lines


def fits_against_small_networks(rows: list[dict], materials: list[str], table_hidden: int) -> list[str]:
    """Per material: the fits that beat the sweep's networks smaller than the table's, in log
    error and in HDR-FLIP (where the fits do win)."""
    lines = []
    for m in materials:
        fits = [r for r in rows if r["material"] == m and r["kind"] == "fit"]
        parts = []
        for r in sweep_rows(rows, m):
            if r["hidden"] >= table_hidden:
                continue
            for key, name in (("log_error_adaptive", "log error"), ("flip_hdr", "HDR-FLIP")):
                winners = [f["label"] for f in fits if f["metrics"][key] < r["metrics"][key]]
                if winners:
                    parts.append(f"{', '.join(winners)} beat the {r['stored_values']}-weight network in {name}")
        if parts:
            lines.append(f"* {m}: " + "; ".join(parts) + ".")
    return lines


def fit_summary(rows: list[dict], materials: list[str], table_hidden: int) -> list[str]:
    """One sentence per fitted model: on how many materials it beats the network, per metric."""
    lines = []
    n = weight_count(table_hidden)
    for model in dict.fromkeys(r["method"] for r in rows if r["kind"] == "fit"):
        counts = []
        label = None
        for k, name, _ in METRIC_COLUMNS:
            won, total = [], 0
            for m in materials:
                net = [r for r in rows if r["material"] == m and r["kind"] == "nbrdf" and r["hidden"] == table_hidden
                       and r["sampling"] == "adaptive"]
                fit = [r for r in rows if r["material"] == m and r["method"] == model]
                if not net or not fit:
                    continue
                label = fit[0]["label"]
                total += 1
                a, b = net[0]["metrics"][k], fit[0]["metrics"][k]
                if (b > a) if k in HIGHER_IS_BETTER else (b < a):
                    won.append(m)
            counts.append(f"{name} {len(won)}/{total}" + (f" ({', '.join(won)})" if won else ""))
        if label:
            lines.append(f"* {label} beats NBRDF-{n} on: " + "; ".join(counts) + ".")
    return lines


def uniform_table(rows: list[dict], materials: list[str]) -> list[str]:
    lines = ["| material | weights | sampling | " + " | ".join(label for _, label, _ in METRIC_COLUMNS) + " |",
             "|---|---:|---|" + "---:|" * len(METRIC_COLUMNS)]
    for m in materials:
        uniform = [r for r in rows if r["material"] == m and r["kind"] == "nbrdf" and r["sampling"] == "uniform"]
        for u in uniform:
            for r in rows:
                if (r["material"] == m and r["kind"] == "nbrdf" and r["hidden"] == u["hidden"]
                        and r["sampling"] == "adaptive"):
                    lines.append(f"| {m} | {r['stored_values']} | adaptive | " + " | ".join(_metric_cells(r)) + " |")
            lines.append(f"| {m} | {u['stored_values']} | uniform | " + " | ".join(_metric_cells(u)) + " |")
    return lines


def _better(key: str, a: float, b: float) -> bool:
    """Whether value ``a`` of metric ``key`` is better than ``b``."""
    return a > b if key in HIGHER_IS_BETTER else a < b

# Fits whose model is a source plugin's own (up to its Fresnel term): their wins are expected.
OWN_MODEL = {"roughconductor_aniso": "roughconductor"}


def anisotropic_summary(rows: list[dict], materials: list[str], plugins: dict | None = None) -> list[str]:
    """Per anisotropic material: the anisotropic NBRDF against the isotropic one, and every
    metric in which a fit beats the anisotropic NBRDF (``plugins``: material -> Mitsuba plugin,
    to say when the fit is the source's own model)."""
    plugins = plugins or {}
    lines = []
    for m in materials:
        mine = [r for r in rows if r["material"] == m]
        nets = {r["anisotropic"]: r for r in mine if r["kind"] == "nbrdf" and "anisotropic" in r}
        if True not in nets:
            continue
        a = nets[True]["metrics"]
        parts = []
        if False in nets:
            i = nets[False]["metrics"]
            la, li = a["log_error_adaptive"], i["log_error_adaptive"]
            parts.append(f"the anisotropic NBRDF against the isotropic one: turned log error {_fmt(la)} "
                         f"against {_fmt(li)} (x{li / max(la, 1e-300):.1f} lower), "
                         f"HDR-FLIP {_fmt(a['flip_hdr'], 'f4')} against {_fmt(i['flip_hdr'], 'f4')}, SSIM "
                         f"{_fmt(a['ssim'], 'f4')} against {_fmt(i['ssim'], 'f4')}")
            worse = [label for k, label, _ in METRIC_COLUMNS if not _better(k, a[k], i[k])]
            if worse:
                parts.append("**the isotropic NBRDF is as good or better in " + ", ".join(worse) + "**")
        winners = 0
        for r in (r for r in mine if r["kind"] == "fit"):
            won = [f"{ANISOTROPIC_LABELS.get(k, label)} ({_fmt(r['metrics'][k], kind)} against {_fmt(a[k], kind)})"
                   for k, label, kind in METRIC_COLUMNS if _better(k, r["metrics"][k], a[k])]
            if won:
                winners += 1
                if r["metrics"]["log_error_adaptive"] < 1e-4:
                    exact = " (the source is of this model's own family, and the fit recovers it: expected)"
                elif OWN_MODEL.get(r["method"]) == plugins.get(m):
                    exact = (f" (expected: it is the source's own `{plugins[m]}` model, up to the Fresnel term, which "
                             "the fit holds as a constant RGB specular_reflectance)")
                else:
                    exact = ""
                parts.append(f"**{r['label']} beats the anisotropic NBRDF** in " + ", ".join(won) + exact)
        if not winners:
            parts.append("no fit beats the anisotropic NBRDF in any metric")
        fits = [r for r in mine if r["kind"] == "fit"]
        if fits:
            best = min(fits, key=lambda r: r["metrics"]["log_error_adaptive"])
            parts.append(f"best fit in turned log error: {best['label']} ({_fmt(best['metrics']['log_error_adaptive'])})")
        lines.append(f"* **{m}**: " + "; ".join(parts) + ".")
    return lines

MARKERS = {"roughconductor": "s", "roughplastic": "D", "blinn_phong": "^", "abc": "v", "sgd": "P",
           "merl-table": "*"}


def plot(path: Path, rows: list[dict], materials: list[str]) -> None:
    """Error against memory (log-log), one column per material: the NBRDF sweep as a line, the
    fits and the MERL table as markers, the sizes of the measured file and the MERL table."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metrics = (("log_error_adaptive", "log-space BRDF error"), ("rmse_tonemapped", "tone-mapped image RMSE"))
    cols = max(len(materials), 1)
    fig, axes = plt.subplots(len(metrics), cols, figsize=(3.6 * cols + 0.6, 6.8), squeeze=False)
    colours = dict(zip(MARKERS, plt.rcParams["axes.prop_cycle"].by_key()["color"][1:]))
    for j, m in enumerate(materials):
        for i, (key, label) in enumerate(metrics):
            ax = axes[i][j]
            s = sweep_rows(rows, m)
            if s:
                ax.plot([r["memory_bytes"] for r in s], [r["metrics"][key] for r in s], "o-", color="k", ms=4,
                        label="NBRDF (adaptive), 6-h-h-3")
            for r in rows:
                if r["material"] == m and r.get("metrics") and r["method"] in MARKERS:
                    ax.scatter([r["memory_bytes"]], [r["metrics"][key]], marker=MARKERS[r["method"]],
                               color=colours[r["method"]], edgecolor="k", linewidths=0.4, s=50, zorder=3,
                               label=r["label"].replace("`", ""))
                if r["material"] == m and r["method"] == "measured":
                    ax.axvline(r["memory_bytes"], color="0.6", ls=":", lw=0.9, label="measured .bsdf file")
            ax.axvline(MERL_TABLE_BYTES, color="0.4", ls="--", lw=0.9, label="MERL table")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(True, which="both", alpha=0.25)
            if i == 0:
                ax.set_title(m, fontsize=9)
            if i == len(metrics) - 1:
                ax.set_xlabel("memory, bytes", fontsize=8)
            if j == 0:
                ax.set_ylabel(label, fontsize=8)
            ax.tick_params(labelsize=7)
    handles = {}
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=min(len(handles), 5), fontsize=7,
               frameon=False)
    fig.suptitle("Error against memory (float32 parameters; file sizes for the references)", fontsize=9)
    fig.tight_layout(rect=(0, 0.08, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _method_lines(document: dict, rows: list[dict], settings: Settings) -> list[str]:
    """The report's head: the command, when and where it was measured, how the numbers are made."""
    training = (f"{settings.samples:,} samples" if settings.samples else "the trainer's default samples (800,000)")
    training += f", at most {settings.epochs} epochs" if settings.epochs else ", the trainer's default epoch budget"
    if settings.samples or settings.epochs:
        training += (" (a reduced budget: the trainer's defaults are 800,000 samples and up to 300 epochs; "
                     "[rgl-training.md](rgl-training.md) has the 675-weight networks at the defaults)")
    stored = Path(document["page"]).with_suffix(".json").name
    conditions = f" {document['conditions']}" if document.get("conditions") else ""
    return [
        "# Fidelity: NBRDF against analytic fits and the measured data", "",
        "```sh", document["regenerate"], "```", "",
        f"The command above writes this page from the stored results, [{stored}]({stored}), which hold every "
        "number. To measure anew (trains, fits and measures every row, reusing the rows of an earlier run with "
        "the same settings in its work folder, then rewrites that file, the plot and this page):", "",
        "```sh", document["command"], "```", "",
        f"Measured {document['date']} on {document['machine']}, {document['cpus']} logical CPUs{conditions}; the "
        f"rows took {sum(r.get('seconds') or 0 for r in rows if r['kind'] == 'nbrdf'):.0f} s of training and "
        f"{sum(r.get('seconds') or 0 for r in rows if r['kind'] == 'fit'):.0f} s of fitting.", "",
        "## How the numbers are made", "",
        "* **Reference**: Mitsuba's `measured` BSDF on the RGL `.bsdf` file (the `merl` BSDF for MERL-format "
        "tables). Every other row is measured against it.",
        f"* **Metrics** (`nbrdf_tools.common.metrics`): {settings.resolution}x{settings.resolution} sphere images under "
        "lights at 0, 30, 45, 60 and 75 degrees (`nbrdf_tools.common.compare_materials`: each pixel is the BSDF's "
        "`eval`, no Monte Carlo noise), averaged over the five: MAE and RMSE of the tone-mapped images "
        "(`min(x^(1/2.2), 1)`), SSIM (scikit-image) of the tone-mapped images, HDR-FLIP (NVIDIA "
        "`flip-evaluator`) of the linear ones; the log-space BRDF error `|ln(1 + f cos) - ln(1 + f_ref cos)|` over "
        f"{settings.metric_samples:,} adaptive (uniform in theta_h, theta_d, phi_d) and as many uniform directions.",
        f"* **NBRDF**: `nbrdf train IN --hidden H --sampling adaptive|uniform --seed {settings.seed}` with "
        f"{training}, the same for every size; widths {', '.join(map(str, settings.hidden))} "
        f"({', '.join(str(weight_count(h)) for h in settings.hidden)} weights); uniform sampling at width "
        f"{', '.join(map(str, settings.uniform_hidden)) or '-'}. Memory: the weights as float32; the JSON file "
        "is larger (text). Seconds: the trainer's own time.",
        f"* **Analytic fits** (`nbrdf_tools.common.analytic_fit`): each model's parameters minimise the squared "
        f"log residual `ln(1 + f cos) - ln(1 + f_ref cos)` over {settings.fit_samples:,} directions (half "
        "adaptive, half uniform; not the metric's directions) with `scipy.optimize.least_squares` (bounded "
        "trust region, several starts). GGX `roughconductor` (specular_reflectance RGB in [0, 1], alpha; "
        "`material none`) and `roughplastic` (diffuse RGB, specular_reflectance, alpha; int_ior 1.5, "
        "`nonlinear false`) are rendered by Mitsuba's own plugins (the roughplastic fit evaluates the plugin "
        "itself); Blinn-Phong (`kd/pi + ks (n+2)/(2pi) cos^n theta_h`), ABC and SGD by a small Python "
        "`mi.BSDF` whose `eval` is the NumPy form (the twins of the Rust forms, held together by "
        "tests/test_fidelity_report.py), at the same pixels. ABC and SGD start from the best three of the 100 "
        "published MERL fits; SGD keeps `kap`, `c`, `k` of its start. Memory: the parameters as float32 "
        "(SGD: 11 per channel). Seconds: the fit's wall time.",
        "* **MERL table**: the measurement tabulated on the MERL grid (`python -m nbrdf_mitsuba.tabulate_rgl "
        "--phi-fold reciprocal`, what Mitsuba's `merl`-style readers take) and rendered with the `merl` BSDF.",
        "",
    ]


def _time_lines(rows: list[dict], settings: Settings) -> list[str]:
    """Training and fitting times of the isotropic materials' representation rows."""
    iso_rows = [r for r in rows if r["group"] == "isotropic"]
    net_s = [r["seconds"] for r in iso_rows if r["kind"] == "nbrdf" and r["hidden"] == settings.table_hidden]
    fit_s = {r["label"]: [] for r in iso_rows if r["kind"] == "fit"}
    for r in iso_rows:
        if r["kind"] == "fit":
            fit_s[r["label"]].append(r["seconds"])
    if net_s and fit_s:
        return [f"Time: training NBRDF-{weight_count(settings.table_hidden)} took {np.mean(net_s):.0f} s on average; "
                "the fits " + ", ".join(f"{k} {np.mean(v):.0f} s" for k, v in fit_s.items())
                + " (wall times on the shared machine; the NumPy fits run on one thread, the trainer on all cores).", ""]
    return []


def _anisotropic_lines(rows: list[dict], materials: list[Material], aniso: list[str], settings: Settings) -> list[str]:
    """The anisotropic materials' section: its sources, method, verdict and tables."""
    lines = ["## Anisotropic materials", ""]
    if aniso:
        by_name = {m.name: m for m in materials}
        sources = []
        for m in aniso:
            spec = by_name[m].spec
            what = (f"`{json.dumps(BUILTIN[spec])}`" if spec in BUILTIN else f"`{spec}`" if spec.startswith("{")
                    else f"`{by_name[m].path}`")
            sources.append(f"`{m}` = {what}")
        lines += [
            "The reference is the BSDF itself: " + "; ".join(sources) + ". (No anisotropic measurement is in the "
            "shared data of this checkout: RGL's four are isotropic.)", "",
            f"* **NBRDF**: `python -m nbrdf_mitsuba.distill SOURCE --hidden {settings.table_hidden} --anisotropy on` "
            f"and `--anisotropy off` (its library call), seed {settings.seed}, "
            + (f"{settings.samples:,} samples" if settings.samples else
               "the distiller's default samples (800,000; 4,000,000 for the anisotropic network)")
            + (f", at most {settings.epochs} epochs" if settings.epochs else ", the trainer's default epoch budget")
            + ". Both have the same 6-h-h-3 shape and weight count; the anisotropic one's input carries the half "
            "vector's azimuth `phi_h`. Seconds: the trainer's own time (Mitsuba's evaluation of the training "
            "directions is in the JSON, `evaluation_seconds`).",
            "* **Analytic fits**: the anisotropic GGX `roughconductor` (specular_reflectance RGB, alpha_u along the "
            "tangent, alpha_v across it; `material none`; rendered by Mitsuba's plugin; its NumPy twin is held to "
            "Mitsuba's by tests/test_fidelity_report.py) and the isotropic models above, fitted the same way on "
            f"{settings.fit_samples:,} directions each turned about the normal by a random azimuth.",
            "* **Metrics**: as above, but the spheres are rendered with every pixel's tangent frame turned by "
            + ", ".join(f"{t:g}" for t in FRAME_TURNS_DEG)
            + f" degrees under each of the five lights ({5 * len(FRAME_TURNS_DEG)} images, averaged), and the "
            "adaptive directions of the log error are each turned about the normal by a random azimuth (an adaptive "
            "pair's half vector has `phi_h = 0`, which would hide the anisotropy); the uniform directions already "
            "cover every azimuth.", "",
            "### Verdict", ""] + anisotropic_summary(rows, aniso, {m.name: m.plugin for m in materials}) + [""]
        for m in aniso:
            lines += [f"### {m}", ""] + representation_table(rows, m, settings.table_hidden, ANISOTROPIC_LABELS) + [""]
    else:
        lines += ["No anisotropic material was given (`--mitsuba` or `--anisotropic`): none is available in the "
                  "shared data of this checkout, so this table is empty.", ""]
    return lines


def write_report(report: Path, document: dict) -> None:
    """The page at ``report``, from the stored results ``document`` alone (what ``NAME.json`` holds)."""
    settings = Settings(**{k: tuple(v) if isinstance(v, list) else v for k, v in document["settings"].items()})
    materials = [Material(**{**m, "path": Path(m["path"])}) for m in document["materials"]]
    rows = document["rows"]
    iso = [m.name for m in materials if m.group == "isotropic"]
    aniso = [m.name for m in materials if m.group == "anisotropic"]
    lines = _method_lines(document, rows, settings)
    lines += ["## Summary", ""] + summary(rows, iso, settings.table_hidden) + [""]
    lines += [f"## Representation table: NBRDF at {weight_count(settings.table_hidden)} weights against each fit", ""]
    for m in iso:
        lines += [f"### {m}", ""] + representation_table(rows, m, settings.table_hidden) + [""]
    verdict_table, wins = fit_verdicts(rows, iso, settings.table_hidden)
    n = weight_count(settings.table_hidden)
    lines += [f"## Material by material: who wins each metric, NBRDF-{n} (adaptive) or the fit", "",
              "Each cell names the winner and gives the fit's value.", ""] + verdict_table + [""]
    lines += ["### Where a fit wins", ""] + fit_summary(rows, iso, settings.table_hidden) + [""]
    lines += (wins or [f"No fit beats NBRDF-{n} on any metric of any material."]) + [""]
    small = fits_against_small_networks(rows, iso, settings.table_hidden)
    if small:
        lines += ["Against the smaller networks of the size sweep, fits do win:", ""] + small + [""]
    lines += _time_lines(rows, settings)
    lines += ["## Size sweep: error against memory", ""]
    lines += [f"![error against memory]({Path(document['page']).with_suffix('.png').name})", ""] if iso else []
    lines += sweep_table(rows, iso) + [""]
    lines += sweep_trend(rows, iso) + [""]
    if settings.uniform_hidden:
        lines += ["## Adaptive against uniform sampling", ""] + uniform_table(rows, iso) + [""]
    lines += _anisotropic_lines(rows, materials, aniso, settings)
    report.write_text("\n".join(lines) + "\n", encoding="utf-8")
