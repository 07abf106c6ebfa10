"""Spectral networks against RGB networks of the same source (issue 31): distils Mitsuba's
``roughconductor`` with measured spectral indices of refraction (``material`` Au, Cu) into a
spectral network (``--variant llvm_ad_spectral``: file format version 3, 16 B-spline coefficients
over 360-830 nm) and into an RGB network (``llvm_ad_rgb``), then compares both with the source.

    python -m nbrdf_tools spectral-networks [--out docs/results/spectral-networks.md]
        [--figure docs/images/spectral-networks.png] [--materials Au,Cu] [--alpha 0.2]
        [--rgl FILE.bsdf ...] [--samples N] [--epochs N] [--size 96] [--spp 64] [--pairs 20000]
        [--quick] [--resume] [--work out/spectral-networks]

Reported, per source:

* per wavelength (every 10 nm, distill's :data:`~nbrdf_mitsuba.distill.WAVELENGTHS`), the log
  error ``mean |ln(1 + f cos) - ln(1 + f_net cos)|`` over ``--pairs`` uniform pairs of directions
  (the log-error measure of :mod:`nbrdf_tools.common.compare_materials`, per wavelength) of the
  spectral network and of the RGB network as ``llvm_ad_spectral`` renders it (Mitsuba's uplift of
  its RGB value);
* sphere images (a sphere under a directional light and a dim constant environment) in
  ``llvm_ad_spectral`` and in ``llvm_ad_rgb``: source, spectral network, RGB network; errors
  from :mod:`nbrdf_tools.common.metrics` (tone-mapped RMSE, SSIM, HDR-FLIP, relative RMSE) against the
  source's image in the same variant and seed; render seconds;
* how finely distill samples the spectrum (Mitsuba sources): linear interpolation between samples
  5, 10, 20 and 40 nm apart against the source's spectra every 1 nm (why distill takes 10 nm);
* the weights (961 for the 6-21-21-16 spectral network, 675 for the 6-21-21-3 RGB one) and the
  seconds each network took to make.

``--rgl FILE.bsdf`` adds an RGL measurement: a spectral one (``*_spec.bsdf``) is distilled in
``llvm_ad_spectral`` (Mitsuba's ``measured``) into the spectral network and learnt by ``nbrdf
train`` through its sRGB projection into the RGB network; an RGB one (``*_rgb.bsdf``) is first
turned into a spectral file by :mod:`nbrdf_tools.data.spectral_rgl` (synthetic spectra, said so in the
report). Mitsuba's ``measured`` refuses spectral files in RGB variants, so an RGL source has no
``llvm_ad_rgb`` reference image.

Every step (a network, the errors of a source, its images) leaves a record under ``--work``;
``--resume`` reads back the records made with the same settings instead of redoing them.
``--quick`` (a few seconds of training, tiny images; for tests) says so in the report.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import nbrdf_mitsuba  # noqa: F401  (first: finds a libLLVM for Dr.Jit before Mitsuba starts its JIT)
import mitsuba as mi
import numpy as np

from nbrdf_tools.common import metrics, progress, stored_page
from nbrdf_tools.common.compare_materials import sample_directions, splitmix_uniforms
from nbrdf_tools.common.paths import REPO, default_cli, default_out
from nbrdf_tools.common.render import read_exr, timed_render, warm_up, write_exr

DEFAULT_FIGURE = REPO / "docs" / "images" / "spectral-networks.png"
SPECTRAL, RGB = "llvm_ad_spectral", "llvm_ad_rgb"
VARIANTS = (SPECTRAL, RGB)
NETWORKS = ("spectral", "rgb")
STEPS_NM = (5.0, 10.0, 20.0, 40.0)
#: The stream of compare_materials' splitmix uniforms this report draws its pairs from.
PAIR_STREAM = 21
#: The image metrics of the report, all from nbrdf_tools.common.metrics.
IMAGE_METRICS = {"rmse_tonemapped": metrics.rmse_tonemapped, "ssim": metrics.ssim, "flip_hdr": metrics.flip_hdr,
                 "relative_rmse": metrics.relative_rmse}


@dataclass(frozen=True)
class Source:
    """What the networks learn: ``spec`` as ``mi.load_dict`` takes it in a spectral variant;
    ``rgb_spec`` the same in RGB variants (None where Mitsuba cannot load it there)."""

    key: str
    label: str
    spec: dict
    rgb_spec: dict | None
    path: Path
    rgl: bool = False
    note: str = ""


def material_source(material: str, alpha: float, work: Path) -> Source:
    spec = {"type": "roughconductor", "material": material, "alpha": alpha}
    path = work / f"{material}.json"
    path.write_text(json.dumps(spec) + "\n")
    return Source(material, material, spec, spec, path)


def rgl_source(path: Path, work: Path) -> Source:
    """A spectral RGL measurement as a source; an RGB one is first made spectral (synthetic
    spectra, :mod:`nbrdf_tools.data.spectral_rgl`)."""
    from nbrdf_tools.data import spectral_rgl

    fields = spectral_rgl.read_tensor_file(path)
    note = ""
    if "wavelengths" not in fields:
        spectral = work / f"{path.name.removesuffix('.bsdf').removesuffix('_rgb')}_spec.bsdf"
        spectral_rgl.write_spectral(path, spectral, spectral_rgl.parse_wavelengths("360:1000:33"))
        note = (f"synthetic spectra: `{path.name}` (RGB) made spectral by `python -m nbrdf_tools spectral-rgl` "
                "(each RGB value times three Gaussian basis spectra)")
        path = spectral
    key = path.name.removesuffix(".bsdf")
    return Source(key, key, {"type": "measured", "filename": str(path)}, None, path, rgl=True, note=note)


class Steps:
    """One JSON record per finished step under ``folder``, with the settings it was made with:
    with ``resume`` a step whose record has the same settings (and whose files exist) is read
    back instead of done again."""

    def __init__(self, folder: Path, settings: dict, resume: bool):
        self.folder, self.settings, self.resume = folder, settings, resume
        folder.mkdir(parents=True, exist_ok=True)

    def run(self, name: str, compute, files: tuple[Path, ...] = ()):
        record = self.folder / f"{name}.json"
        if self.resume and record.exists() and all(Path(f).exists() for f in files):
            saved = json.loads(record.read_text(encoding="utf-8"))
            if saved.get("settings") == self.settings:
                return saved["value"]
        value = compute()
        record.write_text(json.dumps({"settings": self.settings, "value": value}) + "\n", encoding="utf-8")
        return value


def _document_summary(path: Path) -> dict:
    document = json.loads(path.read_text(encoding="utf-8"))
    return {"provenance": document["provenance"], "version": document["version"],
            "parameters": sum(len(layer["weights"]) + len(layer["bias"]) for layer in document["layers"])}


def distil(source: Path, output: Path, variant: str, extra: list[str]) -> dict:
    """Runs ``python -m nbrdf_mitsuba.distill SOURCE -o OUTPUT --variant VARIANT`` in this process;
    returns the network's provenance, its parameter count and the wall and CPU seconds."""
    from nbrdf_mitsuba import distill

    start, cpu = time.perf_counter(), time.process_time()
    status = distill.main([str(source), "-o", str(output), "--variant", variant, "-q", *extra])
    if status != 0:
        raise SystemExit(f"spectral_report: distilling {source} in {variant} failed (status {status})")
    return {**_document_summary(output), "seconds": time.perf_counter() - start,
            "cpu_seconds": time.process_time() - cpu, "how": f"distill --variant {variant}"}


def train_rgb_from_measurement(source: Path, output: Path, extra: list[str]) -> dict:
    """``nbrdf train SOURCE -o OUTPUT`` with the RGB output (the measurement's sRGB projection)."""
    cli = default_cli()
    help_text = subprocess.run([str(cli), "train", "--help"], capture_output=True, text=True).stdout
    # The trainer that makes spectral networks from *_spec.bsdf by default takes --output-kind rgb
    # for the projection; before it, the projection was the only output.
    kind = ["--output-kind", "rgb"] if "--output-kind" in help_text else []
    command = [str(cli), "train", str(source), "-o", str(output), *kind, *extra]
    start, children = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"spectral_report: {' '.join(command)} failed: {result.stderr.strip()}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - children.ru_utime) + (after.ru_stime - children.ru_stime)
    summary = _document_summary(output)
    if summary["version"] == 3:
        raise SystemExit(f"spectral_report: {' '.join(command)} wrote a spectral network, not an RGB one")
    return {**summary, "seconds": time.perf_counter() - start, "cpu_seconds": cpu,
            "how": " ".join(["nbrdf train", *kind])}


def make_networks(source: Source, args, steps: Steps) -> tuple[dict, dict]:
    """(paths, runs) of the spectral and the RGB network of ``source``."""
    extra = [*(["--samples", str(args.samples)] if args.samples else []),
             *(["--epochs", str(args.epochs)] if args.epochs else []),
             *(["--threads", str(args.threads)] if args.threads else [])]
    paths = {kind: args.work / f"{source.key}-{kind}.nbrdf.json" for kind in NETWORKS}
    runs = {"spectral": steps.run(f"{source.key}-spectral-network",
                                  lambda: distil(source.path, paths["spectral"], SPECTRAL, extra), (paths["spectral"],))}
    if source.rgl:
        make_rgb = lambda: train_rgb_from_measurement(source.path, paths["rgb"], extra)  # noqa: E731
    else:
        make_rgb = lambda: distil(source.path, paths["rgb"], RGB, extra)  # noqa: E731
    runs["rgb"] = steps.run(f"{source.key}-rgb-network", make_rgb, (paths["rgb"],))
    for kind, path in paths.items():
        runs[kind]["sampling"] = steps.run(f"{source.key}-{kind}-sampling", lambda: fit_sampling(path),  # noqa: B023
                                           (path,))
    return paths, runs


def fit_sampling(network: Path) -> dict:
    """``nbrdf fit-phong NETWORK`` (in place), as the library converter does, so that the network
    renders with its own lowest-variance sampling instead of distill's cosine lobe; a spectral
    network is fitted on its sRGB projection (one density for every wavelength)."""
    start = time.perf_counter()
    result = subprocess.run([str(default_cli()), "fit-phong", str(network)], capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"spectral_report: nbrdf fit-phong {network} failed: {result.stderr.strip()}")
    sampling = json.loads(network.read_text(encoding="utf-8"))["sampling"]
    return {"default": sampling.get("default"), "seconds": time.perf_counter() - start}


def pairs(count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(view, light) planar float64: ``count`` uniform pairs above the horizon (float32 too)."""
    u = splitmix_uniforms(seed, PAIR_STREAM, 0, 2 * count)
    light, view = sample_directions("uniform", u)
    keep = (light.astype(np.float32)[2] > 0) & (view.astype(np.float32)[2] > 0)
    return view[:, keep][:, :count], light[:, keep][:, :count]


def log_errors(values: dict[str, np.ndarray]) -> dict[str, list[float]]:
    """Per wavelength (row), ``mean |ln(1 + max(source, 0)) - ln(1 + max(v, 0))|`` over the pairs
    (columns) of each of ``values`` but ``source``."""
    reference = np.log1p(np.maximum(values["source"], 0.0))
    return {name: [metrics.mae(reference[j], np.log1p(np.maximum(v[j], 0.0))) for j in range(len(v))]
            for name, v in values.items() if name != "source"}


def per_wavelength_log_error(bsdfs: dict, view: np.ndarray, light: np.ndarray) -> dict[str, list[float]]:
    """:func:`log_errors` of each BSDF of ``bsdfs`` (dictionaries for ``mi.load_dict``) against
    ``source``, evaluated at distill's wavelengths in ``llvm_ad_spectral``."""
    from nbrdf_mitsuba import distill

    mi.set_variant(SPECTRAL)
    return log_errors({name: distill.eval_cos(mi.load_dict(spec), view, light) for name, spec in bsdfs.items()})


def interpolation_errors(spec: dict, view: np.ndarray, light: np.ndarray) -> dict[str, list[float]]:
    """Per sampling step (nm, as a string): [mean, worst] relative RMS over pairs of the
    piecewise-linear spectrum through samples ``step`` apart from 360 nm (and one at 830 nm)
    against the spectrum every 1 nm (pairs whose spectrum peaks above 1e-3 only)."""
    from nbrdf_mitsuba import distill

    mi.set_variant(SPECTRAL)
    bsdf = mi.load_dict(spec)
    fine = np.arange(360.0, 830.0 + 1e-9, 1.0)
    reference = distill.eval_cos(bsdf, view, light, fine)
    seen = np.flatnonzero(reference.max(axis=0) > 1e-3)
    out = {}
    for step in STEPS_NM:
        # Ends at 830 nm even where the step does not divide the range (np.interp would hold the
        # last sample beyond it).
        grid = np.append(np.arange(360.0, 830.0 - 1e-9, step), 830.0)
        samples = distill.eval_cos(bsdf, view, light, grid)
        errors = np.array([metrics.relative_rmse(reference[:, i], np.interp(fine, grid, samples[:, i])) for i in seen])
        out[f"{step:g}"] = [float(errors.mean()), float(errors.max())]
    return out


def sphere_scene(bsdf: dict, size: int) -> dict:
    """A sphere under a directional light 40 degrees off the view and a dim white environment."""
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 22.0,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 6], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}}},
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "sun": {"type": "directional", "direction": [-0.5, -0.45, -0.75], "irradiance": {"type": "d65", "scale": 3.0}},
        "sky": {"type": "constant", "radiance": {"type": "d65", "scale": 0.15}},
    }


#: The source rendered again at another seed: its error against the source is the Monte Carlo
#: noise floor of the image metrics.
NOISE = "source-seed1"


def render_spheres(bsdfs: dict, size: int, spp: int, variant: str, folder: Path, key: str) -> dict:
    """Renders each BSDF's sphere in ``variant`` (after a 1-spp render that compiles the kernels),
    and the source's again at seed 1 (:data:`NOISE`); writes ``folder/KEY-VARIANT-NAME.exr``;
    returns name -> [path, wall seconds, CPU seconds]."""
    mi.set_variant(variant)
    out = {}
    for name, spec in bsdfs.items():
        scene = mi.load_dict(sphere_scene(spec, size))
        warm_up(scene)
        for label, seed in ((name, 0), *(((NOISE, 1),) if name == "source" else ())):
            cpu = time.process_time()
            image, seconds = timed_render(scene, spp, seed=seed)
            path = write_exr(folder / f"{key}-{variant}-{label}.exr", image)
            out[label] = [str(path), seconds, time.process_time() - cpu]
    return out


def image_errors(images: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Every :data:`IMAGE_METRICS` of each image against ``images["source"]``."""
    reference = images["source"]
    return {name: {metric: f(reference, image) for metric, f in IMAGE_METRICS.items()}
            for name, image in images.items() if name != "source"}


def measure(source: Source, args, steps: Steps) -> dict:
    """Everything the report says about one source."""
    paths, runs = make_networks(source, args, steps)
    nets = {kind: {"type": "nbrdf", "filename": str(path)} for kind, path in paths.items()}
    view, light = pairs(args.pairs)
    errors = steps.run(f"{source.key}-log-errors",
                       lambda: per_wavelength_log_error({"source": source.spec, **nets}, view, light))
    renders, images = {}, {}
    for variant in VARIANTS:
        bsdfs = {**({"source": source.spec if variant == SPECTRAL else source.rgb_spec}), **nets}
        bsdfs = {name: spec for name, spec in bsdfs.items() if spec is not None}
        renders[variant] = steps.run(
            f"{source.key}-{variant}-images-fitted-sampling",
            lambda: render_spheres(bsdfs, args.size, args.spp, variant, args.work, source.key),  # noqa: B023
            tuple(args.work / f"{source.key}-{variant}-{name}.exr"
                  for name in [*bsdfs, *([NOISE] if "source" in bsdfs else [])]))
        images[variant] = {name: read_exr(Path(found[0])) for name, found in renders[variant].items()}
    interpolation = None
    if not source.rgl:
        small_view, small_light = pairs(200 if args.quick else 2000, seed=1)
        interpolation = steps.run(f"{source.key}-interpolation",
                                  lambda: interpolation_errors(source.spec, small_view, small_light))
    return {"source": source, "runs": runs, "log_errors": {k: np.asarray(v) for k, v in errors.items()},
            "renders": renders, "images": images,
            "image_errors": {variant: image_errors(found) if "source" in found else {}
                             for variant, found in images.items()},
            "interpolation": interpolation}


# -- figure and page --------------------------------------------------------------------------

LABELS = {"source": "source", "spectral": "spectral net", "rgb": "RGB net"}


def figure(results: list[dict], path: Path) -> Path:
    """One row per source: the six sphere images (tone-mapped) and the per-wavelength errors."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from nbrdf_mitsuba import distill

    columns = [(variant, name) for variant in VARIANTS for name in ("source", *NETWORKS)]
    fig, axes = plt.subplots(len(results), len(columns) + 1, figsize=(2.0 * len(columns) + 4.0, 2.4 * len(results)),
                             squeeze=False, gridspec_kw={"width_ratios": [1] * len(columns) + [2.2]})
    for row, result in zip(axes, results):
        source = result["source"]
        for ax, (variant, name) in zip(row, columns):
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"{source.label if name == 'source' else LABELS[name]}\n{variant}", fontsize=7)
            image = result["images"][variant].get(name)
            if image is None:
                ax.set_box_aspect(1)
                ax.text(0.5, 0.5, "Mitsuba's measured:\nspectral files\nneed a spectral variant", fontsize=6,
                        ha="center", va="center", transform=ax.transAxes)
                continue
            ax.imshow(metrics.tone_map(image))
            found = result["image_errors"][variant].get(name)
            if found:
                ax.set_xlabel(f"FLIP {found['flip_hdr']:.3f}  SSIM {found['ssim']:.3f}", fontsize=6)
        ax = row[-1]
        for name, label in (("spectral", "spectral network"), ("rgb", "RGB network, uplifted")):
            ax.plot(distill.WAVELENGTHS, np.maximum(result["log_errors"][name], 1e-6), label=label)
        ax.set_title(f"{source.label}: log error per wavelength", fontsize=7)
        ax.set_xlabel("wavelength (nm)", fontsize=7)
        ax.set_yscale("log")
        ax.tick_params(labelsize=6)
        ax.legend(fontsize=6)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


PAGE = "spectral-networks"
AT_NM = (400, 500, 600, 700)


def _round(value: float) -> float:
    return float(f"{value:.6g}")


def page_data(command: str, args, results: list[dict], figure_path: Path) -> dict:
    """What the page reports of ``results`` (:func:`measure`), as stored in its data file."""
    from nbrdf_mitsuba import distill

    w = distill.WAVELENGTHS
    sources = []
    for r in results:
        source = r["source"]
        log = {}
        for name in NETWORKS:
            e = r["log_errors"][name]
            log[name] = {"mean": _round(e.mean()), "max": _round(e.max()), "worst_nm": float(w[int(np.argmax(e))]),
                         "at": [_round(e[int(np.argmin(np.abs(w - nm)))]) for nm in AT_NM]}
        images = {}
        for variant in VARIANTS:
            found = r["image_errors"][variant]
            images[variant] = {name: {"errors": {k: _round(v) for k, v in found[name].items()} if name in found else None,
                                      "noise": ({k: _round(found[NOISE][k]) for k in ("flip_hdr", "ssim")}
                                                if NOISE in found else None),
                                      "wall": _round(r["renders"][variant][name][1]),
                                      "cpu": _round(r["renders"][variant][name][2])}
                               for name in NETWORKS}
        training = {name: {"version": run["version"], "how": run["how"], "epochs": run["provenance"].get("epochs"),
                           "best_validation_loss": run["provenance"].get("best_validation_loss"),
                           "seconds": _round(run["seconds"]), "cpu_seconds": _round(run["cpu_seconds"]),
                           "parameters": run["parameters"], "sampling": run.get("sampling", {}).get("default")}
                    for name, run in r["runs"].items()}
        sources.append({"label": source.label, "rgl": source.rgl, "file": source.path.name, "note": source.note,
                        "log_errors": log, "images": images, "interpolation": r["interpolation"],
                        "training": training})
    provenance = results[0]["runs"]["spectral"]["provenance"]
    figure = figure_path.resolve()
    return {"command": command, "quick": args.quick, "alpha": args.alpha, "pairs": args.pairs, "size": args.size,
            "spp": args.spp, "samples": provenance.get("samples"), "max_epochs": provenance.get("max_epochs"),
            "wavelength_step": float(w[1] - w[0]),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores", "load_average": round(os.getloadavg()[0], 1),
            "figure": str(figure.relative_to(REPO)) if figure.is_relative_to(REPO) else str(figure_path),
            "sources": sources}


def parse_arguments(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m nbrdf_tools spectral-networks", description=__doc__.split("\n")[0])
    stored_page.add_arguments(parser, PAGE)
    parser.add_argument("--figure", type=Path, default=DEFAULT_FIGURE, help="the figure (default: %(default)s)")
    parser.add_argument("--work", type=Path, default=default_out("spectral-networks"),
                        help="sources, networks, EXR images and step records (default: %(default)s)")
    parser.add_argument("--resume", action="store_true",
                        help="reuse the steps recorded under --work with the same settings")
    parser.add_argument("--materials", default="Au,Cu",
                        help="comma-separated Mitsuba conductor names, '' for none (default: Au,Cu)")
    parser.add_argument("--rgl", type=Path, action="append", default=[],
                        help="an RGL measurement (*_spec.bsdf; an *_rgb.bsdf is made spectral with synthetic spectra); "
                             "repeatable")
    parser.add_argument("--alpha", type=float, default=0.2, help="roughconductor's alpha (default: 0.2)")
    parser.add_argument("--samples", type=int, help="training pairs (default: the trainer's)")
    parser.add_argument("--epochs", type=int, help="most epochs (default: the trainer's)")
    parser.add_argument("--threads", type=int, help="training threads (default: the trainer's, one per core)")
    parser.add_argument("--size", type=int, default=96, help="sphere image size in pixels (default: 96)")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel (default: 64)")
    parser.add_argument("--pairs", type=int, default=20000, help="pairs of directions for the log error (default: 20000)")
    parser.add_argument("--quick", action="store_true",
                        help="tiny budget (2000 pairs, 3 epochs, 24-pixel images, 4 spp, 2000 error pairs), for tests")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)
    if args.quick:
        args.samples, args.epochs = args.samples or 2000, args.epochs or 3
        args.size, args.spp, args.pairs = 24, 4, 2000
    for name in ("samples", "epochs", "threads", "size", "spp", "pairs"):
        value = getattr(args, name)
        if value is not None and value < 1:
            parser.error(f"--{name} must be at least 1, got {value}")
    return args


def settings_of(args) -> dict:
    """What a step's result depends on (a record made with other settings is not reused)."""
    # "record": the layout of the records; raised when a step's result gains a field.
    return {"record": 2, **{name: getattr(args, name)
                            for name in ("alpha", "samples", "epochs", "size", "spp", "pairs", "quick")}}


def main(argv: list[str] | None = None) -> int:
    from nbrdf_tools.pages import spectral_networks_page as text  # imports this module's constants

    args = parse_arguments(argv)
    if args.stored_only:
        stored_page.write(args.out, text.page(stored_page.load(stored_page.data_for(args, PAGE))))
        print(f"wrote {args.out} from {stored_page.data_for(args, PAGE)}")
        return 0
    progress.set_enabled(not args.no_progress)
    args.work.mkdir(parents=True, exist_ok=True)
    steps = Steps(args.work / "steps", settings_of(args), args.resume)
    sources = [material_source(m.strip(), args.alpha, args.work) for m in args.materials.split(",") if m.strip()]
    sources += [rgl_source(path, args.work) for path in args.rgl]
    if not sources:
        print("spectral_report: nothing to do (no --materials, no --rgl)", file=sys.stderr)
        return 2
    results = [measure(source, args, steps) for source in progress.bar(sources, desc="sources", unit="source")]
    figure(results, args.figure)
    words = ["python -m nbrdf_tools spectral-networks", *(argv if argv is not None else sys.argv[1:])]
    data = page_data(" ".join(words), args, results, args.figure)
    data_file = stored_page.save(stored_page.data_for(args, PAGE), data)
    stored_page.write(args.out, text.page(data, stored_page.opening_command(PAGE, args.out, data_file)))
    print(f"wrote {args.out}, {data_file} and {args.figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
