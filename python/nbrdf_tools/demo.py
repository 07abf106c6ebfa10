"""The main job on the embedded default data: synthesise the MERL-format table of a default
material from its published fit, train its neural BRDF (``nbrdf train``), fit its sampling
(``nbrdf fit-phong``: Blinn-Phong lobes, and the strategy of lowest variance stored as the file's
default), render the Veach MIS scene with the table (``merl``, the ground truth) and with the
network (``nbrdf``, sampled with the file's default) on the plates, print the image error between
them, and write the EXR renders, a plain side-by-side PNG and a labelled one, all under ``--out``
(default out/demo/). ``--docs-figure`` writes the labelled picture to the README's
docs/images/demo.png instead.

    python -m nbrdf_tools demo [--material NAME] [--spp N] [--out DIR] [--figure PNG | --docs-figure]

Needs only the nbrdf CLI (the fits are embedded in it), no shared data.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import nbrdf_mitsuba  # first: finds a libLLVM for Dr.Jit before Mitsuba starts its JIT
import mitsuba as mi
import numpy as np

from nbrdf_tools.common import cli, metrics, progress
from nbrdf_tools.common.paths import REPO, MissingDataError, default_cli, default_out
from nbrdf_tools.common.render import render_passes, write_exr, write_png
from nbrdf_tools.common.scenes.veach import veach_scene_dict

DEFAULT_MATERIAL = "gold-metallic-paint"
#: The README's picture: written only when asked (``--docs-figure``), so that a run leaves the
#: checkout as it was.
DOCS_FIGURE = REPO / "docs" / "images" / "demo.png"


def output_paths(out: Path, material: str, model: str, figure: Path | None = None) -> dict[str, Path]:
    """Every file the demo writes: all under ``out`` but the labelled picture when ``figure``
    places it elsewhere."""
    stem = out / f"veach-{material}"
    return {"table": out / f"{material}.{model}.binary", "network": out / f"{material}.nbrdf.json",
            "table_exr": Path(f"{stem}-table.exr"), "nbrdf_exr": Path(f"{stem}-nbrdf.exr"),
            "side_by_side": Path(f"{stem}.png"), "figure": figure or Path(f"{stem}-labelled.png")}


def sampling_of(bsdf) -> str | None:
    """The sampling strategy a loaded ``nbrdf`` or ``merl`` BSDF uses, as it describes itself;
    None for a BSDF that names none (Mitsuba's own)."""
    for line in str(bsdf).splitlines():
        key, _, value = line.strip().rstrip(",").partition(" = ")
        if key == "sampling":
            return value
    return None


def scene_sampling(scene) -> str:
    """The sampling strategy of the scene's ``nbrdf`` or ``merl`` BSDFs (one dict on all the
    plates), found through the shapes' BSDFs: Mitsuba merges the plates into one mesh, ids lost."""
    strategies = {sampling_of(shape.bsdf()) for shape in scene.shapes()} - {None}
    if len(strategies) != 1:
        raise ValueError(f"the scene's BSDFs name {len(strategies)} sampling strategies "
                         f"({sorted(strategies)}), expected one")
    return strategies.pop()


def network_label(sampling: str) -> str:
    """The title of the network's panel, naming the strategy its BSDF samples with."""
    return f"its neural BRDF (nbrdf BSDF, {sampling} sampling)"


def synthesise(nbrdf: Path, model: str, material: str, table: Path) -> Path:
    if not table.exists():
        cli.run([nbrdf, "synth", "--model", model, "--material", material, "-o", table], capture=False)
    return table


def train(nbrdf: Path, table: Path, network: Path, samples: int) -> Path:
    """The NBRDF of `table` with its fitted sampling; retrained when the table is newer."""
    if not network.exists() or network.stat().st_mtime < table.stat().st_mtime:
        quiet = [] if progress.enabled() else ["--quiet"]
        cli.run([nbrdf, "train", table, "-o", network, "--samples", samples, *quiet], capture=False)
        cli.run([nbrdf, "fit-phong", network], capture=False)
    return network


def labelled_figure(panels: dict[str, np.ndarray], caption: str, path: Path) -> Path:
    """The linear images of ``panels`` side by side at one image pixel per screen pixel, each
    under its label, with ``caption`` below; sRGB-encoded and stored with a 256-colour palette
    (the README's picture stays small)."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    height, width = next(iter(panels.values())).shape[:2]
    dpi, gap, top, bottom = 100, 8, 26, 22
    figure = plt.figure(figsize=((len(panels) * (width + gap) - gap) / dpi, (height + top + bottom) / dpi), dpi=dpi)
    for i, (label, image) in enumerate(panels.items()):
        left = i * (width + gap) / figure.bbox.width
        axes = figure.add_axes((left, bottom / figure.bbox.height, width / figure.bbox.width,
                                height / figure.bbox.height))
        axes.imshow(srgb(image), interpolation="nearest")
        axes.set_axis_off()
        axes.set_title(label, fontsize=9, pad=4)
    figure.text(0.5, 4 / figure.bbox.height, caption, ha="center", va="bottom", fontsize=7.5, color="0.25")
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi, facecolor="white")
    plt.close(figure)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.open(buffer).convert("RGB").quantize(256, dither=Image.Dither.NONE).save(path, optimize=True)
    return path


def srgb(linear: np.ndarray) -> np.ndarray:
    """Clamped sRGB encoding (IEC 61966-2-1) of a linear RGB image, in [0, 1]."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--material", default=DEFAULT_MATERIAL, help="MERL material name (nbrdf list-materials)")
    parser.add_argument("--model", default="sgd", choices=["sgd", "abc"], help="published fit to tabulate")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel in all")
    parser.add_argument("--samples", type=int, default=800_000, help="training samples of the NBRDF")
    parser.add_argument("--passes", type=int, default=8, help="renders averaged (progress granularity)")
    parser.add_argument("--width", type=int, default=384, help="image width (height is 2/3 of it)")
    parser.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant")
    parser.add_argument("--out", type=Path, default=default_out("demo"), help="output folder (default: %(default)s)")
    figure = parser.add_mutually_exclusive_group()
    figure.add_argument("--figure", type=Path,
                        help="the labelled side-by-side PNG (default: OUT/veach-MATERIAL-labelled.png)")
    figure.add_argument("--docs-figure", dest="figure", action="store_const", const=DOCS_FIGURE,
                        help=f"write the labelled PNG to the README's picture, {DOCS_FIGURE.relative_to(REPO)}")
    parser.add_argument("--cli", type=Path, default=default_cli(), help="nbrdf CLI (default: %(default)s)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars (for logs)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    paths = output_paths(args.out, args.material, args.model, args.figure)
    progress.set_enabled(not args.no_progress)

    try:
        cli.check_cli(args.cli)
        args.out.mkdir(parents=True, exist_ok=True)
        mi.set_variant(args.variant)
        nbrdf_mitsuba.register()
        start = time.perf_counter()
        table = synthesise(args.cli, args.model, args.material, paths["table"])
        print(f"table:   {table} ({time.perf_counter() - start:.1f} s)")
        start = time.perf_counter()
        network = train(args.cli, table, paths["network"], args.samples)
        print(f"network: {network} ({time.perf_counter() - start:.1f} s, with the sampling fit)")
    except (MissingDataError, cli.CommandError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1

    passes = max(1, min(args.passes, args.spp))
    resolution = (args.width, args.width * 2 // 3)
    images, sampling = {}, {}
    for label, bsdf in (("table", {"type": "merl", "filename": str(table)}),
                        ("nbrdf", {"type": "nbrdf", "filename": str(network)})):
        scene = mi.load_dict(veach_scene_dict(bsdf, integrator="mis", resolution=resolution))
        sampling[label] = scene_sampling(scene)
        start = time.perf_counter()
        images[label] = render_passes(scene, args.spp, spp_per_pass=args.spp // passes, desc=f"rendering the {label}",
                                      leave=True)
        print(f"render:  {label}, {args.spp} spp in {time.perf_counter() - start:.1f} s ({args.variant}, "
              f"{sampling[label]} sampling)")
        if not np.all(np.isfinite(images[label])):
            print(f"error: the {label} render contains NaN or Inf", file=sys.stderr)
            return 1

    truth, ours = images["table"], images["nbrdf"]
    errors = metrics.render_metrics(truth, ours)
    flip = metrics.flip_hdr(truth, ours)
    for label, image in images.items():
        write_exr(paths[f"{label}_exr"], image)
    write_png(paths["side_by_side"], np.concatenate([truth, ours], axis=1))
    print(f"error:   NBRDF vs table, MAE {errors['mae']:.4f}, RMSE {errors['rmse']:.4f}, relMSE "
          f"{errors['relmse']:.4f}, HDR-FLIP {flip:.4f} (linear radiance, mean pixel {float(np.mean(truth)):.4f}; "
          f"includes Monte Carlo noise at {args.spp} spp)")
    caption = (f"Veach MIS scene, {args.material}, {args.spp} spp ({args.variant}). NBRDF vs table: "
               f"relMSE {errors['relmse']:.1e}, HDR-FLIP {flip:.3f} (Monte Carlo noise included)")
    figure = labelled_figure({"MERL-format table (merl BSDF)": truth, network_label(sampling["nbrdf"]): ours},
                             caption, paths["figure"])
    print(f"images:  {paths['table_exr']}, {paths['nbrdf_exr']}\n"
          f"         {paths['side_by_side']} (left: table, right: NBRDF)\n"
          f"         {figure} (labelled, {figure.stat().st_size // 1024} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
