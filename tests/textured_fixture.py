"""Small spatially varying materials for the tests, and their float64 NumPy oracle.

:func:`write_textured` writes a material as docs/formats.md ("Spatially varying materials")
describes it: the JSON file (format version 4) and its OpenEXR latent texture (channels
``latent.0 .. latent.{C-1}`` and the lobe channels, float16 or float32, written by Mitsuba's
``Bitmap``). The oracle (:func:`lookup`, :func:`eval_oracle`, :func:`pdf_oracle`) is written
from that page and docs/textured.md in float64, without calling the Rust code: the texture read
as Mitsuba's ``bitmap`` reads an image (``to_uv``, wrap mode, bilinear or nearest filtering,
the position rounded to float32 once), the decoder through ``nbrdf_tools.common.network`` (the
one NumPy copy of the network's input and forward pass), and the lobes' Blinn-Phong mixture.
The twins it holds to account are listed in docs/design.md, "Twins".
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import mitsuba as mi
import numpy as np

from nbrdf_tools.common import network

#: The lobe channels of a texture with 0, 1 or 2 lobes, in texture order (docs/formats.md).
LOBE_CHANNELS = {0: [], 1: ["lobe.n", "lobe.w"], 2: ["lobe.n1", "lobe.w1", "lobe.n2", "lobe.w2"]}
#: The largest Blinn-Phong exponent and how far filtered lobe values may pass their range
#: (docs/textured.md, "Sampling with an exact pdf").
MAX_EXPONENT = 1e6
FILTER_SLACK = 1e-5


@dataclass
class Textured:
    """A written material: its files and what they hold (the texture as stored, float32)."""

    path: Path
    exr: Path
    layers: list
    texture: np.ndarray  # (height, width, C + 2 lobes)
    channels: int
    lobes: int
    wrap: str = "repeat"
    filter: str = "bilinear"
    to_uv: np.ndarray = field(default_factory=lambda: np.eye(3))
    anisotropic: bool = False
    spectral: dict | None = None  # the file's "spectral" object: the decoder gives its coefficients

    @property
    def width(self) -> int:
        return self.texture.shape[1]

    @property
    def height(self) -> int:
        return self.texture.shape[0]

    def channel_names(self) -> list[str]:
        return [f"latent.{k}" for k in range(self.channels)] + LOBE_CHANNELS[self.lobes]


def random_decoder(channels: int, hidden: int = 12, seed: int = 0, anisotropic: bool = False,
                   outputs: int = 3) -> list:
    """float32 layers ``6 + C -> hidden -> hidden -> outputs`` (3, RGB, or a spectral basis'
    count) of a smooth decoder whose last layer is positive, so that ``f_r > 0`` everywhere
    (Mitsuba's chi^2 adapter counts zero-weight samples as failures)."""
    rng = np.random.default_rng(seed)
    shapes = [(6 + channels, hidden), (hidden, hidden)]
    layers = [(rng.uniform(-0.6, 0.6, s).astype(np.float32), rng.uniform(-0.1, 0.1, s[1]).astype(np.float32))
              for s in shapes]
    bias = np.full(outputs, 0.3, np.float32) if outputs == 3 else rng.uniform(0.1, 0.5, outputs).astype(np.float32)
    layers.append((rng.uniform(0.0, 0.3, (hidden, outputs)).astype(np.float32), bias))
    return layers


def encode_exponent(n) -> np.ndarray:
    """The stored code of a Blinn-Phong exponent, ``ln(1 + n)`` (docs/formats.md)."""
    return np.log1p(np.clip(np.asarray(n, np.float64), 0.0, MAX_EXPONENT))


def random_texture(width: int, height: int, channels: int, lobes: int = 1, seed: int = 0) -> np.ndarray:
    """float32 (height, width, C + 2 lobes): latent codes in [-1, 1], lobe exponents in
    [5, 300] (encoded) and weights that sum to at most 0.9."""
    rng = np.random.default_rng(seed)
    latent = rng.uniform(-1.0, 1.0, (height, width, channels))
    parts = [latent]
    weights = {1: [(0.2, 0.8)], 2: [(0.2, 0.5), (0.1, 0.4)]}.get(lobes, [])
    for low, high in weights:
        parts.append(encode_exponent(rng.uniform(5.0, 300.0, (height, width, 1))))
        parts.append(rng.uniform(low, high, (height, width, 1)))
    return np.concatenate(parts, axis=2).astype(np.float32)


def write_exr(path: Path, texture: np.ndarray, names: list[str], precision: str = "float16") -> np.ndarray:
    """Writes ``texture`` (height, width, channels) as a one-part OpenEXR file with these channel
    names; returns the values as stored, in float32."""
    dtype = {"float16": np.float16, "float32": np.float32}[precision]
    stored = np.ascontiguousarray(texture, dtype=dtype)
    bitmap = mi.Bitmap(stored, pixel_format=mi.Bitmap.PixelFormat.MultiChannel, channel_names=list(names))
    bitmap.write(str(path))
    return stored.astype(np.float32)


def write_textured(path: Path, layers=None, texture: np.ndarray | None = None, channels: int = 3, lobes: int = 1,
                   wrap: str | None = None, filter: str | None = None, to_uv=None, precision: str = "float16",
                   anisotropic: bool = False, name: str = "fixture", document: dict | None = None,
                   exr_names: list[str] | None = None, spectral: dict | None = None) -> Textured:
    """Writes ``path`` (``*.nbrdf.json``, version 4) and its texture ``<stem>.latent.exr`` beside
    it. Defaults: a random decoder and a random 5 x 4 texture of ``channels`` latent channels and
    ``lobes`` lobes. ``spectral``: the file's ``spectral`` object (a spectral material, whose
    random decoder gives its ``count`` coefficients). ``document`` entries replace the JSON's (to
    write broken files), ``exr_names`` the texture's channel names."""
    path = Path(path)
    outputs = 3 if spectral is None else spectral["count"]
    layers = random_decoder(channels, anisotropic=anisotropic, outputs=outputs) if layers is None else layers
    texture = random_texture(5, 4, channels, lobes) if texture is None else np.asarray(texture)
    material = Textured(path, path.with_name(path.name.replace(".nbrdf.json", "") + ".latent.exr"), layers,
                        texture, channels, lobes, wrap or "repeat", filter or "bilinear",
                        np.eye(3) if to_uv is None else np.asarray(to_uv, np.float64), anisotropic, spectral)
    material.texture = write_exr(material.exr, texture, exr_names or material.channel_names(), precision)
    latent = {"path": material.exr.name, "width": material.width, "height": material.height, "channels": channels}
    if wrap is not None:
        latent["wrap"] = wrap
    if filter is not None:
        latent["filter"] = filter
    if to_uv is not None:
        latent["to_uv"] = [[float(x) for x in row] for row in material.to_uv]
    out = {
        "format": "nbrdf", "version": 4, "name": name, "anisotropic": anisotropic,
        "layers": [{"inputs": int(w.shape[0]), "outputs": int(w.shape[1]),
                    "weights": [float(v) for v in np.asarray(w, np.float32).ravel()],
                    "bias": [float(v) for v in np.asarray(b, np.float32)]} for w, b in layers],
        "latent": latent,
        "provenance": {"source": "nbrdf tests"},
    }
    if spectral is not None:
        out["spectral"] = spectral
    if lobes:
        names = LOBE_CHANNELS[lobes]
        out["sampling"] = {"model": "blinn-phong", "exponent_encoding": "log1p",
                           "lobes": [{"exponent": names[2 * k], "weight": names[2 * k + 1]} for k in range(lobes)]}
    out.update(document or {})
    path.write_text(json.dumps(out))
    return material


# ---------------------------------------------------------------------------------------------
# The oracle (float64)


def _wrap(index: np.ndarray, size: int, mode: str) -> np.ndarray:
    """Texel indices (integers in float64) brought into ``[0, size)`` by the wrap mode."""
    if mode == "clamp":
        return np.clip(index, 0, size - 1).astype(np.int64)
    if mode == "repeat":
        return np.mod(index, size).astype(np.int64)
    m = np.mod(index, 2 * size)
    return np.where(m < size, m, 2 * size - 1 - m).astype(np.int64)


def _axis(coord: np.ndarray, size: int, material: Textured):
    """Per lane: the two texel indices along one axis, their weights, and whether the position
    is finite. The position ``coord size - 1/2`` (bilinear) or ``coord size`` (nearest) is
    rounded to float32 once."""
    offset = -0.5 if material.filter == "bilinear" else 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        position = (coord * size + offset).astype(np.float32).astype(np.float64)
    finite = np.isfinite(position)
    position = np.where(finite, position, 0.0)
    base = np.floor(position)
    w1 = position - base
    return (_wrap(base, size, material.wrap), _wrap(base + 1, size, material.wrap)), (1 - w1, w1), finite


def lookup(material: Textured, uv: np.ndarray):
    """``(values (n, channels), mapped (n,))``: every channel filtered at the planar hits ``uv``
    (2, n), and whether the mapped coordinate's position is finite (where it is not, the hit
    reads no texel). A non-finite value in the footprint (zero weights included) makes the
    filtered channel non-finite."""
    uv = np.asarray(uv, np.float32).astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        mapped = material.to_uv[:2, :2] @ uv + material.to_uv[:2, 2:3]
        mapped = mapped.astype(np.float32).astype(np.float64)
    (x0, x1), (wx0, wx1), fx = _axis(mapped[0], material.width, material)
    (y0, y1), (wy0, wy1), fy = _axis(mapped[1], material.height, material)
    tex = material.texture.astype(np.float64)
    if material.filter == "nearest":
        corners = [(x0, y0, np.ones_like(wx0))]
    else:
        corners = [(x0, y0, wx0 * wy0), (x1, y0, wx1 * wy0), (x0, y1, wx0 * wy1), (x1, y1, wx1 * wy1)]
    values = np.zeros((uv.shape[1], tex.shape[2]))
    with np.errstate(invalid="ignore"):
        for x, y, w in corners:
            values += tex[y, x] * w[:, None]
    return values, fx & fy


def eval_oracle(material: Textured, uv, view, light) -> np.ndarray:
    """``f_r cos(theta_l)`` (3, n) at planar ``uv`` (2, n), ``view`` and ``light`` (3, n): 0 at
    bad texels (a non-finite position or latent value), at or below the horizon. A spectral
    material's (count, n): its coefficients times ``cos(theta_l)``."""
    values, mapped = lookup(material, uv)
    code = values[:, :material.channels]
    good = mapped & np.all(np.isfinite(code), axis=1)
    view, light = np.asarray(view, np.float64), np.asarray(light, np.float64)
    features = network.network_input(view.T, light.T, material.anisotropic)
    inputs = np.concatenate([features, np.where(good[:, None], code, 0.0)], axis=1)
    f = network.forward([(np.asarray(w, np.float64), np.asarray(b, np.float64)) for w, b in material.layers],
                        inputs).T
    v = view / np.linalg.norm(view, axis=0)
    l = light / np.linalg.norm(light, axis=0)
    above = (v[2] > 0) & (l[2] > 0)
    return np.where(above & good, f * l[2], 0.0)


def lobe_parameters(material: Textured, uv) -> np.ndarray:
    """(n, 4) Blinn-Phong mixture ``[n1, w1, n2, w2]`` at each hit from the filtered lobe
    channels (the latent ones do not enter): the exponent decoded from ``ln(1 + n)``, values
    within :data:`FILTER_SLACK` of their range clamped into it, two weights summing just over 1
    scaled to 1; the cosine lobe (all zeros) without lobes, at bad UVs and where a value is out
    of range or not finite."""
    values, mapped = lookup(material, uv)
    lobes = values[:, material.channels:]
    out = np.zeros((values.shape[0], 4))
    if material.lobes == 0:
        return out

    def within(x, low, high):
        slack = FILTER_SLACK * (high - low)
        with np.errstate(invalid="ignore"):
            return (x >= low - slack) & (x <= high + slack), np.clip(np.nan_to_num(x), low, high)

    params, good = [], mapped.copy()
    for k in range(material.lobes):
        code_ok, code = within(lobes[:, 2 * k], 0.0, np.log1p(MAX_EXPONENT))
        weight_ok, weight = within(lobes[:, 2 * k + 1], 0.0, 1.0)
        good &= code_ok & weight_ok
        params.append((np.minimum(np.expm1(code), MAX_EXPONENT), weight))
    if material.lobes == 2:
        total = params[0][1] + params[1][1]
        sum_ok, clamped = within(total, 0.0, 1.0)
        good &= sum_ok
        scale = np.where(total > 1, clamped / np.where(total > 0, total, 1.0), 1.0)
        params = [(e, w * scale) for e, w in params]
    for k, (exponent, weight) in enumerate(params):
        out[:, 2 * k] = np.where(good, exponent, 0.0)
        out[:, 2 * k + 1] = np.where(good, weight, 0.0)
    return out


def lobe_density(view: np.ndarray, light: np.ndarray, exponent: np.ndarray) -> np.ndarray:
    """The Blinn-Phong lobe's density per unit solid angle of ``light`` (docs/design.md section 6):
    ``(n + 1) / (2 pi) cos^n(theta_h) / (4 v.h)``."""
    v, l = view / np.linalg.norm(view, axis=0), light / np.linalg.norm(light, axis=0)
    h = v + l
    h = h / np.linalg.norm(h, axis=0)
    cos_h = np.clip(h[2], 0.0, 1.0)
    return (exponent + 1) / (2 * np.pi) * cos_h ** exponent / (4 * np.abs(np.sum(v * h, axis=0)))


def pdf_oracle(material: Textured, uv, view, light) -> np.ndarray:
    """The sampling density at each hit: ``w1 lobe(n1) + w2 lobe(n2) + (1 - w1 - w2) cos / pi``,
    0 unless both directions are above the horizon."""
    view, light = np.asarray(view, np.float64), np.asarray(light, np.float64)
    n1, w1, n2, w2 = lobe_parameters(material, uv).T
    l = light / np.linalg.norm(light, axis=0)
    v = view / np.linalg.norm(view, axis=0)
    pdf = w1 * lobe_density(view, light, n1) + w2 * lobe_density(view, light, n2) + (1 - w1 - w2) * l[2] / np.pi
    return np.where((l[2] > 0) & (v[2] > 0), pdf, 0.0)


# ---------------------------------------------------------------------------------------------
# A chi^2 goodness-of-fit test of sampled directions against a density (for scalar variants,
# where Mitsuba's mitsuba.chi2 cannot run: it works on Dr.Jit arrays)


def chi2_pvalue(light: np.ndarray, valid: np.ndarray, density, z_bins: int = 8, phi_bins: int = 16,
                refine: int = 24) -> float:
    """The p-value of the hypothesis that the sampled directions ``light`` (3, n) with
    ``valid`` (n,) (false: an invalid sample, pdf 0) come from ``density(light (3, m)) -> pdf
    (m,)`` (per unit solid angle, on the upper hemisphere). Bins are equal in ``cos theta`` and
    ``phi`` (equal solid angle), each bin's probability integrated by the midpoint rule on a
    ``refine x refine`` grid; invalid samples fall in one more bin, whose probability is what
    the density leaves off the hemisphere. Bins expected to hold fewer than 5 samples are pooled,
    as Mitsuba's ChiSquareTest does."""
    from scipy import stats

    n = light.shape[1]
    l = light[:, valid] / np.linalg.norm(light[:, valid], axis=0)
    z_index = np.clip((l[2] * z_bins).astype(int), 0, z_bins - 1)
    phi_index = np.clip(((np.arctan2(l[1], l[0]) + np.pi) / (2 * np.pi) * phi_bins).astype(int), 0, phi_bins - 1)
    observed = np.bincount(z_index * phi_bins + phi_index, minlength=z_bins * phi_bins).astype(float)
    t = (np.arange(refine) + 0.5) / refine
    z = ((np.arange(z_bins)[:, None] + t[None]) / z_bins).ravel()
    phi = ((np.arange(phi_bins)[:, None] + t[None]) / phi_bins * 2 * np.pi - np.pi).ravel()
    Z, P = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(np.maximum(1 - Z**2, 0))
    pdf = density(np.stack([s * np.cos(P), s * np.sin(P), Z]).reshape(3, -1)).reshape(Z.shape)
    cell = (1.0 / (z_bins * refine)) * (2 * np.pi / (phi_bins * refine))
    mass = (pdf * cell).reshape(z_bins, refine, phi_bins, refine).sum(axis=(1, 3)).ravel()
    observed = np.append(observed, n - valid.sum())
    expected = np.append(mass, max(1.0 - mass.sum(), 0.0)) * n
    order = np.argsort(expected)
    small = np.cumsum(expected[order]) < 5
    pooled_observed = np.append(observed[order][~small], observed[order][small].sum())
    pooled_expected = np.append(expected[order][~small], expected[order][small].sum())
    keep = pooled_expected > 0
    if np.any(pooled_observed[~keep] > 0):
        return 0.0  # samples where the density says there are none
    statistic = np.sum((pooled_observed[keep] - pooled_expected[keep]) ** 2 / pooled_expected[keep])
    return float(stats.chi2.sf(statistic, keep.sum() - 1))


def render(path: Path, seed: int = 0, spp: int = 4, size: int = 8, **bsdf) -> np.ndarray:
    """A small render of a sphere (its UVs cover the texture) with the material at ``path``
    under a constant environment, in the current variant. The box filter keeps each sample in
    its pixel, so that a scalar variant's threads cannot change the order of a pixel's sums."""
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 1, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "light": {"type": "constant"},
        "sphere": {"type": "sphere", "bsdf": {"type": "nbrdf", "filename": str(path), **bsdf}},
    })
    return np.asarray(mi.render(scene, seed=seed), dtype=np.float64)
