"""``python -m nbrdf_mitsuba.distill SOURCE -o OUT.nbrdf.json``: a neural BRDF learnt from any
Mitsuba 3 BSDF.

SOURCE is a scene XML file holding one BSDF (or a bare ``<bsdf>`` element), a JSON dictionary
for ``mi.load_dict``, or an RGL measurement (``.bsdf``, loaded as Mitsuba's ``measured``). The
trainer (``libnbrdf_train``, the C ABI of nbrdf-ffi/train) hands out its own sample directions;
Mitsuba evaluates the BSDF there and the values go back to the trainer, which learns a network
exactly as ``nbrdf train`` does (same sampling, loss, validation split and early stopping).

* Values: ``bsdf.eval(ctx, si, wo)`` with ``si.wi = view`` and ``wo = light`` in the local frame
  (``si.sh_frame`` the identity), which is ``f_r cos(theta_light)``: the very quantity the loss
  compares (``ln(1 + f cos_light)``), so it is never divided by the cosine and nothing blows up
  near the horizon.
* Reciprocity: by default the network learns ``f(view, light)`` as the BSDF evaluates it (what
  a scene with it renders); ``--reciprocal`` also evaluates the swapped pairs and learns
  ``(f(v, l) + f(l, v)) / 2``; the swapped term carries ``cos_light / cos_view``, so the trainer
  hands out no pair with a cosine below 0.01 and draws the next candidates in their place: the
  network trains on ``--samples`` pairs, as ``nbrdf train --rgl-fold reciprocal-mean`` does for RGL
  measurements.
* Spectra (``--variant llvm_ad_spectral`` or another ``*_spectral`` one): the BSDF is evaluated at
  :data:`WAVELENGTHS` (``si.wavelengths``, 4 per lane) and the trainer learns a spectral network
  (file format version 3, ``nbrdf_train_spectral_from_arrays``: 16 B-spline coefficients over
  360-830 nm, fitted per pair to the piecewise-linear spectrum through the samples).
* A BSDF returning NaN or infinity is an error (its first bad direction is named); slightly
  negative values are clamped to 0 by the trainer.
* Anisotropy (``--anisotropy auto|on|off``, as ``nbrdf train``): an anisotropic network also
  takes the half vector's azimuth ``phi_h`` (file format version 2) and is trained on the
  trainer's anisotropic directions with 5x the default samples. ``auto`` makes one when the
  BSDF's flags say ``Anisotropic`` or when its values change as view and light turn together
  about the normal (:func:`rotation_difference`): a Python BSDF may not set the flag.

``--spatial`` distils a textured BSDF into a spatially varying material instead (a decoder and a
latent texture, file format version 4): :mod:`nbrdf_mitsuba.distill.spatial`.

Errors are one line on stderr: a usage or input error (a missing or invalid source, an invalid
setting or output path, a BSDF that is not finite) exits with status 2, a training that fails or
a network that cannot be written once trained with 1.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from .. import _exit, _llvm

_llvm.configure()  # must precede the first import of drjit

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

FORMATS = {".xml": "xml", ".json": "json", ".bsdf": "rgl"}
#: Pairs per Mitsuba call in JIT variants (bounds the kernel's memory).
CHUNK = 1 << 20


class DistillError(Exception):
    """A usage or input error: printed as one line, exit status 2."""

    exit_status = _exit.USAGE


class DistillFailed(DistillError):
    """The training, or the writing of its network, failed: one line, exit status 1."""

    exit_status = _exit.FAILED


# -- the source ----------------------------------------------------------------------------------


def pick_variant(requested: str | None = None) -> str:
    """``requested``, else ``llvm_ad_rgb`` when Dr.Jit's LLVM backend works, else ``scalar_rgb``."""
    available = mi.variants()
    if requested:
        if requested not in available:
            raise DistillError(f"Mitsuba variant '{requested}' is not available (these are: {', '.join(available)})")
        if not requested.endswith(("_rgb", "_spectral")):
            raise DistillError(f"variant '{requested}': the network learns RGB (an *_rgb variant) or spectra "
                               "(an *_spectral one, e.g. llvm_ad_spectral)")
        return requested
    if "llvm_ad_rgb" in available and _llvm.problem() is None:
        return "llvm_ad_rgb"
    return "scalar_rgb"


def top_level_bsdfs(root) -> list:
    """The BSDFs of a loaded object that are not nested in another BSDF, in load order."""
    if isinstance(root, mi.BSDF):
        return [root]
    hierarchy = mi.traverse(root).hierarchy
    return [obj for obj, (parent, _) in hierarchy.items()
            if isinstance(obj, mi.BSDF) and not isinstance(parent, mi.BSDF)]


def load_bsdf(source: Path, bsdf_id: str | None = None):
    """(BSDF, format) of SOURCE; a :class:`DistillError` for anything a user can fix."""
    if not source.is_file():
        raise DistillError(f"{source}: no such file")
    kind = FORMATS.get(source.suffix.lower())
    if kind is None:
        raise DistillError(f"{source}: unknown kind of source (expected .xml, .json or .bsdf)")
    try:
        if kind == "rgl":
            root = mi.load_dict({"type": "measured", "filename": str(source)})
        elif kind == "json":
            try:
                spec = json.loads(source.read_text(encoding="utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as error:
                raise DistillError(f"{source}: not JSON: {error}") from None
            if not isinstance(spec, dict) or "type" not in spec:
                raise DistillError(f"{source}: expected a JSON object for mi.load_dict, with a \"type\"")
            root = mi.load_dict(spec)
        else:
            root = mi.load_file(str(source))
    except DistillError:
        raise
    except Exception as error:  # Mitsuba reports malformed scenes as plain exceptions
        message = str(error).strip().splitlines()
        raise DistillError(f"{source}: Mitsuba cannot load it: {message[-1] if message else error}") from None
    bsdfs = top_level_bsdfs(root)
    if bsdf_id is not None:
        bsdfs = [b for b in bsdfs if b.id() == bsdf_id]
        if not bsdfs:
            raise DistillError(f"{source}: no BSDF with id '{bsdf_id}'")
    if not bsdfs:
        raise DistillError(f"{source}: holds no BSDF")
    if len(bsdfs) > 1:
        ids = ", ".join(b.id() or type(b).__name__ for b in bsdfs)
        raise DistillError(f"{source}: holds {len(bsdfs)} BSDFs ({ids}); keep one, or pick one with --bsdf ID")
    return bsdfs[0], kind


# -- evaluation ----------------------------------------------------------------------------------


#: The wavelengths (nm) a BSDF is evaluated at in spectral variants: every 10 nm over 360-830, 48
#: of them (12 evaluations of Mitsuba's 4 wavelengths per lane). The network's target is the
#: B-spline fit of the piecewise-linear spectrum through these samples; its 16 coefficients span
#: 36 nm each. Measured on roughconductor (alpha 0.2) Au and Cu at 2000 pairs against their spectra
#: sampled every 1 nm, linear interpolation between samples every 5 / 10 / 20 / 40 nm is off by
#: 0.03-0.04 / 0.09-0.12 / 0.3-0.4 / 0.8-1.1 % (mean relative RMS; worst pair 0.15 % at 10 nm),
#: against the 0.5 % the 16-coefficient basis itself leaves on these conductors
#: (docs/results/spectral-basis.md): 10 nm adds little to it at a quarter of 5 nm's cost.
WAVELENGTHS = np.arange(360.0, 830.0 + 1e-9, 10.0)


def _interaction(n: int | None, view, uv=None):
    """A surface interaction in the local frame (``si.sh_frame`` the identity) viewed from
    ``view`` at texture coordinates ``uv`` (default the texture's centre): n lanes of planar
    (3, n) directions and (2, n) ``uv`` in JIT variants, one (3,) direction and (2,) ``uv`` else."""
    si = dr.zeros(mi.SurfaceInteraction3f, n) if n is not None else dr.zeros(mi.SurfaceInteraction3f)
    si.sh_frame = mi.Frame3f(mi.Vector3f(1, 0, 0), mi.Vector3f(0, 1, 0), mi.Vector3f(0, 0, 1))
    si.n = mi.Normal3f(0, 0, 1)
    if uv is None:
        si.uv = mi.Point2f(0.5, 0.5)
    else:
        si.uv = mi.Point2f(np.ascontiguousarray(uv, dtype=np.float32)) if n is not None else mi.Point2f(*map(float, uv))
    si.wi = mi.Vector3f(np.ascontiguousarray(view, dtype=np.float32)) if n is not None else mi.Vector3f(*map(float, view))
    return si


def _wavelength_groups(wavelengths) -> list:
    """Mitsuba's 4 wavelengths per lane, in groups covering ``wavelengths`` (the last group padded
    with its last wavelength); ``[None]`` in RGB variants."""
    if not mi.is_spectral:
        return [None]
    w = np.asarray(WAVELENGTHS if wavelengths is None else wavelengths, dtype=np.float64)
    w = np.concatenate([w, np.full(-len(w) % 4, w[-1])])
    return [tuple(map(float, w[k:k + 4])) for k in range(0, len(w), 4)]


def eval_cos(bsdf, view: np.ndarray, light: np.ndarray, wavelengths=None, uv: np.ndarray | None = None) -> np.ndarray:
    """Planar float64 ``bsdf.eval`` (``f_r cos(theta_light)``) at planar (3, n) ``view`` (``si.wi``)
    and ``light`` (``wo``) in the local frame, in the current variant: (3, n) RGB, or in spectral
    variants (m, n), the value at wavelength j of pair i at ``[j, i]`` (``wavelengths``, default
    :data:`WAVELENGTHS`, m of them, set through ``si.wavelengths`` 4 at a time). ``uv``: planar
    (2, n) texture coordinates (``si.uv``) of each pair; by default the texture's centre."""
    ctx = mi.BSDFContext()
    n = view.shape[1]
    groups = _wavelength_groups(wavelengths)
    channels = 3 if groups == [None] else len(WAVELENGTHS if wavelengths is None else wavelengths)
    out = np.empty((4 * len(groups) if groups != [None] else 3, n))
    jit = dr.is_jit_v(mi.Float)
    for start in range(0, n, CHUNK if jit else 1):
        stop = min(start + (CHUNK if jit else 1), n)
        uv_chunk = None if uv is None else uv[:, start:stop] if jit else uv[:, start]
        si = (_interaction(stop - start, view[:, start:stop], uv_chunk) if jit
              else _interaction(None, view[:, start], uv_chunk))
        wo = mi.Vector3f(np.ascontiguousarray(light[:, start:stop], dtype=np.float32)) if jit else (
            mi.Vector3f(*map(float, light[:, start])))
        for g, group in enumerate(groups):
            if group is not None:
                si.wavelengths = mi.UnpolarizedSpectrum(*group)
                if jit:  # kernel parameters, not literals: one kernel for every group
                    dr.make_opaque(si.wavelengths)
            value = bsdf.eval(ctx, si, wo)
            rows = slice(4 * g, 4 * g + 4) if group is not None else slice(0, 3)
            out[rows, start:stop] = (np.asarray(value.numpy(), dtype=np.float64).reshape(-1, stop - start) if jit
                                     else np.asarray(value, dtype=np.float64).reshape(-1, 1))
    return out[:channels]


def check_finite(values: np.ndarray, view: np.ndarray, light: np.ndarray, what: str) -> None:
    bad = ~np.all(np.isfinite(values), axis=0)
    if bad.any():
        i = int(np.argmax(bad))
        raise DistillError(
            f"the BSDF returned {int(bad.sum())} {what} that are not finite numbers (first: {values[:, i].tolist()} "
            f"at view {view[:, i].tolist()}, light {light[:, i].tolist()}); a BSDF must evaluate to finite values")


# -- anisotropy ----------------------------------------------------------------------------------

#: ``--anisotropy auto`` calls a BSDF anisotropic above this :func:`rotation_difference`. An
#: isotropic BSDF differs by float32 rounding only (about 1e-6; a few 1e-4 for a very sharp
#: highlight); roughconductor with alpha_u 0.05, alpha_v 0.3 by about 0.5.
ROTATION_TOLERANCE = 1e-2
ANISOTROPY = ("auto", "on", "off")
#: Random pairs of the rotation check.
ROTATION_PAIRS = 4096


def rotation_difference(bsdf, pairs: int = ROTATION_PAIRS, seed: int = 7) -> float:
    """``sum |f(R v, R l) - f(v, l)| / sum (f(R v, R l) + f(v, l))`` (all channels) over random
    view/light pairs above the horizon, each turned by its own random angle about the normal:
    0 for an isotropic BSDF, up to 1 for one whose highlight depends on the azimuth."""
    rng = np.random.default_rng(seed)

    def hemisphere(n):
        cos = rng.uniform(0.05, 1.0, n)  # not grazing: a horizon cut would dominate rounding
        sin, phi = np.sqrt(1 - cos * cos), rng.uniform(0, 2 * np.pi, n)
        return np.stack([sin * np.cos(phi), sin * np.sin(phi), cos])

    view, light = hemisphere(pairs), hemisphere(pairs)
    # Half the pairs near the mirror direction, where a highlight's shape shows.
    mirror = pairs // 2
    light[:, :mirror] = view[:, :mirror] * np.array([[-1], [-1], [1]])
    light[:2, :mirror] += rng.normal(0, 0.15, (2, mirror))
    light[2, :mirror] = np.abs(light[2, :mirror]) + 0.05
    light /= np.linalg.norm(light, axis=0)
    angle = rng.uniform(0.3, 2 * np.pi - 0.3, pairs)
    c, s = np.cos(angle), np.sin(angle)

    def turn(d):
        return np.stack([c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]])

    a, b = eval_cos(bsdf, view, light), eval_cos(bsdf, turn(view), turn(light))
    check_finite(a, view, light, "values")
    check_finite(b, turn(view), turn(light), "values")
    total = float(np.sum(np.abs(a) + np.abs(b)))
    return 0.0 if total == 0 else float(np.sum(np.abs(a - b)) / total)


def decide_anisotropy(bsdf, requested: str) -> tuple[bool, dict]:
    """Whether to train an anisotropic network for ``--anisotropy requested``, and why (stored in
    the provenance)."""
    if requested not in ANISOTROPY:
        raise DistillError(f"--anisotropy {requested!r}: expected one of {', '.join(ANISOTROPY)}")
    flagged = bool(bsdf.flags() & mi.BSDFFlags.Anisotropic)
    why = {"requested": requested, "bsdf_flag_anisotropic": flagged}
    if requested != "auto":
        return requested == "on", why
    difference = rotation_difference(bsdf)
    why["rotation_difference"] = round(difference, 6)
    return flagged or difference > ROTATION_TOLERANCE, why


# -- the command ---------------------------------------------------------------------------------


def network_name(output: Path) -> str:
    """The output's file name without extensions (``gold.nbrdf.json`` gives ``gold``)."""
    return output.name.split(".")[0] or "nbrdf"


def set_options(config, values, options: dict[str, str]) -> None:
    """Sets each given ``(field, value)`` of a trainer's C config; a value the field cannot hold
    is a :class:`DistillError` naming its command-line option (``options[field]``, else
    ``--field``)."""
    for field, value in values:
        if value is not None:
            option = options.get(field, f"--{field.replace('_', '-')}")
            try:
                if isinstance(value, int) and value < 0:
                    raise OverflowError
                setattr(config, field, value)
            except OverflowError:
                raise DistillError(f"{option} {value} is out of range") from None


def config_from(args):
    from .. import _train_native as native

    config = native.default_config()
    set_options(config, (("samples", args.samples), ("max_epochs", args.epochs), ("hidden", args.hidden),
                         ("batch", args.batch), ("seed", args.seed), ("threads", args.threads),
                         ("learning_rate", args.learning_rate), ("target_loss", args.target_loss)),
                {"max_epochs": "--epochs"})
    if args.sampling is not None:
        config.sampling = native.SAMPLINGS[args.sampling]
    return config


def distill(args) -> dict:
    """Runs the command; returns a summary (printed by :func:`main`)."""
    output = args.output
    if output.is_dir():
        raise DistillError(f"{output}: is a directory; name the network file, e.g. {output / 'out.nbrdf.json'}")
    if not output.parent.is_dir() or not os.access(output.parent, os.W_OK):
        raise DistillError(f"{output}: cannot write there (the folder {output.parent} does not exist or is not writable)")
    if args.spatial:
        from .spatial import distill_spatial

        return distill_spatial(args, output)
    spatial_only = [option for option, value in (("--resolution", args.resolution), ("--channels", args.channels),
                                                 ("--lobes", args.lobes), ("--representatives", args.representatives),
                                                 ("--parameters", args.parameters))
                    if value is not None]
    if spatial_only:
        raise DistillError(f"{', '.join(spatial_only)}: only with --spatial (a spatially varying material)")
    variant = pick_variant(args.variant)
    mi.set_variant(variant)
    bsdf, kind = load_bsdf(args.source, args.bsdf)
    from .. import _train_native as native

    config = config_from(args)
    anisotropic, anisotropy = decide_anisotropy(bsdf, args.anisotropy)
    try:
        # The trainer's default sample count grows for anisotropic networks; a user's stays.
        native.for_anisotropy(config, anisotropic, scale_samples=args.samples is None)
    except native.TrainError as error:
        raise DistillError(str(error)) from None
    fold = "reciprocal-mean" if args.reciprocal else "as-measured"
    start = time.perf_counter()
    try:
        view, light, n_validation = native.sample_directions(config, fold=fold)
    except native.TrainError as error:
        raise DistillError(str(error)) from None
    values = eval_cos(bsdf, view, light)
    check_finite(values, view, light, "values")
    swapped = None
    if args.reciprocal:
        swapped = eval_cos(bsdf, light, view)
        check_finite(swapped, light, view, "swapped values")
    evaluation_seconds = time.perf_counter() - start
    details = {
        "renderer": f"Mitsuba {mi.__version__}",
        "variant": variant,
        "format": kind,
        "file": str(args.source),
        "bsdf": str(bsdf),
        "values": "BSDF.eval(si.wi = view, wo = light) = f_r cos(theta_light), local frame",
        "evaluation_seconds": round(evaluation_seconds, 3),
        "anisotropy": anisotropy,
    }
    train = native.train_from_arrays
    if mi.is_spectral:
        details["wavelengths_nm"] = [float(w) for w in WAVELENGTHS]

        def train(config, view, light, values, *rest, **options):
            return native.train_spectral_from_arrays(config, view, light, WAVELENGTHS, values, *rest, **options)
    progress = _progress(args.quiet, config.max_epochs)
    try:
        text = train(
            config, view, light, values, n_validation, name=args.name or network_name(output),
            source=f"Mitsuba BSDF {args.source}", details=details, swapped_eval_cos=swapped,
            fold=fold, on_epoch=progress.update)
    except native.TrainError as error:  # the settings passed sample_directions: the training failed
        raise DistillFailed(str(error)) from None
    finally:
        progress.close()
    try:
        output.write_text(text, encoding="utf-8")
    except OSError as error:
        raise DistillFailed(f"{output}: cannot write the network: {error.strerror or error}") from None
    provenance = json.loads(text)["provenance"]
    return {
        "output": output, "pairs": view.shape[1], "validation": n_validation, "variant": variant,
        "evaluation_seconds": evaluation_seconds, "seconds": time.perf_counter() - start,
        "epochs": provenance["epochs"], "loss": provenance["best_validation_loss"],
        "anisotropic": anisotropic, "spectral": bool(mi.is_spectral),
    }


class _progress:
    """A tqdm bar over the epochs when tqdm is installed and the output is a terminal."""

    def __init__(self, quiet: bool, epochs: int):
        self.bar = None
        if not quiet and sys.stderr.isatty():
            try:
                from tqdm import tqdm
            except ImportError:
                return
            self.bar = tqdm(total=epochs, unit="epoch", desc="training")

    def update(self, stats) -> None:
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(loss=f"{stats.validation_loss:.3e}")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m nbrdf_mitsuba.distill",
        description="Train a neural BRDF (*.nbrdf.json) from any Mitsuba 3 BSDF: Mitsuba evaluates it at the "
                    "trainer's sample directions, and nbrdf's trainer learns the values (as `nbrdf train`). With "
                    "--spatial, a spatially varying material (a decoder and a latent texture) from a textured BSDF.")
    p.add_argument("source", type=Path,
                   help="the BSDF: a scene .xml holding one BSDF (or a bare <bsdf> element), a .json dictionary "
                        "for mi.load_dict, or an RGL measurement .bsdf")
    p.add_argument("-o", "--output", type=Path, required=True, help="the network file to write, e.g. OUT.nbrdf.json")
    p.add_argument("--name", help="name stored in the network (default: the output's file name without extensions)")
    p.add_argument("--bsdf", metavar="ID", help="the id of the BSDF to distil when SOURCE holds several")
    p.add_argument("--variant", help="Mitsuba variant: an *_rgb one (an RGB network; default: llvm_ad_rgb when "
                                     "available, else scalar_rgb, which is much slower) or an *_spectral one (a "
                                     "spectral network, file format version 3: 16 B-spline coefficients over "
                                     "360-830 nm, learnt from the BSDF evaluated every 10 nm), e.g. llvm_ad_spectral")
    p.add_argument("--reciprocal", action="store_true",
                   help="learn (f(view, light) + f(light, view)) / 2 instead of the BSDF as it evaluates (on "
                        "pairs with both cosines at least 0.01, still --samples of them)")
    p.add_argument("--anisotropy", default="auto", choices=ANISOTROPY,
                   help="an anisotropic network (its input carries the half vector's azimuth; 5x the default "
                        "samples): on, off, or auto (default): when the BSDF's flags say Anisotropic or its values "
                        "change as view and light turn together about the normal")
    p.add_argument("--samples", type=int, help="training pairs (default: the trainer's, 800000; 4000000 for "
                                               "an anisotropic network)")
    p.add_argument("--epochs", type=int, help="most epochs (default: the trainer's, 300, with early stopping)")
    p.add_argument("--hidden", type=int, help="hidden layer width (default: 21, the paper's)")
    p.add_argument("--batch", type=int, help="mini-batch size (default: 512)")
    p.add_argument("--learning-rate", type=float, help="Adam's step size (default: 1e-3)")
    p.add_argument("--target-loss", type=float, help="stop once the validation loss is at most this (default: 2e-4)")
    p.add_argument("--sampling", choices=["adaptive", "uniform"], help="how pairs are drawn (default: adaptive)")
    p.add_argument("--seed", type=int, help="random seed (default: 0)")
    p.add_argument("--threads", type=int, help="training threads (default: one per core)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    spatial = p.add_argument_group(
        "spatially varying materials", "--spatial distils a textured BSDF into a decoder and a latent texture "
        "(docs/textured.md). These apply too, with their own defaults: --samples (1000000 pairs, 8 a texel), "
        "--epochs (40), --hidden (the decoder's, 32), --batch (512), --learning-rate (0.002); and --sampling, "
        "--seed, --threads, --anisotropy, --variant (an *_rgb one, or an *_spectral one for a spectral material), "
        "--name, --bsdf")
    spatial.add_argument("--spatial", action="store_true",
                         help="write a spatially varying material (file format version 4, its latent texture "
                              "OUT.latent.exr beside it) from a textured BSDF: a twosided gives its front, a bumpmap "
                              "or normalmap wrapper its nested BSDF (keep the wrapper in the scene); a BSDF that is "
                              "the same at every texel is refused (distil it without --spatial)")
    spatial.add_argument("--resolution", type=int, metavar="N",
                         help="the latent texture's size, N x N texels (default: the largest bitmap the BSDF reads, "
                              "times its to_uv tiling; 256 x 256 without one)")
    spatial.add_argument("--channels", type=int, metavar="C", help="latent channels per texel (default: 8)")
    spatial.add_argument("--lobes", type=int, choices=[0, 1, 2],
                         help="sampling lobes per texel, fitted to representative codes (default: 1; 0: cosine "
                              "sampling)")
    spatial.add_argument("--representatives", type=int, metavar="K",
                         help="representative codes whose lobes are fitted, each texel taking its nearest one's "
                              "(default: 64, at most 256; the fits are most of the baking's time)")
    spatial.add_argument("--parameters", choices=["signature", "textures"],
                         help="what describes a texel to the encoder: the BSDF's values at fixed direction pairs "
                              "there (default) or the values of the textures it reads")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        summary = distill(args)
    except DistillError as error:
        print(f"error: {error}", file=sys.stderr)
        return error.exit_status
    except ImportError as error:  # the training library is missing: nothing can be trained
        print(f"error: {error}", file=sys.stderr)
        return _exit.FAILED
    except KeyboardInterrupt:  # delivered once the running Mitsuba or trainer call returns
        print("error: interrupted; no network written", file=sys.stderr)
        return 130
    if args.spatial:
        from .spatial import report

        print(report(summary))
        return _exit.SUCCESS
    kind = ("anisotropic" if summary["anisotropic"] else "isotropic") + (", spectral" if summary["spectral"] else "")
    print(f"wrote {summary['output']} ({kind}): {summary['pairs'] - summary['validation']} samples "
          f"(+{summary['validation']} validation) evaluated by Mitsuba ({summary['variant']}) in "
          f"{summary['evaluation_seconds']:.1f} s; {summary['epochs']} epochs, best validation loss "
          f"{summary['loss']:.4e}; {summary['seconds']:.1f} s in all")
    return _exit.SUCCESS

