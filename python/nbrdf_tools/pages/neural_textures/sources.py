"""The textured sources the neural-textures page distils, split once into a tuning set (on which
the distillation's defaults may be chosen) and a test set (reported, never tuned on).

Every source is a Mitsuba BSDF dict built from real texture images and measurements of the
shared data (``../shared``: the kitchen's textures, CC BY 3.0, and the RGL measurements); maps
the sources need beyond the images (a blend's mask, a roughness map) are derived from those
images by :func:`derived_map` and written into the work folder.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nbrdf_tools.common.paths import require_shared

TUNING, TEST = "tuning", "test"


@dataclass(frozen=True)
class Source:
    """A textured source: ``kind`` (``principled``, ``blend``, ``kitchen``, ``conductor``), the
    images it reads (shared paths), how it is built (:func:`bsdf`) and, for a blend, the
    measurements it blends (the per-material route's inputs)."""

    name: str
    subset: str
    kind: str
    image: str
    measurements: tuple[str, ...] = ()
    options: dict = field(default_factory=dict)


SOURCES = (
    Source("principled-chopping-board", TUNING, "principled", "Chopping-Board.jpg",
           options={"roughness": (0.3, 0.7)}),
    Source("blend-paper-napoli", TUNING, "blend", "Tea-Towel.jpg",
           measurements=("paper_white_rgb", "colodur_napoli_4f_rgb")),
    Source("kitchen-tabletop", TEST, "kitchen", "Tabletop-light.jpg", options={"bsdf_id": "TabletopBSDF"}),
    Source("blend-ibiza-iris", TEST, "blend", "wood.jpg",
           measurements=("cc_ibiza_sunset_rgb", "cc_iris_purple_gem_rgb")),
    Source("principled-wood", TEST, "principled", "wood.jpg", options={"roughness": (0.25, 0.6)}),
    Source("conductor-cushion", TEST, "conductor", "cushion-bump.jpg", options={"roughness": (0.08, 0.4)}),
)


def texture_path(image: str) -> Path:
    return require_shared("scenes", "kitchen", "textures", image, what="the kitchen scene's textures")


def measurement_path(name: str) -> Path:
    return require_shared("data", "rgl", f"{name}.bsdf", what="the RGL measurements")


def luminance(image: str) -> np.ndarray:
    """The image's linear luminance in [0, 1], (H, W)."""
    import mitsuba as mi

    bitmap = mi.Bitmap(str(texture_path(image))).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32,
                                                          srgb_gamma=False)
    rgb = np.array(bitmap, dtype=np.float64)
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


#: Pixels per side of the blocks a mask's image is averaged over before thresholding.
MASK_BLOCK = 8


def derived_map(image: str, low: float, high: float, work: Path, name: str, threshold: bool = False) -> Path:
    """A single-channel EXR from ``image``'s luminance: remapped to [low, high] by its own 2nd and
    98th percentiles (a roughness map), or thresholded at its median (a blend's mask, 0 or 1 but
    for a one-texel smooth edge from bilinear filtering) after averaging blocks of
    :data:`MASK_BLOCK` pixels, so that the mask keeps the image's shapes rather than its grain."""
    import mitsuba as mi

    value = luminance(image)
    if threshold:
        h, w = (n // MASK_BLOCK * MASK_BLOCK for n in value.shape)
        value = value[:h, :w].reshape(h // MASK_BLOCK, MASK_BLOCK, w // MASK_BLOCK, MASK_BLOCK).mean(axis=(1, 3))
    lo, hi = np.percentile(value, [2, 98])
    t = np.clip((value - lo) / max(hi - lo, 1e-6), 0.0, 1.0)
    if threshold:
        t = (value > np.median(value)).astype(np.float64)
    out = work / f"{name}.exr"
    out.parent.mkdir(parents=True, exist_ok=True)
    mi.Bitmap((low + (high - low) * t)[..., None].astype(np.float32)).write(str(out))
    return out


def _bitmap(path: Path, raw: bool) -> dict:
    return {"type": "bitmap", "filename": str(path), "raw": raw, "filter_type": "bilinear"}


def bsdf(source: Source, work: Path) -> dict:
    """The source's BSDF dict (absolute file names, so it loads from anywhere)."""
    if source.kind == "principled":
        roughness = derived_map(source.image, *source.options["roughness"], work, f"{source.name}-roughness")
        return {"type": "principled", "base_color": _bitmap(texture_path(source.image), False),
                "roughness": _bitmap(roughness, True), "specular": 0.5}
    if source.kind == "conductor":
        alpha = derived_map(source.image, *source.options["roughness"], work, f"{source.name}-alpha")
        return {"type": "roughconductor", "material": "Cu", "distribution": "ggx", "alpha": _bitmap(alpha, True)}
    if source.kind == "blend":
        mask = derived_map(source.image, 0.0, 1.0, work, f"{source.name}-mask", threshold=True)
        first, second = (measurement_path(m) for m in source.measurements)
        return {"type": "blendbsdf", "weight": _bitmap(mask, True),
                "bsdf_0": {"type": "measured", "filename": str(first)},
                "bsdf_1": {"type": "measured", "filename": str(second)}}
    if source.kind == "kitchen":
        return kitchen_bsdf(source.options["bsdf_id"])
    raise ValueError(f"unknown kind of source '{source.kind}'")


def kitchen_bsdf(bsdf_id: str) -> dict:
    """The kitchen's BSDF ``bsdf_id`` as a dict, the ``twosided`` wrapper dropped (a distilled
    network reflects on the front; the kitchen wraps it again) and texture paths made absolute."""
    import xml.etree.ElementTree as ET

    from nbrdf_tools.common.scenes.kitchen import kitchen_path

    path = kitchen_path()
    root = ET.parse(path).getroot()
    element = next((e for e in root.iter("bsdf") if e.get("id") == bsdf_id), None)
    if element is None:
        raise KeyError(f"no BSDF '{bsdf_id}' in {path}")
    if element.get("type") == "twosided":
        element = element.find("bsdf")
    return _element_dict(element, path.parent)


def _element_dict(element, folder: Path) -> dict:
    """A Mitsuba XML ``bsdf``/``texture`` element as a ``load_dict`` dict (the value tags the
    kitchen uses: float, string, boolean, rgb, texture)."""
    result = {"type": element.get("type")}
    for child in element:
        name, value = child.get("name"), child.get("value")
        if child.tag == "float":
            result[name] = float(value)
        elif child.tag == "boolean":
            result[name] = value == "true"
        elif child.tag == "rgb":
            result[name] = {"type": "rgb", "value": [float(v) for v in value.replace(",", " ").split()]}
        elif child.tag == "string":
            result[name] = str(folder / value) if name == "filename" else value
        elif child.tag in ("texture", "bsdf"):
            result[name] = _element_dict(child, folder)
    return result


def select(subset: str, names: list[str] | None = None) -> list[Source]:
    """The sources of ``subset`` (``tuning``, ``test`` or ``all``), or those named."""
    chosen = [s for s in SOURCES if subset == "all" or s.subset == subset]
    if names:
        unknown = sorted(set(names) - {s.name for s in SOURCES})
        if unknown:
            raise SystemExit(f"neural-textures: unknown source(s) {', '.join(unknown)}; "
                             f"known: {', '.join(s.name for s in SOURCES)}")
        chosen = [s for s in SOURCES if s.name in names]
    return chosen
