"""The latent-space report (issue #6): autoencoder vs PCA-32 on the test split, a t-SNE map of
the latent space, latent vs weight interpolation strips with their measured smoothness, the
lobes of two predictors (the default: code + the network's highlight profile; and the code
alone, docs/design.md section 7) scored by sampling variance and (optionally) in the Veach scene.

    python python/latent_report.py [--source sgd|authors] [--train-missing] [--veach]

Inputs: NAME.nbrdf.json networks of the 100 MERL materials in OUT/nbrdfs (OUT = out/latent/SOURCE),
all trained by ``nbrdf train`` from the common initialisation (seed 0), which is what aligns their
hidden units (``--train-missing`` trains those not there yet; docs/results/latent.md gives the time):

* ``--source sgd`` (default, runs on a fresh machine): on tables synthesised from the SGD fits;
* ``--source authors``: on the tabulations of the authors' networks of the real MERL
  measurements (``nbrdf tabulate``; needs ../shared/data/reference-nbrdf/merl/), i.e. the real
  materials, re-learnt in our aligned family. PCA then decomposes those same networks' tables.

Or pass any folder with ``--nbrdfs`` (e.g. the authors' networks as they are, imported with
``python -m nbrdf_mitsuba.import_keras``). Everything else goes through the ``nbrdf`` CLI:
``ae train``, ``ae eval``, ``ae encode``, ``interpolate``, ``predictor train``,
``predictor eval``, ``predict-phong``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

from nbrdf_tools.common import cli, metrics, progress
from nbrdf_tools.common.network import Layers, forward, lerp, network_input, read_document, read_layers
from nbrdf_tools.common.materials import authors_merl, train_missing
from nbrdf_tools.common.paths import MissingDataError, default_cli, default_out, require_shared
from nbrdf_tools.pages.latent_page import files_of_run, write_measured, write_stored


def run(cmd: list) -> str:
    """stdout of a command; a failure raises cli.CommandError with the command's stderr."""
    return cli.run(cmd).stdout


# --- sphere images of networks (the geometry of metrics::render_sphere / latent::sphere) ------


def sphere_inputs(size: int, light_theta: float):
    """Network inputs (size, size, 6) of a unit sphere seen from +z under the light
    ``(sin t, 0, cos t)``, and the light's cosine (zero off the lit disk)."""
    light = np.array([np.sin(light_theta), 0.0, np.cos(light_theta)])
    px = (2.0 * (np.arange(size) + 0.5) / size) - 1.0
    x, y = np.meshgrid(px, -px)
    r2 = x * x + y * y
    on = r2 < 1.0
    n = np.stack([x, y, np.sqrt(np.clip(1.0 - r2, 0.0, None))], -1)
    # Any tangent frame: the network input does not depend on the rotation about the normal.
    t = np.cross(n, np.array([0.0, 1.0, 0.0]))
    t /= np.linalg.norm(t, axis=-1, keepdims=True) + 1e-30
    b = np.cross(n, t)
    l_loc = np.stack([t @ light, b @ light, n @ light], -1)
    v_loc = np.stack([t[..., 2], b[..., 2], n[..., 2]], -1)
    lit = on & (l_loc[..., 2] > 0)
    return network_input(v_loc, l_loc), np.where(lit, l_loc[..., 2], 0.0)


def render_layers(layers: Layers, size: int = 64, light_deg: float = 45.0) -> np.ndarray:
    """Linear sphere image (size, size, 3) of a network given as (W, b) pairs."""
    inp, cos = sphere_inputs(size, np.radians(light_deg))
    return forward(layers, inp) * cos[..., None]


def render_network(path: Path, size: int = 64, light_deg: float = 45.0) -> np.ndarray:
    """Linear sphere image of an ``*.nbrdf.json`` network."""
    return render_layers(read_layers(path), size, light_deg)


def tone(img: np.ndarray) -> np.ndarray:
    return metrics.tone_map(img)


LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def appearance(img: np.ndarray) -> dict:
    """What a person sees change along an interpolation, from a linear sphere image:
    `highlight` = fraction of the lit disk at or above half the peak luminance, both measured
    above the median lit pixel (the highlight's width: small for a sharp lobe, large for a
    diffuse one), `chromaticity` = the image's mean
    RGB over its sum, `luminance` = mean luminance of the lit pixels."""
    lum = img @ LUMINANCE
    lit = lum > 0
    if not lit.any():
        return {"highlight": 0.0, "chromaticity": [1 / 3] * 3, "luminance": 0.0}
    total = img[lit].sum(axis=0)
    # Above the diffuse floor (the median lit pixel), so that a sharp spot on a bright base and
    # a broad glossy lobe are told apart.
    above = np.maximum(lum[lit] - np.median(lum[lit]), 0.0)
    return {"highlight": float(np.mean(above >= 0.5 * above.max())) if above.max() > 0 else 1.0,
            "chromaticity": (total / max(total.sum(), 1e-30)).tolist(),
            "luminance": float(lum[lit].mean())}


def detour(values: np.ndarray) -> float:
    """Length of a path through `values` (frames along axis 0) over the straight distance from
    its first to its last value: 1 for a monotone, even change; large when the path swings away
    and back (a dark or blown-out midpoint, a highlight that narrows and widens again)."""
    values = np.asarray(values, dtype=np.float64).reshape(len(values), -1)
    steps = np.linalg.norm(np.diff(values, axis=0), axis=1)
    direct = np.linalg.norm(values[-1] - values[0])
    return float(steps.sum() / max(direct, 1e-12))


def smoothness(images: list[np.ndarray]) -> dict:
    """Detours of an interpolation's tone-mapped images, highlight width and chromaticity, and
    its largest single step over the mean step (1 for even steps)."""
    toned = np.array([tone(i) for i in images])
    looks = [appearance(i) for i in images]
    steps = np.sqrt(np.mean(np.diff(toned, axis=0) ** 2, axis=(1, 2, 3)))
    return {"image_detour": detour(toned),
            "highlight_detour": detour(np.array([l["highlight"] for l in looks])),
            "colour_detour": detour(np.array([l["chromaticity"] for l in looks])),
            "largest_step": float(steps.max() / max(steps.mean(), 1e-12)),
            "appearance": looks}


def markdown_table(ev: dict) -> str:
    s = ev["summary"]
    # The sphere-image metrics of `nbrdf ae eval` (the Rust tool's definitions: its SSIM truncates the
    # window at the border, unlike scikit-image's in nbrdf_tools.common.metrics).
    lines = ["| method | MAE | RMSE | SSIM (nbrdf ae eval) |", "|---|---|---|---|"]
    methods = [("ae", "autoencoder (32)"), ("ae_refined", "autoencoder (32), refined codes"),
               ("pca", f"PCA-32 ({ev['pca']['tables']} tables)")]
    for key, label in methods:
        if key not in s:
            continue
        cells = [f"{s[key][m]['mean']:.5f} ± {s[key][m]['std']:.5f} (median {s[key][m]['median']:.5f})"
                 for m in ("mae", "rmse", "ssim")]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


class Predictor(NamedTuple):
    label: str
    file: str
    folder: str
    suffix: str
    options: tuple


# The shipped predictor (code + highlight profile, the CLI's defaults) and the code-only one of
# docs/design.md section 7 with the settings it did best with (README).
PREDICTORS = (
    Predictor("code+profile", "predictor.json", "predicted", "", ()),
    Predictor("code only", "predictor_code_only.json", "predicted_code_only", "_code_only",
              ("--code-only", "--hidden", 0, "--weight-decay", 0.01)),
)


def main(argv: list[str] | None = None) -> int:
    try:
        return report(argv)
    except (MissingDataError, cli.CommandError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1


def missing_inputs(args, ae: Path) -> list[str]:
    """What the run lacks, found before any work starts."""
    try:
        cli.check_cli(args.cli)
    except MissingDataError as error:
        return [str(error)]
    problems = []
    if args.source == "authors" and args.train_missing:
        try:
            require_shared("data", "reference-nbrdf", "merl", what="--source authors: the authors' MERL networks")
        except MissingDataError as error:
            problems.append(str(error))
    has_networks = args.nbrdfs.is_dir() and any(args.nbrdfs.glob("*.nbrdf.json"))
    if not args.train_missing and not has_networks and not (ae.exists() and (args.veach_only or args.interpolation_only)):
        problems.append(f"no networks in {args.nbrdfs}: pass --train-missing to train them (100 networks), "
                        "or --nbrdfs FOLDER")
    if (args.veach_only or args.interpolation_only) and not ae.exists():
        problems.append(f"{ae} is missing: --veach-only and --interpolation-only need an earlier full run")
    return problems


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cli", type=Path, default=default_cli(), help="the nbrdf tool (default: %(default)s)")
    p.add_argument("--source", choices=["sgd", "authors"], default="sgd",
                   help="which networks of the 100 MERL materials: trained on the SGD-synthesised tables "
                        "(default, runs anywhere) or re-learnt from the authors' networks of the real "
                        "measurements (needs ../shared); both from the common initialisation")
    p.add_argument("--nbrdfs", type=Path, help="the networks (default: OUT/nbrdfs)")
    p.add_argument("--train-missing", action="store_true", help="train the networks not yet in --nbrdfs")
    p.add_argument("--samples", type=int, default=800_000)
    p.add_argument("--out", type=Path, help="output folder of everything (default: out/latent/SOURCE); with "
                                            "--stored-only, the page")
    p.add_argument("--stored-only", action="store_true",
                   help="measure nothing: write docs/results/latent.md (or --out) from its stored data, "
                        "docs/results/data/latent.json")
    p.add_argument("--data", type=Path,
                   help="the page's data a full run updates, its page written beside it (default: "
                        "docs/results/data/latent.json and docs/results/latent.md with the default --out, else "
                        "OUT/latent.json and OUT/latent.md)")
    p.add_argument("--ae", type=Path, help="an existing AE.json (default: OUT/ae.json, trained if missing)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--ae-seeds", type=int, default=3,
                   help="autoencoders trained (seeds SEED...); the one with the best refined validation "
                        "reconstructions is kept (ae train --seeds)")
    p.add_argument("--lobe-weight", type=float, default=0.0,
                   help="ae train --lobe-weight: auxiliary loss pulling the codes towards the fitted lobes "
                        "(0: the paper's loss)")
    p.add_argument("--predictor-hidden", type=int,
                   help="predictor train --hidden of the default predictor (default: the CLI's; 0 for a linear "
                        "predictor); the code-only one keeps --hidden 0 --weight-decay 0.01")
    p.add_argument("--predictor-weight-decay", type=float,
                   help="predictor train --weight-decay of the default predictor (default: the CLI's)")
    p.add_argument("--pca-tables", choices=["sgd", "nbrdf"],
                   help="what PCA-32 decomposes: the SGD tables or the input networks' tabulations "
                        "(default: sgd for --source sgd, nbrdf for --source authors)")
    p.add_argument("--refine", type=int, default=30,
                   help="also score codes refined by this many Levenberg-Marquardt iterations (ae encode --refine); 0: off")
    p.add_argument("--pair", nargs=2, help="materials to interpolate (default: two test materials)")
    p.add_argument("--steps", type=int, default=7)
    p.add_argument("--interpolation-pairs", type=int, default=10,
                   help="pairs of test materials whose interpolations are measured (besides the figure's)")
    p.add_argument("--authors", type=Path, default=authors_merl(),
                   help="the authors' Keras networks, for the independently trained row of the interpolation")
    p.add_argument("--veach", action="store_true", help="also render the Veach scene, predicted vs fitted")
    p.add_argument("--interpolation-only", action="store_true",
                   help="only the interpolation figure (needs OUT/ae.json from an earlier run)")
    p.add_argument("--veach-only", action="store_true",
                   help="only the Veach comparison (needs OUT/ae.json and the predicted lobes of an earlier run)")
    p.add_argument("--veach-spp", type=int, default=16)
    p.add_argument("--veach-gt-spp", type=int, default=512, help="spp of the converged MIS render")
    p.add_argument("--veach-seeds", type=int, default=8, help="renders (seeds) averaged per strategy")
    p.add_argument("--no-progress", action="store_true", help="no progress bars (for logs)")
    return p


def ae_vs_pca(args, ae: Path) -> None:
    """The autoencoder against PCA-32 on the test split: ae_vs_pca_TABLES.json and .md."""
    ev = json.loads(run([args.cli, "ae", "eval", "--ae", ae, "--nbrdfs", args.nbrdfs,
                         "--pca-tables", args.pca_tables, "--refine", args.refine]))
    (args.out / f"ae_vs_pca_{args.pca_tables}.json").write_text(json.dumps(ev, indent=1))
    table = markdown_table(ev)
    keys = [k for k in ("ae", "ae_refined", "pca") if k in ev["materials"][0]]
    rows = ["| material | " + " | ".join(f"{k} {m}" for m in ("MAE", "RMSE", "SSIM") for k in keys) + " |",
            "|---|" + "---|" * (3 * len(keys))]
    rows += [f"| {r['name']} | " + " | ".join(f"{r[k][m]:.5f}" for m in ("mae", "rmse", "ssim") for k in keys) + " |"
             for r in ev["materials"]]
    m = ev["materials"]
    if "ae_refined" in m[0]:
        wins = [sum(better(r["ae_refined"][q], r["pca"][q]) for r in m)
                for q, better in (("mae", float.__lt__), ("rmse", float.__lt__), ("ssim", float.__gt__))]
        table += (f"\n\nRefined autoencoder better than PCA-32 per material: MAE {wins[0]}, RMSE {wins[1]}, "
                  f"SSIM {wins[2]} of {len(m)}.")
    selection = json.loads(ae.read_text()).get("provenance", {}).get("selection")
    if selection:
        table += "\n\nAutoencoder chosen among seeds by " + selection["criterion"] + ": " + ", ".join(
            f"seed {c['seed']} {c['refined_validation_loss']:.3e}" for c in selection["candidates"]) + "."
    (args.out / f"ae_vs_pca_{args.pca_tables}.md").write_text(table + "\n\n" + "\n".join(rows) + "\n")
    print(table)


def tsne_figure(args, ae: Path, split: dict, plt) -> None:
    """latent_tsne.png: the t-SNE of every material's code, the test split marked."""
    names = sorted(f.name[: -len(".nbrdf.json")] for f in args.nbrdfs.glob("*.nbrdf.json"))
    codes = np.array([json.loads(run([args.cli, "ae", "encode", "--ae", ae, args.nbrdfs / f"{n}.nbrdf.json"]))
                      for n in names])
    from sklearn.manifold import TSNE

    xy = TSNE(n_components=2, perplexity=15, random_state=args.seed, init="pca").fit_transform(codes)
    test = np.array([n in split["test"] for n in names])
    fig, ax = plt.subplots(figsize=(10, 8))
    ax.scatter(xy[~test, 0], xy[~test, 1], c="tab:blue", s=18, label="train")
    ax.scatter(xy[test, 0], xy[test, 1], c="tab:red", marker="*", s=80, label="test")
    for (x, y), n in zip(xy, names):
        ax.annotate(n, (x, y), fontsize=5, alpha=0.7)
    ax.legend()
    ax.set_title("t-SNE of the 32-value autoencoder codes")
    fig.savefig(args.out / "latent_tsne.png", dpi=150, bbox_inches="tight")
    plt.close(fig)


def train_predictors(args, ae: Path) -> None:
    """The predictors of :data:`PREDICTORS` not yet in the output folder."""
    for variant in PREDICTORS:
        pred = args.out / variant.file
        if not pred.exists():
            options = list(variant.options)
            # The code-only comparison keeps its own settings (the CLI refuses a repeated option).
            if variant is PREDICTORS[0] and args.predictor_hidden is not None:
                options += ["--hidden", args.predictor_hidden]
            if variant is PREDICTORS[0] and args.predictor_weight_decay is not None:
                options += ["--weight-decay", args.predictor_weight_decay]
            print(run([args.cli, "predictor", "train", "--ae", ae, "--nbrdfs", args.nbrdfs, "-o", pred, *options]))
        (args.out / variant.folder).mkdir(exist_ok=True)


def predicted_vs_fitted(args, ae: Path, split: dict) -> None:
    """predicted_vs_fitted.md: each test material's fitted lobe beside each predictor's."""
    lines = ["| material | fitted n | fitted w | " + " | ".join(f"{v.label} n | {v.label} w" for v in PREDICTORS) + " |",
             "|---|---|---|" + "---|---|" * len(PREDICTORS)]
    for n in split["test"]:
        src = args.nbrdfs / f"{n}.nbrdf.json"
        fitted = read_document(src).get("sampling")
        if fitted is None or fitted.get("source") != "fit":
            fitted_dir = args.out / "fitted"
            fitted_dir.mkdir(exist_ok=True)
            run([args.cli, "fit-phong", src, "--lobes", "1", "-o", fitted_dir / f"{n}.nbrdf.json"])
            fitted = read_document(fitted_dir / f"{n}.nbrdf.json")["sampling"]
        row = f"| {n} | {fitted['exponent']:.1f} | {fitted['specular_weight']:.3f} |"
        for variant in PREDICTORS:
            dst = args.out / variant.folder / f"{n}.nbrdf.json"
            run([args.cli, "predict-phong", "--ae", ae, "--predictor", args.out / variant.file, src, "-o", dst])
            s = read_document(dst)["sampling"]
            row += f" {s['exponent']:.1f} | {s['specular_weight']:.3f} |"
        lines.append(row)
    (args.out / "predicted_vs_fitted.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def predictor_variance(args, ae: Path) -> None:
    """predictor_eval.md: the lobes scored by the relative variance of BSDF sampling (noise-free,
    all views)."""
    lines = []
    for variant in PREDICTORS:
        pe = json.loads(run([args.cli, "predictor", "eval", "--ae", ae, "--predictor", args.out / variant.file,
                             "--nbrdfs", args.nbrdfs]))
        (args.out / f"predictor_eval{variant.suffix}.json").write_text(json.dumps(pe, indent=1))
        lines += [f"Predictor: {variant.label}.", "",
                  "| material | fitted n, w | predicted n, w | R-1 fitted | R-1 predicted | R-1 cosine | RMSE ratio |",
                  "|---|---|---|---|---|---|---|"]
        for r in pe["test"]:
            f, q = r["fitted"], r["predicted"]
            lines.append(f"| {r['name']} | {f['exponent']:.3g}, {f['specular_weight']:.2f} | "
                         f"{q['exponent']:.3g}, {q['specular_weight']:.2f} | {f['relative_variance']:.3g} | "
                         f"{q['relative_variance']:.3g} | {r['cosine_relative_variance']:.3g} | {r['rmse_ratio']:.2f} |")
        q = pe["rmse_ratio"]
        lines += ["", f"RMSE ratio sqrt((R-1) predicted / (R-1) fitted): median {q['median']:.2f}, "
                  f"max {q['max']:.2f}, within 1.25x for {q['within_1_25']} of {q['materials']}.", ""]
    (args.out / "predictor_eval.md").write_text("\n".join(lines))
    print("\n".join(lines))


def report(argv: list[str] | None) -> int:
    args = parser().parse_args(argv)
    if args.stored_only:
        write_stored(args.out, args.data)
        return 0
    progress.set_enabled(not args.no_progress)
    out_given = args.out
    args.out = args.out or default_out("latent", args.source)
    args.nbrdfs = args.nbrdfs or args.out / "nbrdfs"
    args.pca_tables = args.pca_tables or ("sgd" if args.source == "sgd" else "nbrdf")
    ae = args.ae or args.out / "ae.json"
    problems = missing_inputs(args, ae)
    if problems:
        print("error: missing inputs, nothing done:\n  " + "\n  ".join(problems), file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    if args.train_missing:
        train_missing(args.cli, args.nbrdfs, args.samples, args.source)
    if not ae.exists():
        print(run([args.cli, "ae", "train", "--nbrdfs", args.nbrdfs, "-o", ae, "--seed", args.seed,
                   "--seeds", args.ae_seeds, "--lobe-weight", args.lobe_weight]))
    split = json.loads(ae.read_text())["split"]
    if args.veach_only:
        veach(args, split)
        return 0
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a, b = args.pair or (split["test"][0], split["test"][-1])
    if args.interpolation_only:
        interpolation(args, ae, a, b, plt, split)
        return 0

    # 1. AE vs PCA on the test split.
    ae_vs_pca(args, ae)
    # 2. t-SNE of the codes.
    tsne_figure(args, ae, split, plt)
    # 3. Interpolation strips: latent, weights of the aligned networks, weights of the authors'
    # independently trained networks of the same materials (the paper's comparison).
    interpolation(args, ae, a, b, plt, split)

    # 4. Predictors: fitted vs predicted on the test split. The default reads the code and the
    # network's highlight profile; the code-only one is docs/design.md section 7 to the letter.
    train_predictors(args, ae)
    predicted_vs_fitted(args, ae, split)
    predictor_variance(args, ae)
    if args.veach:
        veach(args, split)
    given = sys.argv[1:] if argv is None else argv
    write_measured(json.loads((args.out / f"ae_vs_pca_{args.pca_tables}.json").read_text()),
                   json.loads(ae.read_text()).get("provenance", {}), args.source,
                   f"python -m nbrdf_tools latent {shlex.join(str(a) for a in given)}".strip(), args.refine,
                   *files_of_run(args.data, out_given, args.out))
    return 0


def interpolation_rows(args, ae: Path, a: str, b: str, interp: Path) -> dict:
    """The rendered paths from material a to b: latent, weights of the aligned networks, and
    weights of the authors' networks when their Keras files are there."""
    run([args.cli, "interpolate", "--ae", ae, args.nbrdfs / f"{a}.nbrdf.json", args.nbrdfs / f"{b}.nbrdf.json",
         "--steps", args.steps, "--refine", args.refine, "-o", interp])
    ts = np.linspace(0.0, 1.0, args.steps)
    interp.mkdir(parents=True, exist_ok=True)
    rows = {"latent (autoencoder)": [render_network(interp / f"latent_{i:02d}.nbrdf.json") for i in range(args.steps)],
            "weights, aligned networks": [render_network(interp / f"weights_{i:02d}.nbrdf.json")
                                          for i in range(args.steps)]}
    keras = [args.authors / f"{m}.h5" for m in (a, b)]
    if all(k.exists() for k in keras):
        from nbrdf_mitsuba.import_keras import convert
        layers = []
        for k in keras:
            convert(k, interp / f"authors_{k.stem}.nbrdf.json")
            layers.append(read_layers(interp / f"authors_{k.stem}.nbrdf.json"))
        rows["weights, the authors' networks"] = [render_layers(lerp(*layers, t)) for t in ts]
    else:
        print(f"note: the authors' networks of {a} and {b} are not in {args.authors}: "
              "the independently trained row is left out", file=sys.stderr)
    return rows


def interpolation(args, ae: Path, a: str, b: str, plt, split: dict | None = None) -> dict:
    """Renders the strips of a and b, measures their smoothness (also averaged over
    --interpolation-pairs pairs of test materials), writes interpolation.{png,json,md}."""
    interp = args.out / "interp"
    ts = np.linspace(0.0, 1.0, args.steps)
    rows = interpolation_rows(args, ae, a, b, interp)
    stats = {name: smoothness(images) for name, images in rows.items()}
    fig = plt.figure(figsize=(1.6 * args.steps + 4.2, 1.7 * len(rows) + 0.6))
    grid = fig.add_gridspec(len(rows), args.steps + 3)
    for r, (name, images) in enumerate(rows.items()):
        for i, img in enumerate(images):
            ax = fig.add_subplot(grid[r, i])
            ax.imshow(tone(img))
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_ylabel(name.replace(", ", ",\n"), fontsize=7)
            if r == 0:
                ax.set_title(f"t = {ts[i]:.2f}", fontsize=7)
    curves = fig.add_subplot(grid[:, args.steps:])
    for name, st in stats.items():
        line, = curves.plot(ts, [l["highlight"] for l in st["appearance"]], marker="o", ms=3,
                            label=f"{name}: highlight (detour {st['highlight_detour']:.2f})")
        curves.plot(ts, [l["chromaticity"][0] for l in st["appearance"]], ls="--", color=line.get_color(),
                    label=f"red share (colour detour {st['colour_detour']:.2f})")
    curves.set_xlabel("t")
    curves.set_ylabel("highlight width (solid), red share (dashed)", fontsize=7)
    curves.yaxis.set_label_position("right")
    curves.yaxis.tick_right()
    curves.legend(fontsize=5)
    fig.suptitle(f"{a} → {b}: interpolation in latent space and in weight space", fontsize=9)
    fig.savefig(args.out / "interpolation.png", dpi=150, bbox_inches="tight")
    plt.close(fig)
    lines = [f"{a} → {b}, {args.steps} steps. Detour = path length / straight distance (1: monotone and even).", "",
             "| path | image detour | highlight-width detour | colour detour | largest step / mean step |",
             "|---|---|---|---|---|"]
    lines += [f"| {name} | {st['image_detour']:.2f} | {st['highlight_detour']:.2f} | {st['colour_detour']:.2f} | "
              f"{st['largest_step']:.2f} |" for name, st in stats.items()]
    # The same measures over pairs of test materials (first with last, second with second to
    # last, ...): one pair is an anecdote.
    test = (split or {}).get("test", [])
    pairs = [(test[i], test[-1 - i]) for i in range(min(args.interpolation_pairs, len(test) // 2))]
    per_pair = {}
    for pa, pb in pairs:
        pair_rows = interpolation_rows(args, ae, pa, pb, args.out / "interp_pairs")
        per_pair[f"{pa} -> {pb}"] = {name: {k: v for k, v in smoothness(images).items() if k != "appearance"}
                                     for name, images in pair_rows.items()}
    if per_pair:
        names = list(next(iter(per_pair.values())))
        lines += ["", f"Over {len(per_pair)} pairs of test materials (median, and worst pair):", "",
                  "| path | image detour | colour detour | largest step / mean step | image detour < latent's |",
                  "|---|---|---|---|---|"]
        latent = [v[names[0]]["image_detour"] for v in per_pair.values()]
        for name in names:
            vals = {k: [v[name][k] for v in per_pair.values() if name in v]
                    for k in ("image_detour", "colour_detour", "largest_step")}
            mine = [v[name]["image_detour"] for v in per_pair.values()]
            lines.append(f"| {name} | " + " | ".join(f"{np.median(x):.2f} ({max(x):.2f})" for x in vals.values())
                         + f" | {sum(m < l for m, l in zip(mine, latent))} of {len(mine)} |")
    (args.out / "interpolation.json").write_text(json.dumps({"a": a, "b": b, "t": ts.tolist(), "rows": stats,
                                                             "pairs": per_pair}, indent=1))
    (args.out / "interpolation.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return stats


def veach(args, split) -> None:
    """Veach scene, pure BSDF sampling, `nbrdf` with Phong sampling from fitted vs predicted
    parameters at equal spp: RMSE against a converged MIS render of the same network, averaged
    over several seeds (single renders of this scene are heavy-tailed)."""
    import nbrdf_mitsuba  # (before mitsuba)
    import mitsuba as mi

    from nbrdf_tools.common import render as rendering
    from nbrdf_tools.common.scenes.veach import plate_mask, veach_scene_dict

    mi.set_variant("llvm_ad_rgb")
    nbrdf_mitsuba.register()
    seeds = range(args.veach_seeds)
    # Errors on the plates only: elsewhere the images are the same diffuse scene, and the
    # anti-aliased edges of the bright lights would swamp the plates' sampling noise.
    plates = plate_mask(mi.load_dict(veach_scene_dict({"type": "diffuse"}, resolution=(192, 128))))
    lines = [f"Veach scene, pure BSDF sampling, 192x128, {args.veach_spp} spp, RMSE on the plates against "
             f"{args.veach_gt_spp} spp MIS, mean over {len(seeds)} seeds. Predicted lobes: "
             + "; ".join(f"{v.label} ({v.file})" for v in PREDICTORS) + ".", "",
             "| material | fitted n, w | " + " | ".join(f"{v.label} n, w" for v in PREDICTORS)
             + " | RMSE fitted | " + " | ".join(f"RMSE {v.label}" for v in PREDICTORS) + " | cosine | "
             + " | ".join(f"{v.label} / fitted" for v in PREDICTORS) + " |",
             "|---|---|" + "---|" * (3 * len(PREDICTORS) + 2)]
    ratios = {v.label: [] for v in PREDICTORS}
    for n in progress.bar(split["test"], desc="veach: predicted vs fitted", unit="material"):
        fitted = args.out / "fitted" / f"{n}.nbrdf.json"
        if not fitted.exists():
            fitted = args.nbrdfs / f"{n}.nbrdf.json"
        predicted = [args.out / v.folder / f"{n}.nbrdf.json" for v in PREDICTORS]

        def render(path, spp, seed, integrator="bsdf", sampling="phong"):
            d = veach_scene_dict({"type": "nbrdf", "filename": str(path), "sampling": sampling},
                                 integrator=integrator, resolution=(192, 128), spp=spp, seed=seed)
            # The seed is the sampler's (mi.render's own stays 0, as it was).
            return rendering.render(mi.load_dict(d), spp)

        gt = render(fitted, args.veach_gt_spp, 10_000, "mis")

        def rmse(path, sampling="phong", gt=gt):
            return float(np.mean([metrics.rmse(gt, render(path, args.veach_spp, s, sampling=sampling), plates)
                                  for s in seeds]))

        r_fit, r_cos = rmse(fitted), rmse(fitted, "cosine")
        r_pred = [rmse(p) for p in predicted]
        for v, r in zip(PREDICTORS, r_pred):
            ratios[v.label].append(r / r_fit)
        lobe = [read_document(p)["sampling"] for p in (fitted, *predicted)]
        lines.append(f"| {n} | " + " | ".join(f"{x['exponent']:.3g}, {x['specular_weight']:.2f}" for x in lobe)
                     + f" | {r_fit:.4g} | " + " | ".join(f"{r:.4g}" for r in r_pred) + f" | {r_cos:.4g} | "
                     + " | ".join(f"{r / r_fit:.2f}" for r in r_pred) + " |")
    lines.append("")
    for label, rs in ratios.items():
        lines.append(f"{label} / fitted: median {np.median(rs):.2f}, mean {np.mean(rs):.2f}, max {np.max(rs):.2f}, "
                     f"within 1.25x for {sum(r <= 1.25 for r in rs)} of {len(rs)} materials.")
    (args.out / "veach_predicted_vs_fitted.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
