"""The Veach multiple-importance-sampling scene (DESIGN.md section 10) as a Mitsuba 3 dict.

Four glossy plates under four sphere lights of equal power and growing radius, a diffuse floor
and back wall, and a fill light. The plates take the materials under test: any Mitsuba BSDF dict
(``nbrdf``, ``merl``, ``measured`` or a built-in), so one geometry serves the ground truth, our
NBRDFs and Mitsuba's own BSDFs alike.
"""

from __future__ import annotations

import mitsuba as mi

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


def _rectangle(centre, half_u, half_v) -> mi.ScalarTransform4f:
    """Maps Mitsuba's [-1, 1]^2 rectangle (normal +z) onto centre + s half_u + t half_v; the
    normal becomes half_u x half_v, so the argument order picks the side that faces up."""
    hu = mi.ScalarVector3f(half_u)
    hv = mi.ScalarVector3f(half_v)
    n = mi.ScalarVector3f(
        hu[1] * hv[2] - hu[2] * hv[1], hu[2] * hv[0] - hu[0] * hv[2], hu[0] * hv[1] - hu[1] * hv[0]
    )
    n_len = (n[0] ** 2 + n[1] ** 2 + n[2] ** 2) ** 0.5
    n = n / n_len
    return mi.ScalarTransform4f(
        [
            [hu[0], hv[0], n[0], centre[0]],
            [hu[1], hv[1], n[1], centre[1]],
            [hu[2], hv[2], n[2], centre[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def plate_transform(index: int) -> mi.ScalarTransform4f:
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
            "to_world": mi.ScalarTransform4f().look_at(
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
