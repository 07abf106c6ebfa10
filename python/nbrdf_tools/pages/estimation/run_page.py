"""The page of one estimation run (``python -m nbrdf_tools estimation --work WORK``): its
headline per set, the table per material and model, the summary lines, the candidates the
``nbrdf`` estimates chose, and the figure of truth and estimates at the first novel pair.

The protocol's settings and helpers (:data:`CEILING`, the novel pairs, the renders) live in
:mod:`nbrdf_tools.pages.estimation`; they are read at call time, as that package imports this one.
"""

from __future__ import annotations

import json
import os
import platform
from pathlib import Path

import numpy as np

from nbrdf_tools.pages.estimation import truths

#: The network distilled from the truth's BRDF (not an estimate from images): the ceiling.
CEILING = "nbrdf-from-truth"


def _or(values) -> str:
    """Values as prose: ``0.1 or 0``, ``0, 0.001 or 0.1``."""
    text = [f"{v:g}" for v in values]
    return text[0] if len(text) == 1 else ", ".join(text[:-1]) + " or " + text[-1]


def write(out: Path, command: str, results: list[dict], work: Path, settings: dict, models: list[str],
          chosen: dict[str, dict], missing: list[str], ceiling: bool) -> Path:
    """Writes the run's page to ``out`` and its figure beside it (``images/estimation.png``)."""
    from nbrdf_mitsuba import estimate

    from nbrdf_tools.pages import estimation as protocol

    columns = models + ([CEILING] if ceiling else [])
    image = out.parent / "images" / "estimation.png"
    image.parent.mkdir(parents=True, exist_ok=True)
    figure(results, work, image, columns)
    side = protocol.train_resolution(settings)
    pairs = protocol.novel_pairs(settings)
    lines = ["```sh", command, "```", "", "# Material estimation from images", "",
             f"A sphere, {settings['views']} training views ({side}x{side}, "
             f"{settings['reference_spp']} spp references; the novel views {settings['resolution']}x"
             f"{settings['resolution']}) under {len(protocol.LIGHTS)} point lights and a dim sky; every model "
             f"fitted to the same images by `python -m nbrdf_mitsuba.estimate` ({settings['steps']} steps, "
             f"{settings['spp']} spp per render, prb depth 3, seed {settings['seed']}). Measured on "
             f"{len(pairs)} novel views, each under its own novel light (the image metrics are means over "
             "the pairs), and in "
             f"BRDF space (mean |ln(1 + f cos) - ln(1 + f' cos)|, {settings['log_samples']} uniform pairs). "
             f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, load average "
             f"{os.getloadavg()[0]:.1f} at the end (shared).", "",
             *run_headline(results, chosen), "",
             *table(results, models), "", *summary(results), "",
             *([] if not ceiling else [
                 f"`{CEILING}` is no estimate: the same isotropic 675-weight network distilled from the truth's BRDF "
                 "(`python -m nbrdf_mitsuba.distill`, the trainer's defaults), measured the same way. Its error is "
                 "what the network's form leaves; the rest of an estimate's is what the few images and the "
                 "optimisation leave.", ""]),
             *([f"Not run (missing from this table): {', '.join(missing)}.", ""] if missing else []),
             "The `nbrdf` estimates' start and strengths (the code strength, the code phase's Gaussian penalty "
             f"toward the training codes, `code` {_or(estimate.CODE_STRENGTHS)}; the pull strength, the weight "
             "phase's pull toward the "
             f"decoded network's BRDF, `pull` {_or(estimate.PULL_STRENGTHS)}, from each code; or an analytic "
             f"fit, the best of {', '.join(estimate.ANALYTIC_MODELS)}, as the base of a zero network), chosen per "
             f"estimate by its last training view, held out (one render at {estimate.JUDGE_SPP} samples per "
             "candidate); where the albedo check rejected every candidate or the final "
             f"network (directional albedo above 1, or above its own up to {estimate.ALBEDO_LIT_INCIDENCE} degrees' "
             f"incidence if higher, by more than {estimate.ALBEDO_MARGIN:.0%}, or above {estimate.ALBEDO_BOUND:g}), "
             "the common start without the prior:", "",
             *chosen_strengths(results, work), "",
             "Every model gets the same images and the same number of steps; a step of an analytic model costs "
             "a fraction of a network's (its kernels are smaller), so the seconds differ. The first network "
             "estimate of a run includes compiling Mitsuba's kernels for the network (cached afterwards). Novel "
             "pairs (view; light): " + "; ".join(f"({v}; {light} at {i:g})" for v, (light, i) in pairs)
             + ", no view and no light any training image used; the estimates' novel renders take "
             f"{protocol.novel_spp(settings, 'estimate')} spp, the truth's "
             f"{protocol.novel_spp(settings, 'truth')}, and the errors "
             "hold their Monte Carlo noise.", "",
             f"![truth and estimates at the first novel pair]({os.path.relpath(image, out.parent)})", ""]
    out.write_text("\n".join(lines))
    return image


def figure(results: list[dict], work: Path, path: Path, models: list[str]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from nbrdf_tools.common.metrics import tone_map
    from nbrdf_tools.pages.estimation import read_exr

    names = list(dict.fromkeys(r["material"] for r in results))
    columns = ["truth", *models]
    fig, axes = plt.subplots(len(names), len(columns), figsize=(1.6 * len(columns), 1.6 * len(names)),
                             squeeze=False)
    for row, name in enumerate(names):
        for col, model in enumerate(columns):
            ax = axes[row][col]
            ax.axis("off")
            exr = work / name / ("novel-truth-0.exr" if model == "truth" else f"novel-{model}-0.exr")
            if exr.is_file():
                ax.imshow(tone_map(read_exr(exr)))
            if row == 0:
                ax.set_title(model, fontsize=7)
            if col == 0:
                ax.text(-0.05, 0.5, name, transform=ax.transAxes, rotation=90, ha="right", va="center", fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def table(results: list[dict], models: list[str]) -> list[str]:
    """Image metrics are means over the novel pairs; the RMSE of each pair beside them."""
    lines = ["| material | model | RMSE (tone-mapped) | RMSE per novel pair | SSIM | HDR-FLIP | BRDF log error | "
             "seconds (CPU s) |", "|---|---|---|---|---|---|---|---|"]
    for r in results:
        pairs = " / ".join(f"{m['rmse_tonemapped']:.4f}" for m in r.get("novel", []))
        lines.append(f"| {r['material']} | {r['model']} | {r['rmse_tonemapped']:.4f} | {pairs or '-'} | "
                     f"{r['ssim']:.4f} | {r['flip_hdr']:.4f} | {r['log_error']:.4f} | "
                     f"{r['seconds']:.0f} ({r['cpu_seconds']:.0f}) |")
    return lines


def chosen_strengths(results: list[dict], work: Path) -> list[str]:
    """Per ``nbrdf`` estimate: the candidate its held-out training view chose (the code strength
    and the pull strength from the decoded start), or the common start without the prior where
    the albedo check rejected the decoded network, the held-out losses of the candidates and the
    rejected albedos (from the network file's provenance; a network written before the strengths
    had these names records them as ``prior_weight`` and ``code_prior``, and one written before
    the chosen fit became the network's base has the fit distilled)."""
    lines = []
    for r in results:
        path = work / r["material"] / "nbrdf.nbrdf.json"
        if r["model"] != "nbrdf" or not path.is_file():
            continue
        document = json.loads(path.read_text())
        provenance = document.get("provenance", {})
        losses = provenance.get("held_out_losses") or {}
        text = "; ".join(f"{k}: {v:.4g}" for k, v in losses.items())
        pull = provenance.get("pull_strength", provenance.get("prior_weight"))
        code = provenance.get("code_strength", provenance.get("code_prior"))
        start = provenance.get("start")
        analytic = (provenance.get("analytic") or {}).get("type", "analytic")
        chosen = ("the common start, no prior (the result is the no-prior estimate)" if start == "common"
                  else f"the {analytic} fit, {'as its base' if 'base' in document else 'distilled'}"
                  if start == "analytic"
                  else f"pull strength {pull}" + (f", code strength {code}" if code is not None else ""))
        rejected = "; ".join(f"{k}: {v:.3g}" for k, v in (provenance.get("albedo_rejected") or {}).items())
        lines.append(f"* {r['material']}: {chosen}" + (f" (held-out view loss {text})" if text else "")
                     + (f"; albedo over the bound, rejected: {rejected}" if rejected else ""))
    return lines


def measured_only(by_material: dict) -> list:
    """The values of the measured materials (RGL and MERL), not of the Mitsuba BSDF truths."""
    return [v for k, v in by_material.items() if not k.startswith("mitsuba-")]


def summary(results: list[dict]) -> list[str]:
    """Per material: the model with the lowest novel-view RMSE, and nbrdf's over the best analytic's."""
    lines, ratios, ceilings = [], {}, {}
    for name in dict.fromkeys(r["material"] for r in results):
        rows = {r["model"]: r for r in results if r["material"] == name}
        ceiling = rows.pop(CEILING, None)
        if not rows:
            continue
        best = min(rows.values(), key=lambda r: r["rmse_tonemapped"])
        analytic = [r for m, r in rows.items() if not m.startswith("nbrdf")]
        best_analytic = min(analytic, key=lambda r: r["rmse_tonemapped"]) if analytic else None
        text = f"* {name}: lowest novel-view RMSE: {best['model']}"
        if "nbrdf" in rows and best_analytic:
            ratio = rows["nbrdf"]["rmse_tonemapped"] / best_analytic["rmse_tonemapped"]
            ratios[name] = ratio
            text += f"; nbrdf / best analytic ({best_analytic['model']}) = {ratio:.2f}x"
        if "nbrdf" in rows and "nbrdf-no-prior" in rows:
            text += (f"; prior {rows['nbrdf']['rmse_tonemapped']:.4f} vs no prior "
                     f"{rows['nbrdf-no-prior']['rmse_tonemapped']:.4f}")
        if ceiling is not None and best_analytic:
            ceilings[name] = ceiling["rmse_tonemapped"] / best_analytic["rmse_tonemapped"]
            text += f"; the network trained on the truth itself {ceiling['rmse_tonemapped']:.4f}"
        lines.append(text)
    if ratios:
        lines.append(f"* mean nbrdf / best analytic novel-view RMSE: {np.mean(list(ratios.values())):.2f}x over "
                     f"{len(ratios)} materials")
        # The issue's target is over measured materials; an analytic truth is the analytic model's home ground.
        measured = measured_only(ratios)
        if measured and len(measured) < len(ratios):
            lines.append(f"* mean over the {len(measured)} measured materials (RGL and MERL): {np.mean(measured):.2f}x")
    measured = measured_only(ceilings)
    if measured:
        lines.append(f"* the ceiling, {CEILING} (distilled from the truth's BRDF, not from images) / best analytic "
                     f"estimate: {np.mean(measured):.2f}x over the {len(measured)} measured materials")
    return lines


def run_headline(results: list[dict], chosen: dict[str, dict]) -> list[str]:
    """A run page's headline (:mod:`headline`): per set, then per material of each set measured."""
    from nbrdf_tools.pages.estimation import headline, seeds

    by_set = headline.split_by_set(seeds.by_case(results),
                                   lambda m: next(r["set"] for r in results if r["material"] == m))
    lines = ["Per set, the prior's (`nbrdf`) novel-view RMSE over the best analytic model's: the test set's "
             "truths are the judgement (nothing was chosen on them), the tuning set's are what the defaults were "
             "chosen on.", "", *headline.table(by_set), ""]
    for which in truths.SETS:
        if which in by_set:
            lines += [f"The {which} set, per material:", "", *headline.material_table(by_set[which]), ""]
    forms = "; ".join(f"{name}: {material['form']}" for name, material in chosen.items())
    return [*lines, "Each truth's training images were rendered through its scene form (the marked BSDF "
            f"nested in its shape, inside a `twosided`, or shared by two shapes; the field of view a `-D` "
            f"parameter): {forms}."]
