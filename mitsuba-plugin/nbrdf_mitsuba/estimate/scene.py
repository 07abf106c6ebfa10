"""The scene file, its ``-D`` parameters, the Mitsuba variant and the reference images."""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import mitsuba as mi
import numpy as np

from .. import _llvm
from .errors import EstimateError


def parse_defines(items: list[str]) -> dict:
    defines = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise EstimateError(f"-D {item}: expected key=value")
        defines[key] = value
    return defines


def check_paths(scene: Path, output: Path) -> None:
    """The scene file and the output's folder, checked before the variant and anything else."""
    if not scene.is_file():
        raise EstimateError(f"{scene}: no such file")
    if output.is_dir():
        raise EstimateError(f"-o {output}: is a directory; name the result's file, e.g. {output / 'out.json'}")
    if not output.parent.is_dir():
        raise EstimateError(f"-o {output}: cannot write there (the folder {output.parent} does not exist)")


def require_differentiable_variant(variant: str | None) -> str:
    """``variant`` or llvm_ad_rgb; an error where the variant cannot differentiate."""
    variant = variant or "llvm_ad_rgb"
    if variant not in mi.variants():
        raise EstimateError(f"Mitsuba variant '{variant}' is not available (these are: {', '.join(mi.variants())})")
    if "_ad_" not in variant or not variant.endswith("_rgb"):
        raise EstimateError(f"variant '{variant}' is not differentiable: the estimate needs an *_ad_rgb variant "
                            "(e.g. llvm_ad_rgb)")
    if variant.startswith("llvm") and _llvm.problem() is not None:
        raise EstimateError(f"variant {variant} cannot run: {_llvm.problem()}")
    mi.set_variant(variant)
    return variant


def _resolver():
    return mi.file_resolver() if hasattr(mi, "file_resolver") else mi.Thread.thread().file_resolver()


def _mitsuba_message(error: Exception) -> str:
    lines = str(error).strip().splitlines()
    return lines[-1] if lines else type(error).__name__


class Scene:
    """The scene XML with the BSDF ``bsdf_id`` replaceable by another element."""

    def __init__(self, path: Path, bsdf_id: str, defines: dict):
        if not path.is_file():
            raise EstimateError(f"{path}: no such file")
        self.path, self.bsdf_id, self.defines = path, bsdf_id, defines
        try:
            self.tree = ET.parse(path)
        except ET.ParseError as error:
            raise EstimateError(f"{path}: not XML: {error}") from None
        self.element = next((e for e in self.tree.iter("bsdf") if e.get("id") == bsdf_id), None)
        _resolver().prepend(str(path.resolve().parent))
        if self.element is None:
            ids = sorted({e.get("id") for e in self.tree.iter("bsdf") if e.get("id")})
            raise EstimateError(f"{path}: no BSDF with id '{bsdf_id}' (BSDF ids there: {', '.join(ids) or 'none'})")

    def load(self, replacement: ET.Element | None = None):
        """The scene, the marked BSDF replaced by ``replacement`` (its id kept)."""
        element = self.element
        parent = next(p for p in self.tree.iter() if element in list(p))
        index = list(parent).index(element)
        if replacement is not None:
            replacement.set("id", self.bsdf_id)
            parent[index] = replacement
        try:
            text = ET.tostring(self.tree.getroot(), encoding="unicode")
            return mi.load_string(text, **self.defines)
        except Exception as error:  # Mitsuba reports malformed scenes as plain exceptions
            raise EstimateError(f"{self.path}: Mitsuba cannot load it: {_mitsuba_message(error)}") from None
        finally:
            parent[index] = element


def bsdf_key_prefix(params, bsdf_id: str) -> str:
    """The prefix of the BSDF ``bsdf_id``'s parameters in ``params`` (``mi.traverse`` of the
    scene), found by the object, not by its name: ``mi.traverse`` names a BSDF by its path in
    the scene graph, which is its id only where the BSDF is declared at the top of the scene (a
    BSDF nested in its shape or in a ``twosided`` is ``<shape>.bsdf`` or ``<shape>.bsdf.brdf_0``).
    The BSDF is the traversed object with that id; its own traversal's keys, matched to the
    scene's by the object that holds each parameter, give the prefix."""
    # SceneParameters keeps, per key, the object holding it (properties) and every traversed
    # object (hierarchy): the only link from an object to its keys.
    bsdf = next((node for node in params.hierarchy if isinstance(node, mi.BSDF) and node.id() == bsdf_id), None)
    if bsdf is None:
        raise EstimateError(f"the scene holds no BSDF with id '{bsdf_id}' once loaded: is it used by a shape?")
    for key, (_, _, node, _) in mi.traverse(bsdf).properties.items():
        for scene_key, (_, _, scene_node, _) in params.properties.items():
            if scene_node is node and scene_key.endswith("." + key):
                return scene_key[:-len(key) - 1]
    raise EstimateError(f"BSDF '{bsdf_id}' has no parameters in the loaded scene")

def load_images(paths: list[Path], scene) -> list:
    """The reference images as ``mi.TensorXf`` (h, w, 3), checked against the scene's sensors."""
    sensors = scene.sensors()
    if len(paths) != len(sensors):
        raise EstimateError(f"{len(paths)} images for {len(sensors)} sensors: give one image per sensor, "
                            "in the scene's order")
    images = []
    for i, (path, sensor) in enumerate(zip(paths, sensors)):
        if not path.is_file():
            raise EstimateError(f"image {i} {path}: no such file")
        try:
            bitmap = mi.Bitmap(str(path)).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
        except Exception as error:
            raise EstimateError(f"image {i} {path}: cannot read it: {_mitsuba_message(error)}") from None
        array = np.array(bitmap, dtype=np.float32)
        width, height = (int(v) for v in sensor.film().crop_size())
        if array.shape[:2] != (height, width):
            raise EstimateError(f"image {i} {path} is {array.shape[1]}x{array.shape[0]}, sensor {i} renders "
                                f"{width}x{height}")
        bad = ~np.isfinite(array)
        if bad.any():
            y, x, _ = np.argwhere(bad)[0]
            raise EstimateError(f"image {i} {path}: {int(bad.any(axis=2).sum())} pixels are NaN or infinite "
                                f"(the first at x={x}, y={y})")
        if (array < 0).any():
            # Renders of measured BSDFs can hold slightly negative values: radiance is never negative.
            print(f"warning: image {i} {path}: {int((array < 0).any(axis=2).sum())} pixels are negative, "
                  "taken as 0", file=sys.stderr)
            array = np.maximum(array, 0.0)
        images.append(mi.TensorXf(array))
    return images
