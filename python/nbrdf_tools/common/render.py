"""Rendering for the scripts: BSDF dicts as Mitsuba XML, the one render loop (single, timed and
averaged renders), masks of the pixels that see given shapes, and EXR/PNG input/output.

Import ``nbrdf_mitsuba`` before this module (it points Dr.Jit at a usable libLLVM).
"""

from __future__ import annotations

import time
from pathlib import Path
from xml.sax.saxutils import quoteattr

import drjit as dr
import mitsuba as mi
import numpy as np
from nbrdf_tools.common.progress import bar

# ---------------------------------------------------------------------------------------------
# BSDF dicts as XML


def _xml_value(name: str, value, indent: str) -> str:
    key = quoteattr(name)
    if isinstance(value, bool):
        return f'{indent}<boolean name={key} value="{str(value).lower()}"/>'
    if isinstance(value, int):
        return f"{indent}<integer name={key} value=\"{value}\"/>"
    if isinstance(value, float):
        return f"{indent}<float name={key} value=\"{value!r}\"/>"
    if isinstance(value, (str, Path)):
        return f"{indent}<string name={key} value={quoteattr(str(value))}/>"
    if isinstance(value, dict) and value.get("type") == "rgb":
        rgb = value["value"]
        rgb = [rgb] * 3 if isinstance(rgb, (int, float)) else list(rgb)
        return f"{indent}<rgb name={key} value=\"{', '.join(repr(float(c)) for c in rgb)}\"/>"
    if isinstance(value, dict) and "type" in value:
        tag = "bsdf" if name.startswith("bsdf") or name in ("nested", "material") else "texture"
        return bsdf_xml(value, tag=tag, name=name, indent=indent)
    raise TypeError(f"cannot write parameter {name!r} = {value!r} as Mitsuba XML")


def bsdf_xml(bsdf: dict, tag: str = "bsdf", name: str | None = None, bsdf_id: str | None = None,
             indent: str = "", version: bool = False) -> str:
    """The Mitsuba XML element of a BSDF dict (as given to ``mi.load_dict``).

    Values: str/Path -> ``string``, float -> ``float``, int -> ``integer``, bool -> ``boolean``,
    ``{"type": "rgb", "value": ...}`` -> ``rgb``, nested dicts with a ``type`` -> nested
    ``bsdf`` (keys starting with ``bsdf``) or ``texture`` elements.
    """
    attributes = f" type={quoteattr(bsdf['type'])}"
    if version:
        attributes = ' version="3.0.0"' + attributes
    if name is not None:
        attributes += f" name={quoteattr(name)}"
    if bsdf_id is not None:
        attributes += f" id={quoteattr(bsdf_id)}"
    children = [_xml_value(k, v, indent + "    ") for k, v in bsdf.items() if k not in ("type", "id")]
    if not children:
        return f"{indent}<{tag}{attributes}/>"
    return "\n".join([f"{indent}<{tag}{attributes}>", *children, f"{indent}</{tag}>"])


def write_bsdf_file(bsdf: dict, path: Path) -> Path:
    """Writes a BSDF dict as a stand-alone XML file (e.g. a Veach plate, ``<include>``-able)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(bsdf_xml(bsdf, version=True) + "\n")
    return path


# ---------------------------------------------------------------------------------------------
# Renders


def sync() -> None:
    if dr.is_jit_v(mi.Float):
        dr.sync_thread()


def render(scene, spp: int, seed: int = 0) -> np.ndarray:
    """One render as a float64 (H, W, 3) array; waits for the kernels to finish."""
    image = mi.render(scene, spp=spp, seed=seed)
    dr.eval(image)
    sync()
    return np.array(image, dtype=np.float64)[..., :3]


def timed_render(scene, spp: int, seed: int = 0) -> tuple[np.ndarray, float]:
    """(image, wall-clock seconds) of one render (compile the kernels beforehand to time only
    the rendering: see :func:`warm_up`)."""
    start = time.perf_counter()
    image = render(scene, spp, seed)
    return image, time.perf_counter() - start


def warm_up(scene, spp: int = 1) -> float:
    """Renders once (compiling and caching the kernels); returns the seconds it took."""
    return timed_render(scene, spp, seed=2**31 - 1)[1]


def render_passes(scene, spp: int, spp_per_pass: int = 64, seed: int = 0, desc: str | None = None,
                  progress: bool = True, leave: bool = False) -> np.ndarray:
    """Average of independent renders (seeds ``seed``, ``seed + 1``, ...) totalling ``spp``
    samples per pixel: bounded memory for high sample counts, with a progress bar."""
    passes = max(1, -(-spp // spp_per_pass))
    total = None
    weight = 0
    done = 0
    for k in bar(range(passes), desc=desc, unit="pass", disable=not progress, leave=leave):
        n = min(spp_per_pass, spp - done)
        image = render(scene, n, seed=seed + k)
        total = image * n if total is None else total + image * n
        weight += n
        done += n
    return total / weight


# ---------------------------------------------------------------------------------------------
# Masks


def pixel_rays(scene, resolution: tuple[int, int] | None = None):
    """Camera rays through the pixel centres of the scene's first sensor (row-major)."""
    sensor = scene.sensors()[0]
    width, height = resolution or tuple(sensor.film().crop_size())
    xs, ys = np.meshgrid((np.arange(width) + 0.5) / width, (np.arange(height) + 0.5) / height)
    ray, _ = sensor.sample_ray(0.0, 0.0, mi.Point2f(xs.ravel(), ys.ravel()), mi.Point2f(0.5, 0.5))
    return ray, (height, width)


def _pointer(value) -> np.ndarray:
    return np.array(dr.reinterpret_array(mi.UInt32, value)).astype(np.int64)


def primary_hit_mask(scene, shape_ids=None, bsdf_ids=None) -> np.ndarray:
    """(H, W) bool: the pixel centre sees a shape whose id is in ``shape_ids`` or whose BSDF's id
    is in ``bsdf_ids`` (JIT variants)."""
    shape_ids = set(shape_ids or ())
    bsdf_ids = set(bsdf_ids or ())
    ray, shape = pixel_rays(scene)
    si = scene.ray_intersect(ray)
    wanted_shapes, wanted_bsdfs = [], []
    for s in scene.shapes():
        if s.id() in shape_ids:
            wanted_shapes.append(int(_pointer(mi.ShapePtr(s))[0]))
        if s.bsdf() is not None and s.bsdf().id() in bsdf_ids:
            wanted_bsdfs.append(int(_pointer(mi.BSDFPtr(s.bsdf()))[0]))
    valid = np.array(si.is_valid(), dtype=bool)
    hit = np.isin(_pointer(si.shape), wanted_shapes) | np.isin(_pointer(si.bsdf(ray)), wanted_bsdfs)
    return (hit & valid).reshape(shape)


# ---------------------------------------------------------------------------------------------
# Images


def write_exr(path: Path, image: np.ndarray) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32)).write(str(path))
    return path


def read_exr(path: Path) -> np.ndarray:
    return np.array(mi.Bitmap(str(path)), dtype=np.float64)[..., :3]


def write_png(path: Path, image: np.ndarray) -> Path:
    """sRGB-tonemapped PNG (clipped) of a linear image."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mi.util.write_bitmap(str(path), np.ascontiguousarray(image, dtype=np.float32))
    return path
