"""The Veach multiple-importance-sampling scene (docs/design.md section 10) as a Mitsuba 3 dict.

Four glossy plates under four sphere lights of equal power and growing radius, a diffuse floor
and back wall, and a fill light. The plates take the materials under test: any Mitsuba BSDF dict
(``nbrdf``, ``merl``, ``measured`` or a built-in), so one geometry serves the ground truth, our
NBRDFs and Mitsuba's own BSDFs alike.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import mitsuba as mi
import numpy as np

from nbrdf_tools.common.paths import SCENES
from nbrdf_tools.common.render import pixel_rays, write_bsdf_file

VEACH_XML = SCENES / "veach_mis.xml"
PLATE_IDS = ("plate1", "plate2", "plate3", "plate4")

# (y, z) of the two long edges of each plate; the plates span x = -4 .. 4.
PLATE_EDGES = (
    ((-2.70651, 0.25609), (-2.08375, -0.526323)),
    ((-3.28825, 1.36972), (-2.83856, 0.476536)),
    ((-3.73096, 2.70046), (-3.43378, 1.74564)),
    ((-3.99615, 4.0667), (-3.82069, 3.08221)),
)
# (centre, radius, radiance) of the lights above the plates, then the fill light.
SPHERE_LIGHTS = (
    ((-3.75, 0.0, 0.0), 0.03333, 901.803),
    ((-1.25, 0.0, 0.0), 0.1, 100.0),
    ((1.25, 0.0, 0.0), 0.3, 11.1111),
    ((3.75, 0.0, 0.0), 0.9, 1.23457),
    ((10.0, 10.0, 4.0), 0.5, 800.0),
)
FLOOR_Y = -4.14615
BACK_WALL_Z = -2.0
FULL_RESOLUTION = (768, 512)


def _rectangle(centre, half_u, half_v) -> mi.ScalarTransform4d:
    """Maps Mitsuba's [-1, 1]^2 rectangle (normal +z) onto centre + s half_u + t half_v; the
    normal becomes half_u x half_v, so the argument order picks the side that faces up.

    Computed in double precision, like Mitsuba's XML parser does with the same numbers, so that
    ``scenes/veach_mis.xml`` (which holds these matrices) gives a bit-identical scene."""
    hu = np.asarray(half_u, dtype=np.float64)
    hv = np.asarray(half_v, dtype=np.float64)
    n = np.cross(hu, hv)
    n = n / np.sqrt(np.sum(n * n))
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = hu, hv, n, centre
    return mi.ScalarTransform4d(matrix)


def plate_transform(index: int) -> mi.ScalarTransform4d:
    (y0, z0), (y1, z1) = PLATE_EDGES[index]
    centre = (0.0, 0.5 * (y0 + y1), 0.5 * (z0 + z1))
    return _rectangle(centre, (4.0, 0.0, 0.0), (0.0, 0.5 * (y1 - y0), 0.5 * (z1 - z0)))


def integrator_dict(kind: str, max_depth: int = 2) -> dict:
    """``bsdf`` = pure BSDF sampling (``direct``, ``emitter_samples = 0``), ``mis`` = Mitsuba's
    direct integrator with both strategies combined, ``path`` = a path tracer."""
    if kind == "bsdf":
        return {"type": "direct", "emitter_samples": 0, "bsdf_samples": 1}
    if kind == "mis":
        return {"type": "direct", "emitter_samples": 1, "bsdf_samples": 1}
    if kind == "path":
        return {"type": "path", "max_depth": max_depth}
    raise ValueError(f"unknown integrator kind '{kind}' (bsdf, mis or path)")


def veach_scene_dict(
    plates: list[dict] | dict,
    integrator: str = "mis",
    resolution: tuple[int, int] = FULL_RESOLUTION,
    spp: int = 16,
    seed: int = 0,
) -> dict:
    """The scene dict; ``plates`` is one BSDF dict for all four plates or a list of four."""
    if isinstance(plates, dict):
        plates = [plates] * 4
    if len(plates) != 4:
        raise ValueError(f"the Veach scene has 4 plates, got {len(plates)} materials")
    diffuse = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.4, 0.4, 0.4]}}
    scene = {
        "type": "scene",
        "integrator": integrator_dict(integrator),
        "sensor": {
            "type": "perspective",
            "fov": 28.0,
            "fov_axis": "smaller",
            "to_world": mi.ScalarTransform4d().look_at(
                origin=[0.0, 2.0, 15.0], target=[0.0, -2.0, 2.5], up=[0.0, 1.0, 0.0]
            ),
            "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
            "film": {
                "type": "hdrfilm",
                "width": resolution[0],
                "height": resolution[1],
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
        },
        "floor": {
            "type": "rectangle",
            "to_world": _rectangle((0.0, FLOOR_Y, 0.0), (10.0, 0.0, 0.0), (0.0, 0.0, -10.0)),
            "bsdf": diffuse,
        },
        "back_wall": {
            "type": "rectangle",
            "to_world": _rectangle((0.0, 0.0, BACK_WALL_Z), (10.0, 0.0, 0.0), (0.0, 10.0, 0.0)),
            "bsdf": diffuse,
        },
    }
    for i, material in enumerate(plates):
        scene[f"plate{i + 1}"] = {"type": "rectangle", "to_world": plate_transform(i), "bsdf": material}
    for i, (centre, radius, radiance) in enumerate(SPHERE_LIGHTS):
        scene[f"light{i + 1}"] = {
            "type": "sphere",
            "center": list(centre),
            "radius": radius,
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}},
        }
    return scene


def emitter_samples(integrator: str) -> int:
    """The ``emitter_samples`` parameter of ``scenes/veach_mis.xml`` for ``bsdf`` or ``mis``."""
    if integrator not in ("bsdf", "mis"):
        raise ValueError(f"scenes/veach_mis.xml has the integrators bsdf and mis, not '{integrator}'")
    return integrator_dict(integrator)["emitter_samples"]


def load_veach_xml(
    plates: list[dict] | dict,
    integrator: str = "mis",
    resolution: tuple[int, int] = FULL_RESOLUTION,
    spp: int = 16,
    seed: int = 0,
    xml: Path = VEACH_XML,
):
    """Loads ``scenes/veach_mis.xml`` with the given plate BSDF dicts (written as temporary plate
    files and passed as the ``plate1`` .. ``plate4`` parameters): the XML twin of
    ``mi.load_dict(veach_scene_dict(...))``."""
    if isinstance(plates, dict):
        plates = [plates] * 4
    if len(plates) != 4:
        raise ValueError(f"the Veach scene has 4 plates, got {len(plates)} materials")
    with tempfile.TemporaryDirectory(prefix="veach-plates-") as folder:
        files = {pid: str(write_bsdf_file(p, Path(folder) / f"{pid}.xml")) for pid, p in zip(PLATE_IDS, plates)}
        return mi.load_file(
            str(xml), **files, emitter_samples=str(emitter_samples(integrator)), spp=str(spp),
            seed=str(seed), resx=str(resolution[0]), resy=str(resolution[1]),
        )


def plate_mask(scene) -> np.ndarray:
    """(H, W) bool: the pixel centre's camera ray hits one of the four plates first.

    Found geometrically (the hit point lies on a plate rectangle), since Mitsuba merges
    rectangles that share a BSDF into one unnamed mesh. JIT variants."""
    ray, shape = pixel_rays(scene)
    si = scene.ray_intersect(ray)
    points = np.array(si.p, dtype=np.float64).reshape(3, -1).T
    valid = np.array(si.is_valid(), dtype=bool).reshape(-1)
    mask = np.zeros(points.shape[0], dtype=bool)
    for i in range(len(PLATE_EDGES)):
        inverse = np.linalg.inv(np.array(plate_transform(i).matrix, dtype=np.float64))
        local = points @ inverse[:3, :3].T + inverse[:3, 3]
        on_plate = (np.abs(local[:, 0]) <= 1 + 1e-4) & (np.abs(local[:, 1]) <= 1 + 1e-4) & (np.abs(local[:, 2]) < 1e-3)
        mask |= on_plate
    return (mask & valid).reshape(shape)
