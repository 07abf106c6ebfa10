"""``python -m nbrdf_mitsuba.distill SOURCE --spatial -o OUT.nbrdf.json``: a spatially varying
neural material (a decoder and a latent texture, file format version 4) learnt from a textured
Mitsuba 3 BSDF (docs/textured.md, "Distilling a textured BSDF").

Every texel of the output is described by the source's parameters there (:func:`parameter_image`);
an encoder (parameters -> latent code) and the decoder are trained jointly in Rust
(``nbrdf_train_textured``) on the source's ``BSDF.eval`` at random texels and the trainer's own
direction pairs, and the encoder's code of every texel becomes the latent texture, with sampling
lobes fitted to representative codes.

* What is distilled (:func:`distilled_part`): a ``twosided`` source gives its front BSDF (the
  material is seen from above its surface); a ``bumpmap`` or ``normalmap`` wrapper gives the BSDF
  it wraps, and the wrapper must stay in the scene around the ``nbrdf`` BSDF; a wrapper nested
  deeper (inside a ``blendbsdf``) cannot be separated and is refused.
* A source whose values do not vary over the texture is refused, pointing to the plain distill.
* Spectra (an ``*_spectral`` variant): the training values are the source's at
  :data:`~nbrdf_mitsuba.distill.WAVELENGTHS`, as for a spectral network, and the material is
  spectral (its decoder gives B-spline coefficients); a texel's signature reads the source at
  :data:`SIGNATURE_WAVELENGTHS`.
"""

from __future__ import annotations

import hashlib
import math
import sys
import time
from pathlib import Path

import numpy as np

from . import (
    WAVELENGTHS,
    DistillError,
    DistillFailed,
    _progress,
    check_finite,
    decide_anisotropy,
    eval_cos,
    load_bsdf,
    mi,
    network_name,
    pick_variant,
    set_options,
)

#: Classes that wrap one BSDF and change the shading frame from a texture: distilled without them.
FRAME_WRAPPERS = ("BumpMap", "NormalMap")
#: The largest texture side of a material (``nbrdf_core::textured::MAX_TEXTURE_SIDE``).
MAX_SIDE = 16384
#: The side of the latent texture when the source reads no bitmap.
DEFAULT_SIDE = 256
#: Direction pairs drawn per texel visited in training.
PAIRS_PER_TEXEL = 8
#: Training samples by default (texel visits times :data:`PAIRS_PER_TEXEL`).
DEFAULT_SAMPLES = 1_000_000
#: Texels per Mitsuba call when evaluating the parameters over the texture.
TEXEL_CHUNK = 1 << 16
#: The wavelengths (nm) of a texel's signature in spectral variants: one of Mitsuba's evaluations
#: (4 wavelengths a lane), spread over the observer's most sensitive range. Values at separate
#: wavelengths tell apart spectra that an RGB projection would merge, and need no projection.
SIGNATURE_WAVELENGTHS = (440.0, 510.0, 580.0, 650.0)


# -- what is distilled ---------------------------------------------------------------------------


def _children(bsdf) -> list:
    """The BSDFs directly nested in ``bsdf``, in load order."""
    hierarchy = mi.traverse(bsdf).hierarchy
    return [obj for obj, (parent, _) in hierarchy.items() if isinstance(obj, mi.BSDF) and parent is bsdf]


def distilled_part(bsdf) -> tuple[object, list[str]]:
    """(the BSDF whose values are distilled, notes for the user) for a loaded source: twosided
    and frame wrappers (:data:`FRAME_WRAPPERS`) at the top are unwrapped; a frame wrapper deeper
    down is a :class:`DistillError`."""
    notes = []
    while True:
        kind = bsdf.class_name()
        if kind.startswith("TwoSided"):
            bsdf = _children(bsdf)[0]
            notes.append("twosided: its front BSDF is distilled (the material as seen from above its surface)")
        elif kind in FRAME_WRAPPERS:
            name = kind.lower()
            bsdf = _children(bsdf)[0]
            notes.append(f"{name}: the BSDF it wraps is distilled; keep the {name} in the scene around the nbrdf "
                         f"BSDF (<bsdf type=\"{name}\"> ... <bsdf type=\"nbrdf\"/></bsdf>): its shading normals "
                         "are not in the material")
        else:
            break
    hierarchy = mi.traverse(bsdf).hierarchy
    nested = [obj.class_name() for obj in hierarchy if isinstance(obj, mi.BSDF) and obj.class_name() in FRAME_WRAPPERS]
    if nested:
        raise DistillError(f"the source holds a {nested[0].lower()} inside a {bsdf.class_name()}: a shading-frame "
                           "wrapper can be left out of the distillation only at the top of the BSDF (or inside a "
                           "twosided); move it there")
    return bsdf, notes


# -- the texture's size --------------------------------------------------------------------------


def bitmap_sizes(bsdf) -> list[tuple[int, int]]:
    """(width, height) in texels per unit of UV of every bitmap ``bsdf`` reads: each image's
    size, scaled by its ``to_uv`` (a texture tiled 4 times needs 4 times the texels)."""
    params = mi.traverse(bsdf)
    sizes = []
    for key in params.keys():
        if not key.endswith(".data"):
            continue
        shape = getattr(params[key], "shape", ())
        if len(shape) != 3:
            continue
        height, width = int(shape[0]), int(shape[1])
        scale_u = scale_v = 1.0
        transform = key[: -len(".data")] + ".to_uv"
        if transform in params.keys():
            matrix = np.array(params[transform].matrix, dtype=np.float64)
            scale_u, scale_v = np.linalg.norm(matrix[:2, 0]), np.linalg.norm(matrix[:2, 1])
        sizes.append((max(1, math.ceil(width * scale_u - 1e-6)), max(1, math.ceil(height * scale_v - 1e-6))))
    return sizes


def texture_size(bsdf, resolution: int | None) -> tuple[int, int]:
    """(width, height) of the latent texture: ``resolution`` squared when given, else the largest
    bitmap the BSDF reads (:func:`bitmap_sizes`, at most :data:`MAX_SIDE` a side), else
    :data:`DEFAULT_SIDE` squared."""
    if resolution is not None:
        if not 1 <= resolution <= MAX_SIDE:
            raise DistillError(f"--resolution {resolution}: expected 1 to {MAX_SIDE} texels a side")
        return resolution, resolution
    sizes = bitmap_sizes(bsdf)
    if not sizes:
        return DEFAULT_SIDE, DEFAULT_SIDE
    width, height = max(sizes, key=lambda s: s[0] * s[1])
    return min(width, MAX_SIDE), min(height, MAX_SIDE)


def texel_centres(width: int, height: int, texels: np.ndarray | None = None) -> np.ndarray:
    """Planar (2, n) UVs of texel centres, texel ``y width + x`` at ``((x + 1/2) / width,
    (y + 1/2) / height)``: row 0 at v = 0, as Mitsuba's ``bitmap`` and the latent texture read
    an image. All texels in order, or those of ``texels``."""
    t = np.arange(width * height) if texels is None else np.asarray(texels)
    return np.stack([(t % width + 0.5) / width, (t // width + 0.5) / height])


# -- the parameters of a texel -------------------------------------------------------------------


def _direction(theta_deg: float, phi_deg: float) -> np.ndarray:
    theta, phi = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def _mirror(view: np.ndarray, half: np.ndarray) -> np.ndarray:
    return 2 * np.dot(view, half) * half - view


def signature_pairs() -> tuple[np.ndarray, np.ndarray]:
    """Planar (3, K) view and light directions at which the source's values describe a texel:
    mirror pairs (half vector at the normal) from normal to grazing incidence; the half vector
    tilted from the normal by growing angles, in the plane of incidence and across it (a lobe's
    width, and its anisotropy); off-specular pairs (the diffuse part), a grazing pair and a
    retro-reflection pair."""
    pairs = [(_direction(theta, 0), _direction(theta, 180)) for theta in (0, 20, 40, 60, 80)]
    view = _direction(30, 0)
    for tilt in (3, 8, 16, 30):
        pairs.append((view, _mirror(view, _direction(tilt, 0))))
    for tilt in (3, 8, 16):
        pairs.append((view, _mirror(view, _direction(tilt, 90))))
    pairs += [(_direction(0, 0), _direction(60, 0)), (_direction(45, 0), _direction(45, 90)),
              (_direction(80, 0), _direction(80, 90)), (_direction(60, 0), _direction(60, 0))]
    view, light = (np.stack([p[k] for p in pairs], axis=1) for k in (0, 1))
    return view, light


def signature(bsdf, uv: np.ndarray) -> np.ndarray:
    """(c K, n) ``ln(1 + f cos)`` of the source at the n planar ``uv`` and the K
    :func:`signature_pairs`, the c values of pair k in rows ``c k .. c k + c - 1``: RGB, or in
    spectral variants the values at :data:`SIGNATURE_WAVELENGTHS`."""
    view, light = signature_pairs()
    k, n = view.shape[1], uv.shape[1]
    views, lights = np.repeat(view, n, axis=1), np.repeat(light, n, axis=1)
    values = eval_cos(bsdf, views, lights, wavelengths=SIGNATURE_WAVELENGTHS, uv=np.tile(uv, k))
    check_finite(values, views, lights, "values")
    values = np.log1p(np.maximum(values, 0.0))
    c = values.shape[0]
    return values.reshape(c, k, n).transpose(1, 0, 2).reshape(c * k, n)


def varying_textures(bsdf) -> list:
    """The textures ``bsdf`` reads that vary over the surface, each once, in load order."""
    hierarchy = mi.traverse(bsdf).hierarchy
    return [obj for obj in hierarchy if isinstance(obj, mi.Texture) and obj.is_spatially_varying()]


def texture_values(bsdf, uv: np.ndarray) -> np.ndarray:
    """(c T, n) values of the T :func:`varying_textures` at the n planar ``uv``: RGB, or in
    spectral variants the spectra at :data:`SIGNATURE_WAVELENGTHS`."""
    import drjit as dr

    rows = []
    for texture in varying_textures(bsdf):
        si = dr.zeros(mi.SurfaceInteraction3f, uv.shape[1])
        si.uv = mi.Point2f(np.ascontiguousarray(uv, dtype=np.float32))
        if mi.is_spectral:
            si.wavelengths = mi.UnpolarizedSpectrum(*SIGNATURE_WAVELENGTHS)
        rows.append(np.asarray(texture.eval(si).numpy(), dtype=np.float64).reshape(-1, uv.shape[1]))
    return np.concatenate(rows) if rows else np.zeros((0, uv.shape[1]))


#: How a texel is described (``--parameters``): the source's values at fixed direction pairs, or
#: the values of every texture it reads.
PARAMETERS = {"signature": signature, "textures": texture_values}


def parameter_image(bsdf, kind: str, width: int, height: int, progress=None) -> np.ndarray:
    """(texels, P) float32 parameters of every texel centre (:func:`texel_centres`), texel-major,
    without parameters that are the same at every texel or repeat an earlier one (the equal
    channels of a grey texture)."""
    describe = PARAMETERS[kind]
    texels = width * height
    image = None
    for start in range(0, texels, TEXEL_CHUNK):
        stop = min(start + TEXEL_CHUNK, texels)
        chunk = describe(bsdf, texel_centres(width, height, np.arange(start, stop)))
        if image is None:
            image = np.empty((texels, chunk.shape[0]), np.float32)
        image[start:stop] = chunk.T
        if progress is not None:
            progress(stop - start)
    kept, digests = [], {}
    for k in range(image.shape[1]):
        column = np.ascontiguousarray(image[:, k])
        digest = hashlib.blake2b(column).digest()
        same = digests.get(digest)
        if column.min() < column.max() and (same is None or not np.array_equal(image[:, same], column)):
            kept.append(k)
            digests.setdefault(digest, k)
    return image if len(kept) == image.shape[1] else image[:, kept]


# -- training samples ----------------------------------------------------------------------------


def stratified_texels(count: int, width: int, height: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` texel indices covering the texture evenly: every texel the same number of times
    (``count // texels``), and the rest at distinct texels, one in each of as many strata (blocks
    of whole texels of a grid of at least that many) drawn at random."""
    texels = width * height
    full, rest = divmod(count, texels)
    picks = [np.tile(np.arange(texels), full)]
    if rest:
        across = min(width, math.ceil(math.sqrt(rest * width / height)))
        down = min(height, -(-rest // across))
        strata = rng.choice(across * down, rest, replace=False)

        def texel_in(block, blocks, size):  # a random texel of block `block` of `blocks` along `size`
            low, high = block * size // blocks, (block + 1) * size // blocks
            return low + (rng.random(rest) * (high - low)).astype(np.int64)

        picks.append(texel_in(strata // across, down, height) * width + texel_in(strata % across, across, width))
    return np.concatenate(picks)


def training_samples(bsdf, native, args, size: tuple[int, int], anisotropic: bool, rng: np.random.Generator):
    """(texel of each sample, view, light, eval_cos): the trainer's direction pairs (covering the
    half vector's azimuth when ``anisotropic``), each at a texel of :func:`stratified_texels`
    (:data:`PAIRS_PER_TEXEL` pairs a texel, shuffled), and the source's values there: (3, n) RGB,
    or in spectral variants (m, n) at :data:`~nbrdf_mitsuba.distill.WAVELENGTHS`."""
    width, height = size
    config = native.default_config()
    config.samples = args.samples or DEFAULT_SAMPLES
    config.seed = args.seed or 0
    if args.sampling is not None:
        config.sampling = native.SAMPLINGS[args.sampling]
    try:
        native.for_anisotropy(config, anisotropic, scale_samples=False)
        view, light, _ = native.sample_directions(config)
    except native.TrainError as error:
        raise DistillError(str(error)) from None
    n = view.shape[1]
    visits = stratified_texels(-(-n // PAIRS_PER_TEXEL), width, height, rng)
    texel = rng.permutation(np.repeat(visits, PAIRS_PER_TEXEL)[:n])
    values = eval_cos(bsdf, view, light, uv=texel_centres(width, height, texel))
    check_finite(values, view, light, "values")
    return texel, view, light, values


# -- the command ---------------------------------------------------------------------------------


def textured_config(native, args):
    config = native.textured_default_config()
    set_options(config, (("channels", args.channels), ("epochs", args.epochs), ("batch", args.batch),
                         ("decoder_hidden", args.hidden), ("learning_rate", args.learning_rate),
                         ("seed", args.seed), ("threads", args.threads), ("lobes", args.lobes),
                         ("representatives", args.representatives)),
                {"decoder_hidden": "--hidden"})
    if not 1 <= config.channels <= 32:
        raise DistillError(f"--channels {config.channels}: expected 1 to 32 latent channels")
    if config.lobes > 2:
        raise DistillError(f"--lobes {config.lobes}: expected 0, 1 or 2")
    if not 1 <= config.representatives <= 256:
        raise DistillError(f"--representatives {config.representatives}: expected 1 to 256")
    if config.epochs < 1:
        raise DistillError("--epochs must be at least 1")
    return config


def unsupported_options(args) -> list[str]:
    """The homogeneous distill's options that --spatial does not take, as given."""
    given = [("--reciprocal", args.reciprocal), ("--target-loss", args.target_loss is not None)]
    return [name for name, on in given if on]


def distill_spatial(args, output: Path) -> dict:
    """Runs ``--spatial``; returns a summary (printed by :func:`main`)."""
    refused = unsupported_options(args)
    if refused:
        raise DistillError(f"{', '.join(refused)}: not available with --spatial")
    variant = pick_variant(args.variant)
    mi.set_variant(variant)
    source, kind = load_bsdf(args.source, args.bsdf)
    bsdf, notes = distilled_part(source)
    from .. import _train_native as native

    config = textured_config(native, args)
    width, height = texture_size(bsdf, args.resolution)
    parameters = args.parameters or "signature"
    anisotropic, anisotropy = decide_anisotropy(bsdf, args.anisotropy)
    config.anisotropic = int(anisotropic)
    start = time.perf_counter()
    bar = _bar(args.quiet, width * height, "texels", "evaluating")
    try:
        image = parameter_image(bsdf, parameters, width, height, progress=bar.update)
    finally:
        bar.close()
    if image.shape[1] == 0:
        raise DistillError(f"{args.source}: the BSDF is the same at every texel (a homogeneous material: no texture "
                           "it reads changes its values); distil it without --spatial, as a network: python -m "
                           f"nbrdf_mitsuba.distill {args.source} -o {network_name(output)}.nbrdf.json")
    rng = np.random.default_rng(args.seed or 0)
    texel, view, light, values = training_samples(bsdf, native, args, (width, height), anisotropic, rng)
    evaluation_seconds = time.perf_counter() - start
    details = {
        "renderer": f"Mitsuba {mi.__version__}", "variant": variant, "format": kind, "file": str(args.source),
        "bsdf": str(bsdf).splitlines()[0], "parameters": parameters, "texture_size": [width, height],
        "values": "BSDF.eval(si.uv = texel centre, si.wi = view, wo = light) = f_r cos(theta_light), local frame",
        "anisotropy": anisotropy, "notes": notes, "evaluation_seconds": round(evaluation_seconds, 3),
    }
    wavelengths = None
    if mi.is_spectral:
        wavelengths = WAVELENGTHS
        details["wavelengths_nm"] = [float(w) for w in WAVELENGTHS]
        details["signature_wavelengths_nm"] = list(SIGNATURE_WAVELENGTHS)
    epochs = _progress(args.quiet, config.epochs)
    baking = _bake_progress(args.quiet, epochs)
    try:
        native.train_textured(config, image[texel].T, view, light, values, image.reshape(height, width, -1), output,
                              name=args.name or network_name(output), source=f"Mitsuba BSDF {args.source}",
                              details=details, on_epoch=epochs.update, on_bake=baking.update, wavelengths=wavelengths)
    except native.TrainError as error:
        raise DistillFailed(str(error)) from None
    finally:
        epochs.close()
        baking.close()
    return {"output": output, "samples": view.shape[1], "parameters": image.shape[1], "size": (width, height),
            "channels": config.channels, "anisotropic": anisotropic, "spectral": wavelengths is not None,
            "variant": variant, "evaluation_seconds": evaluation_seconds, "seconds": time.perf_counter() - start,
            "notes": notes}


def report(summary: dict) -> str:
    """The lines :func:`main` prints after a spatial distillation."""
    width, height = summary["size"]
    kind = ("anisotropic" if summary["anisotropic"] else "isotropic") + (", spectral" if summary["spectral"] else "")
    lines = [f"wrote {summary['output']} (spatially varying, {kind}, {width} x {height} texels, "
             f"{summary['channels']} latent channels; texture beside it): {summary['samples']} samples of "
             f"{summary['parameters']} parameters a texel evaluated by Mitsuba ({summary['variant']}) in "
             f"{summary['evaluation_seconds']:.1f} s; {summary['seconds']:.1f} s in all"]
    return "\n".join(lines + [f"note: {note}" for note in summary["notes"]])


class _bar:
    """A tqdm bar when tqdm is installed, the output is a terminal and not ``quiet``."""

    def __init__(self, quiet: bool, total: int, unit: str, desc: str):
        self.bar = None
        if not quiet and sys.stderr.isatty():
            try:
                from tqdm import tqdm
            except ImportError:
                return
            self.bar = tqdm(total=total, unit=unit, desc=desc)

    def update(self, count: int) -> None:
        if self.bar is not None:
            self.bar.update(count)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


class _bake_progress:
    """The baking's stages as one tqdm bar over the lobe fits; ``training.close()`` (the epochs'
    bar) when the baking begins."""

    def __init__(self, quiet: bool, training):
        self.quiet, self.bar, self.training = quiet, None, training

    def update(self, stage: str, done: int, total: int) -> None:
        self.training.close()
        if stage != "fitting lobes":
            return
        if self.bar is None:
            self.bar = _bar(self.quiet, total, "lobe", "fitting lobes")
        self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
