"""Renders a Mitsuba 3 scene that uses the ``nbrdf``/``merl`` BSDFs: the ``mitsuba`` command,
with this package's plugins registered.

    python -m nbrdf_mitsuba render SCENE.xml [-o OUT.exr] [-D key=value ...] [-m VARIANT]
                                              [--spp N] [--seed S] [--passes P] [-t THREADS]

Mitsuba's own ``mitsuba`` executable cannot load Python plugins, hence this command. Its options
follow ``mitsuba``'s: ``-D key=value`` sets the scene parameter ``$key`` (it overrides the XML's
``<default name="key" .../>``; values are passed to ``mi.load_file`` as keyword arguments, so
relative file names resolve against the scene's folder first), ``-m``/``--variant`` picks the
variant (default ``llvm_ad_rgb`` when Dr.Jit's LLVM backend works, else ``scalar_rgb``), ``-o``
names the output (default: the scene's name with ``.exr``, beside it). Besides the EXR it writes a
PNG of the same name, clamped to [0, 1] and sRGB-encoded (Mitsuba's own conversion).

The ``--spp`` samples per pixel (default: the sensor's sampler) are drawn in ``--passes``
independently seeded passes, weighted by their sample counts, so that a progress bar can follow
a JIT render (one kernel launch per pass) as well as a scalar one. A user error (missing file,
malformed ``-D``, unknown variant, a scene Mitsuba rejects) is one line on stderr and exit
status 2; a render that fails, or images that cannot be written, exit status 1 (the policy of
``python -m nbrdf_mitsuba``).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from . import _exit

PROGRAM = "python -m nbrdf_mitsuba render"
DEFAULT_VARIANTS = ("llvm_ad_rgb", "scalar_rgb")
# Keyword arguments of mi.load_file itself: a scene parameter cannot be called so.
RESERVED_PARAMETERS = ("path", "parallel", "optimize")
_PARAMETER_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*$")


class UsageError(Exception):
    """A mistake of the user's (reported as one line, no traceback; exit status 2)."""


class RenderFailed(Exception):
    """The render, or the writing of its images, failed (one line; exit status 1)."""


def parse_defines(defines: list[str]) -> dict[str, str]:
    """``["key=value", ...]`` as a dict; the last of repeated keys wins, as in ``mitsuba``."""
    parameters = {}
    for define in defines:
        key, sep, value = define.partition("=")
        key = key.strip()
        if not sep or not key:
            raise UsageError(f"-D {define}: expected key=value")
        if not _PARAMETER_NAME.match(key):
            raise UsageError(f"-D {define}: '{key}' is not a parameter name (letters, digits, underscores)")
        if key in RESERVED_PARAMETERS:
            raise UsageError(f"-D {define}: '{key}' is reserved (a keyword of mi.load_file)")
        parameters[key] = value
    return parameters


def output_paths(scene: Path, output: str | None) -> tuple[Path, Path]:
    """(EXR, PNG) paths: ``-o`` with ``.exr`` added when it has no suffix, or the scene's name."""
    exr = Path(output) if output else scene.with_suffix(".exr")
    if exr.suffix == "":
        exr = exr.with_suffix(".exr")
    if exr.suffix.lower() != ".exr":
        raise UsageError(f"-o {output}: the output is an OpenEXR file (.exr); a PNG is written beside it")
    return exr, exr.with_suffix(".png")


def pass_sizes(spp: int, passes: int) -> list[int]:
    """``spp`` split into at most ``passes`` near-equal positive parts."""
    passes = max(1, min(passes, spp))
    base, extra = divmod(spp, passes)
    return [base + (1 if i < extra else 0) for i in range(passes)]


def default_variant(mi) -> str:
    from . import llvm

    available = mi.variants()
    if "llvm_ad_rgb" in available and llvm.problem() is None:
        return "llvm_ad_rgb"
    return "scalar_rgb"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROGRAM,
        description="Render a Mitsuba 3 scene with the nbrdf and merl BSDFs registered; writes OUT.exr "
                    "and a tone-mapped OUT.png (clamped, sRGB).")
    parser.add_argument("scene", help="scene description (Mitsuba 3 XML)")
    parser.add_argument("-o", "--output", help="output EXR (default: the scene's name with .exr, beside it)")
    parser.add_argument("-D", "--define", action="append", default=[], metavar="KEY=VALUE",
                        help="set the scene parameter $KEY (repeatable), as with `mitsuba -D`")
    parser.add_argument("-m", "--variant", "--mode", dest="variant",
                        help="Mitsuba variant (default: llvm_ad_rgb when Dr.Jit's LLVM backend works, "
                             "else scalar_rgb)")
    parser.add_argument("-s", "--sensor", type=int, default=0, help="index of the sensor to render (default 0)")
    parser.add_argument("--spp", type=int, help="samples per pixel (default: the sensor's sampler)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first pass (default 0)")
    parser.add_argument("--passes", type=int,
                        help="render in this many passes for the progress bar (default: 1 when the "
                             "scene has at most 4 spp, else 8)")
    parser.add_argument("-t", "--threads", type=int, help="CPU threads (default: all)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (for logs)")
    return parser


def _check_arguments(args) -> None:
    scene = Path(args.scene)
    if not scene.is_file():
        raise UsageError(f"scene file '{scene}' not found" if not scene.exists() else f"'{scene}' is not a file")
    for name in ("spp", "passes", "threads"):
        value = getattr(args, name)
        if value is not None and value < 1:
            raise UsageError(f"--{name} {value}: must be at least 1")
    if args.sensor < 0:
        raise UsageError(f"--sensor {args.sensor}: must be at least 0")
    if not 0 <= args.seed < 2**32:
        raise UsageError(f"--seed {args.seed}: must be in [0, 2^32)")


def _set_variant(mi, requested: str | None) -> str:
    import nbrdf_mitsuba

    variant = requested or default_variant(mi)
    if variant not in mi.variants():
        raise UsageError(f"variant '{variant}' is not available; this Mitsuba has: {', '.join(mi.variants())}")
    if variant.startswith("llvm_"):
        from . import llvm

        problem = llvm.problem()
        if problem:
            raise UsageError(f"variant '{variant}' needs Dr.Jit's LLVM backend: {problem}")
    try:
        mi.set_variant(variant)
    except Exception as error:  # e.g. a cuda_* variant without a GPU
        raise UsageError(f"cannot use variant '{variant}': {_one_line(error)}") from error
    nbrdf_mitsuba.register(variant)
    return variant


def _one_line(error: BaseException) -> str:
    """Mitsuba's message on one line, without its '[file.cpp:line]' prefix and without the Python
    traceback it embeds when a Python plugin's constructor raised (the exception line stays)."""
    kept, in_traceback = [], False
    for line in str(error).splitlines():
        head, marker, _ = line.partition("Traceback (most recent call last):")
        if marker:
            kept.append(head)
            in_traceback = True
        elif in_traceback and line[:1].isspace():
            continue  # a frame of the embedded traceback
        else:
            in_traceback = False
            kept.append(line)
    text = " ".join(" ".join(kept).split())
    return re.sub(r"^\[[\w.]+:\d+\]\s*", "", text) or type(error).__name__


def _render(mi, scene, sensor, sizes: list[int], seed: int, progress: bool):
    """Mean of the passes' images weighted by their spp, and the film's developed bitmap of the
    last pass (for the channel layout)."""
    import drjit as dr
    import numpy as np
    from tqdm import tqdm

    total = None
    with tqdm(total=sum(sizes), unit="spp", disable=not progress, desc="rendering", file=sys.stderr) as bar:
        for index, spp in enumerate(sizes):
            image = mi.render(scene, sensor=sensor, spp=spp, seed=seed * len(sizes) + index)
            dr.eval(image)
            values = np.array(image, dtype=np.float64) * spp
            total = values if total is None else total + values
            bar.update(spp)
    return (total / sum(sizes)).astype(np.float32), sensor.film().bitmap()


def write_outputs(mi, image, reference, exr: Path, png: Path) -> None:
    """Writes the EXR (the film's channels) and the PNG (its RGB part, clamped, sRGB)."""
    names = [field.name for field in reference.struct_()]
    bitmap = mi.Bitmap(image, pixel_format=reference.pixel_format(), channel_names=names)
    exr.parent.mkdir(parents=True, exist_ok=True)
    bitmap.write(str(exr))
    formats = mi.Bitmap.PixelFormat
    colour = bitmap if bitmap.pixel_format() in (formats.RGB, formats.RGBA, formats.Y, formats.YA) \
        else bitmap.split()[0][1]
    colour.convert(formats.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(str(png))


def run(args) -> tuple[Path, Path]:
    _check_arguments(args)
    parameters = parse_defines(args.define)
    scene_path = Path(args.scene)
    exr, png = output_paths(scene_path, args.output)

    import nbrdf_mitsuba  # noqa: F401  (before mitsuba: picks Dr.Jit's libLLVM)
    import mitsuba as mi

    variant = _set_variant(mi, args.variant)
    if args.threads:
        import drjit as dr

        dr.set_thread_count(args.threads)
    try:
        scene = mi.load_file(str(scene_path), **parameters)
    except Exception as error:
        raise UsageError(f"cannot load '{scene_path}': {_one_line(error)}") from error
    sensors = scene.sensors()
    if args.sensor >= len(sensors):
        raise UsageError(f"--sensor {args.sensor}: the scene has {len(sensors)} sensor(s)")
    sensor = sensors[args.sensor]
    spp = args.spp or sensor.sampler().sample_count()
    passes = args.passes or (1 if spp <= 4 else 8)
    sizes = pass_sizes(spp, passes)
    size = sensor.film().size()
    print(f"{PROGRAM}: {scene_path} ({variant}, {size[0]}x{size[1]}, {spp} spp in {len(sizes)} pass(es))",
          file=sys.stderr)
    try:
        image, reference = _render(mi, scene, sensor, sizes, args.seed, not args.no_progress)
    except Exception as error:
        # A BSDF or integrator that fails mid-render reports through Mitsuba as a RuntimeError.
        raise RenderFailed(f"rendering '{scene_path}' failed: {_one_line(error)}") from error
    try:
        write_outputs(mi, image, reference, exr, png)
    except Exception as error:
        raise RenderFailed(f"cannot write '{exr}': {_one_line(error)}") from error
    print(f"{PROGRAM}: wrote {exr} and {png}", file=sys.stderr)
    return exr, png


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        run(args)
    except UsageError as error:
        print(f"{PROGRAM}: error: {error}", file=sys.stderr)
        return _exit.USAGE
    except RenderFailed as error:
        print(f"{PROGRAM}: error: {error}", file=sys.stderr)
        return _exit.FAILED
    except KeyboardInterrupt:
        print(f"{PROGRAM}: interrupted", file=sys.stderr)
        return 130
    return _exit.SUCCESS


if __name__ == "__main__":
    sys.exit(main())
