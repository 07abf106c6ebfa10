"""Compare two materials the way ``nbrdf compare`` does, through Mitsuba, so that any BSDF
Mitsuba can evaluate takes part: a MERL-format table (``*.binary``, the ``merl`` BSDF), a neural
BRDF (``*.nbrdf.json``, the ``nbrdf`` BSDF) or an RGL measurement (``*.bsdf``, Mitsuba's own
``measured`` BSDF, the ground truth of real measured materials).

    python -m nbrdf_tools compare A B [--resolution 128] [--samples 100000] [--json]

The first material is the reference. The images and directions are the Rust tool's
(``nbrdf compare``), reproduced here pixel for pixel; the image metrics are those of
:mod:`nbrdf_tools.common.metrics` (names say which definition):

* a unit sphere seen orthographically from +z, ``resolution`` x ``resolution`` pixels (pixel
  centres, float32 geometry), lit by one directional light of unit irradiance from
  ``(sin t, 0, cos t)`` for each ``t`` in 0, 30, 45, 60, 75 degrees; a pixel's radiance is
  ``f_r(l, v) cos(theta_l)``, i.e. the BSDF's ``eval`` in the local frame of the sphere (no Monte
  Carlo: deterministic and noise-free); the background is black;
* ``mae``, ``rmse``, ``relmse`` and ``psnr_peak_ref`` (``20 log10(max(reference) / rmse)``, the
  Rust tool's PSNR) over all pixels and channels of the linear images; ``ssim`` (scikit-image,
  Wang et al.'s settings) of the tone-mapped ``min(max(x, 1e-12)^(1/2.2), 1)`` images, averaged
  over the RGB channels (the Rust tool's own SSIM differs at the image border: it truncates and
  renormalises the window where scikit-image leaves the border out); ``flip_hdr`` (NVIDIA's
  HDR-FLIP) of the linear images; the means over the five lights;
* the log-space BRDF error ``|ln(1 + f_A cos) - ln(1 + f_B cos)|`` averaged over the channels and
  over ``samples`` light/view pairs drawn adaptively (uniform in theta_h, theta_d, phi_d) and
  uniformly (over the hemisphere), from the same counter-based SplitMix64 stream as the Rust tool,
  so the directions are the same ones.

Import :func:`compare` (or :func:`render_spheres`, :func:`image_errors`) from other scripts.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import nbrdf_mitsuba  # noqa: F401  (before mitsuba: points Dr.Jit at a usable libLLVM)
import drjit as dr
import mitsuba as mi
import numpy as np

from nbrdf_tools.common import metrics

LIGHT_THETAS_DEG = (0.0, 30.0, 45.0, 60.0, 75.0)
DEFAULT_RESOLUTION = 128
DEFAULT_SAMPLES = 100_000
VARIANT = "llvm_ad_rgb"

KINDS = {".binary": "merl", ".json": "nbrdf", ".bsdf": "measured"}


def kind_of(path: str | Path) -> str:
    """The Mitsuba plugin that reads ``path``: merl (.binary), nbrdf (.nbrdf.json), measured (.bsdf)."""
    suffix = Path(path).suffix.lower()
    if suffix not in KINDS:
        raise ValueError(f"{path}: unknown material file type '{suffix}' "
                         "(expected .binary, .nbrdf.json or an RGL .bsdf)")
    return KINDS[suffix]


def set_variant() -> None:
    if mi.variant() != VARIANT:
        mi.set_variant(VARIANT)
    # The traced backend of nbrdf/merl runs in Dr.Jit's default (symbolic) mode; a rust-backed
    # BSDF made elsewhere in the process may have switched it off, which is fine too.


def load_bsdf(path: str | Path):
    """The Mitsuba BSDF of a material file (llvm_ad_rgb variant)."""
    set_variant()
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    return mi.load_dict({"type": kind_of(path), "filename": str(path)})


def eval_cos(bsdf, view: np.ndarray, light: np.ndarray) -> np.ndarray:
    """``f_r(light, view) cos(theta_light)`` (3, n) float64 of local directions (3, n): the
    BSDF's ``eval`` with ``si.wi = view`` and ``wo = light``; non-finite and negative -> 0."""
    n = view.shape[1]
    if n == 0:
        return np.zeros((3, 0))
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(np.ascontiguousarray(view, dtype=np.float32))
    value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(np.ascontiguousarray(light, dtype=np.float32)))
    out = np.array(value, dtype=np.float64).reshape(3, n)
    out[~np.isfinite(out)] = 0.0
    return np.maximum(out, 0.0)


# --------------------------------------------------------------------------------------------
# Sphere images (metrics::render_sphere)


def _orthonormal_pair(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """glam's ``Vec3::any_orthonormal_pair`` (Duff et al. 2017) in float32, rows (3, n)."""
    x, y, z = n
    sign = np.where(z >= 0, np.float32(1), np.float32(-1))  # f32::signum (no zeros or NaN here)
    a = np.float32(-1) / (sign + z)
    b = x * y * a
    t = np.stack([np.float32(1) + sign * x * x * a, sign * b, -sign * x])
    bt = np.stack([b, sign + y * y * a, -y])
    return t, bt


def sphere_geometry(size: int, light_theta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel mask (size*size,) and local view and light directions (3, k) of the lit disk, for
    the light ``(sin t, 0, cos t)`` (float32 throughout, like the Rust renderer)."""
    f = np.float32
    coords = (f(2) * (np.arange(size, dtype=f) + f(0.5)) / f(size)) - f(1)
    x = np.tile(coords, size)  # pixel (px, py) is row-major index py * size + px
    y = (f(1) - (f(2) * (np.repeat(np.arange(size, dtype=f), size) + f(0.5)) / f(size))).astype(f)
    r2 = x * x + y * y
    mask = r2 < f(1)
    x, y, r2 = x[mask], y[mask], r2[mask]
    normal = np.stack([x, y, np.sqrt(f(1) - r2)])
    t, b = _orthonormal_pair(normal)
    light_world = np.array([math.sin(light_theta), 0.0, math.cos(light_theta)], dtype=f)
    view = np.stack([t[2], b[2], normal[2]])  # the world view direction is +z
    light = np.stack([light_world @ t, light_world @ b, light_world @ normal]).astype(f)
    return mask, view.astype(f), light


def turn_about_normal(d: np.ndarray, angle) -> np.ndarray:
    """Local directions (3, n) turned by ``angle`` (radians; a scalar or one per direction) about
    the normal: what turning the tangent frame by ``-angle`` does to them."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]]).astype(d.dtype)


def render_spheres(bsdf, size: int = DEFAULT_RESOLUTION, light_thetas_deg=LIGHT_THETAS_DEG,
                   frame_turn_deg: float = 0.0) -> np.ndarray:
    """Linear RGB images (lights, 3, size, size) float32 of the sphere under each light.
    ``frame_turn_deg`` turns every pixel's tangent frame about its normal (an isotropic BSDF
    renders the same; an anisotropic one's highlight turns)."""
    geometry = [sphere_geometry(size, math.radians(deg)) for deg in light_thetas_deg]
    if frame_turn_deg:
        angle = -math.radians(frame_turn_deg)
        geometry = [(mask, turn_about_normal(v, angle), turn_about_normal(light, angle))
                    for mask, v, light in geometry]
    view = np.concatenate([g[1] for g in geometry], axis=1)
    light = np.concatenate([g[2] for g in geometry], axis=1)
    values = eval_cos(bsdf, view, light).astype(np.float32)
    images = np.zeros((len(geometry), 3, size * size), dtype=np.float32)
    start = 0
    for i, (mask, v, _) in enumerate(geometry):
        count = v.shape[1]
        images[i][:, mask] = values[:, start:start + count]
        start += count
    return images.reshape(len(geometry), 3, size, size)


# --------------------------------------------------------------------------------------------
# Image metrics (metrics::image_errors, metrics::ssim)


@dataclass
class ImageErrors:
    mae: float
    rmse: float
    relmse: float
    psnr_peak_ref: float
    ssim: float
    flip_hdr: float


def image_errors(reference: np.ndarray, test: np.ndarray) -> ImageErrors:
    """Errors of ``test`` against ``reference``, both (3, size, size) linear RGB."""
    r = np.moveaxis(reference.astype(np.float64), 0, -1)
    t = np.moveaxis(test.astype(np.float64), 0, -1)
    return ImageErrors(mae=metrics.mae(r, t), rmse=metrics.rmse(r, t), relmse=metrics.relmse(r, t),
                       psnr_peak_ref=metrics.psnr_peak_ref(r, t), ssim=metrics.ssim(r, t),
                       flip_hdr=metrics.flip_hdr(r, t))


# --------------------------------------------------------------------------------------------
# Log-space error (metrics::log_error), on the Rust tool's random stream

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_METRICS_STREAM = 6
# The azimuths of log_error(turned=True) (analytic_fit's fitting directions use 11 and 12).
_TURN_STREAM = 13


def _mix64(z: np.ndarray) -> np.ndarray:
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def splitmix_uniforms(seed: int, stream: int, first: int, count: int) -> np.ndarray:
    """(count, 4) uniforms of candidates ``first ..`` as ``SplitMix64::new(seed, stream, 4 k)``
    followed by four ``next_f64`` draws gives them in the Rust code."""
    with np.errstate(over="ignore"):
        base = _mix64(np.array([seed], dtype=np.uint64) ^ _mix64(np.array([stream + 1], dtype=np.uint64)))[0]
        k = np.arange(first, first + count, dtype=np.uint64)
        j = np.arange(1, 5, dtype=np.uint64)
        state = base + (np.uint64(4) * k[:, None] + j[None, :]) * _GAMMA
        bits = _mix64(state) >> np.uint64(11)
    return bits.astype(np.float64) * (1.0 / (1 << 53))


def sample_directions(sampling: str, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Light and view (3, n) float64 of ``dataset::directions``."""
    if sampling == "adaptive":
        th, td, pd = u[:, 0] * (math.pi / 2), u[:, 1] * (math.pi / 2), u[:, 2] * 2 * math.pi
        d = np.stack([np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)])
        ch, sh = np.cos(th), np.sin(th)
        light = np.stack([ch * d[0] + sh * d[2], d[1], -sh * d[0] + ch * d[2]])
        half = np.stack([sh, np.zeros_like(sh), ch])
        view = 2.0 * np.sum(light * half, axis=0) * half - light
        return light, view
    if sampling == "uniform":
        def hemisphere(uc, up):
            s = np.sqrt(np.maximum(1.0 - uc * uc, 0.0))
            return np.stack([s * np.cos(2 * math.pi * up), s * np.sin(2 * math.pi * up), uc])
        return hemisphere(u[:, 0], u[:, 1]), hemisphere(u[:, 2], u[:, 3])
    raise ValueError(f"unknown sampling '{sampling}' (adaptive or uniform)")


def log_error(a, b, sampling: str, samples: int = DEFAULT_SAMPLES, seed: int = 0, turned: bool = False) -> float:
    """Mean ``|ln(1 + f_a cos) - ln(1 + f_b cos)|`` over ``samples`` light/view pairs above the
    horizon and the three channels (BSDFs ``a`` and ``b``). ``turned`` turns each pair about the
    normal by its own uniform angle (on a stream of its own): adaptive pairs all have their half
    vector in the xz plane (``phi_h = 0``), which shows nothing of an anisotropic BSDF."""
    lights, views, kept, first = [], [], 0, 0
    while kept < samples:
        count = max(2 * (samples - kept), 1024)
        light, view = sample_directions(sampling, splitmix_uniforms(seed, _METRICS_STREAM, first, count))
        first += count
        # The Rust tool tests the float64 directions; the BSDFs get float32 ones.
        keep = (light[2] > 0) & (view[2] > 0) & (light.astype(np.float32)[2] > 0) & (view.astype(np.float32)[2] > 0)
        lights.append(light[:, keep])
        views.append(view[:, keep])
        kept += int(keep.sum())
    light = np.concatenate(lights, axis=1)[:, :samples]
    view = np.concatenate(views, axis=1)[:, :samples]
    if turned:
        angle = 2 * math.pi * splitmix_uniforms(seed, _TURN_STREAM, 0, light.shape[1])[:, 0]
        light, view = turn_about_normal(light, angle), turn_about_normal(view, angle)
    fa, fb = eval_cos(a, view, light), eval_cos(b, view, light)
    return float(np.mean(np.abs(np.log1p(fa) - np.log1p(fb))))


# --------------------------------------------------------------------------------------------
# The comparison


@dataclass
class Comparison:
    resolution: int
    per_light: list  # [(degrees, ImageErrors)]
    mean: ImageErrors
    log_error_adaptive: float
    log_error_uniform: float

    def to_json(self) -> dict:
        """The layout of ``nbrdf compare --json``'s "comparison", with the metric names of
        :class:`ImageErrors` (an infinite PSNR is null)."""
        def errors(e: ImageErrors) -> dict:
            return {k: (v if math.isfinite(v) else None) for k, v in asdict(e).items()}
        return {
            "resolution": self.resolution,
            "per_light": [[deg, errors(e)] for deg, e in self.per_light],
            "mean": errors(self.mean),
            "log_error_adaptive": self.log_error_adaptive,
            "log_error_uniform": self.log_error_uniform,
        }


def _as_bsdf(material):
    return load_bsdf(material) if isinstance(material, (str, Path)) else material


def compare(reference, test, resolution: int = DEFAULT_RESOLUTION, samples: int = DEFAULT_SAMPLES,
            reference_images: np.ndarray | None = None) -> Comparison:
    """Compares ``test`` against ``reference`` (paths or Mitsuba BSDFs). ``reference_images``
    (from :func:`render_spheres`) saves re-rendering a reference used many times."""
    if resolution < 1 or samples < 1:
        raise ValueError("resolution and samples must be at least 1")
    ref, tst = _as_bsdf(reference), _as_bsdf(test)
    ref_images = render_spheres(ref, resolution) if reference_images is None else reference_images
    test_images = render_spheres(tst, resolution)
    per_light = [(deg, image_errors(ref_images[i], test_images[i])) for i, deg in enumerate(LIGHT_THETAS_DEG)]
    n = len(per_light)
    mean = ImageErrors(**{f.name: sum(getattr(e, f.name) for _, e in per_light) / n for f in fields(ImageErrors)})
    return Comparison(
        resolution=resolution,
        per_light=per_light,
        mean=mean,
        log_error_adaptive=log_error(ref, tst, "adaptive", samples),
        log_error_uniform=log_error(ref, tst, "uniform", samples),
    )


def _e(x: float, width: int = 0) -> str:
    """Rust's ``{:.4e}``: no zero padding or plus sign in the exponent."""
    mantissa, _, exponent = f"{x:.4e}".partition("e")
    text = f"{mantissa}e{int(exponent)}" if exponent else mantissa
    return f"{text:>{width}}"


def format_text(reference: str, test: str, c: Comparison) -> str:
    """The text report (``nbrdf compare``'s, with relMSE and HDR-FLIP; PSNR_ref: peak = max(reference))."""
    lines = [f"{reference} vs {test} (reference first), {c.resolution}x{c.resolution} spheres:",
             f"  {'theta_l':>9}{'MAE':>12}{'RMSE':>12}{'relMSE':>12}{'PSNR_ref':>9}{'SSIM':>8}{'FLIP':>8}"]

    def row(label, e):
        return (f"  {label:>9}{_e(e.mae, 12)}{_e(e.rmse, 12)}{_e(e.relmse, 12)}{e.psnr_peak_ref:>9.2f}"
                f"{e.ssim:>8.4f}{e.flip_hdr:>8.4f}")

    lines += [row(f"{deg:.0f} deg", e) for deg, e in c.per_light]
    lines.append(row("mean", c.mean))
    lines.append("log-space BRDF error |ln(1+fA cos) - ln(1+fB cos)|: "
                 f"adaptive {_e(c.log_error_adaptive)}, uniform {_e(c.log_error_uniform)}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m nbrdf_tools compare",
        description="Compare two materials (MERL table .binary, NBRDF .nbrdf.json or RGL measurement "
                    ".bsdf) on rendered spheres under five light elevations (MAE, RMSE, relMSE, PSNR with "
                    "peak max(reference), SSIM, HDR-FLIP) and in log space, as `nbrdf compare` does. The first "
                    "is the reference.")
    parser.add_argument("reference", type=Path, metavar="A", help="the reference material")
    parser.add_argument("test", type=Path, metavar="B", help="the material compared against A")
    parser.add_argument("--resolution", type=int, default=DEFAULT_RESOLUTION,
                        help="width and height of the sphere images, pixels (default %(default)s)")
    parser.add_argument("--samples", type=int, default=DEFAULT_SAMPLES,
                        help="directions for the log-space error, each of adaptive and uniform "
                             "sampling (default %(default)s)")
    parser.add_argument("--json", action="store_true", help="print the comparison as JSON")
    args = parser.parse_args(argv)
    try:
        for path in (args.reference, args.test):
            kind_of(path)
            if not path.is_file():
                raise FileNotFoundError(f"{path}: no such file")
        c = compare(args.reference, args.test, args.resolution, args.samples)
    except (ValueError, OSError, RuntimeError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps({"reference": str(args.reference), "test": str(args.test),
                          "comparison": c.to_json()}, indent=2))
    else:
        sys.stdout.write(format_text(str(args.reference), str(args.test), c))
    return 0


if __name__ == "__main__":
    sys.exit(main())
