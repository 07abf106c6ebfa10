"""What the neural-textures page measures for one source: the conversion, renders of the source
and its neural texture on a sphere and a plane (views and lights no training saw: distillation
never renders), their errors against a reference render of the source, rays per second against
the source and ``roughconductor``, memory, and the pdf's chi2 at several texels."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from nbrdf_tools.common import metrics
from nbrdf_tools.common.render import render_passes, sync, timed_render, warm_up

#: The rays of one sample of the ``direct`` integrator with one emitter and one BSDF sample: the
#: camera ray, the shadow ray and the BSDF ray (as bench-rays counts them).
RAYS_PER_SAMPLE = 3
#: The kitchen's reference render has this many times the samples of the compared renders, so
#: that its own noise adds little to theirs (its noise floor row shows what is left).
REFERENCE_SPP_FACTOR = 4
#: Texels (u, v) and view angles (radians from the normal) of the chi2 tests.
CHI2_TEXELS = ((0.2, 0.3), (0.55, 0.5), (0.8, 0.85))
CHI2_THETAS = (0.3, 1.1)
#: Integration points per cell side of the chi2 test's expected counts: Mitsuba's default (4)
#: misintegrates lobes as narrow as a kitchen table top's (its pdf sums to a few percent over 1).
CHI2_IRES = 16
ROUGHCONDUCTOR = {"type": "roughconductor", "material": "Cu", "distribution": "ggx", "alpha": 0.2}


def scene_dict(bsdf: dict, size: int, spp: int, lit_for: str = "comparison") -> dict:
    """A sphere on a plane under two point lights; both shapes carry ``bsdf`` with their own UVs
    (the sphere's wrap the texture once around it). ``comparison``: emitter samples only, so that
    two renders with one seed trace the same paths and differ by the BSDF alone; ``timing``: one
    emitter and one BSDF sample (MIS) and a dim sky, which BSDF sampling serves."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    timing = lit_for == "timing"
    scene = {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": int(timing)},
        "sensor": {"type": "perspective", "fov": 38,
                   "to_world": T().look_at(origin=[0.6, -3.6, 2.4], target=[0, 0, 0.45], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": size, "height": size * 3 // 4, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "plane": {"type": "rectangle", "bsdf": bsdf, "to_world": T().scale(1.4)},
        "ball": {"type": "sphere", "bsdf": bsdf,
                 "to_world": T().translate([0.1, 0.2, 0.62]).rotate([1, 0, 0], 70).scale(0.6)},
        "key": {"type": "point", "position": [1.6, -1.0, 2.6], "intensity": {"type": "rgb", "value": 9.0}},
        "rim": {"type": "point", "position": [-1.8, 1.9, 1.4], "intensity": {"type": "rgb", "value": 4.0}},
    }
    if timing:
        scene["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": 0.06}}
    return scene


def distill(source_file: Path, out: Path, resolution: int, channels: int | None, extra: list[str]) -> dict:
    """Runs ``nbrdf_mitsuba.distill --spatial``; its wall seconds and the file's provenance."""
    command = [sys.executable, "-m", "nbrdf_mitsuba.distill", str(source_file), "--spatial", "-o", str(out),
               "--resolution", str(resolution), "-q", *extra]
    if channels is not None:
        command += ["--channels", str(channels)]
    return _run(command, out)


def distill_homogeneous(source_file: Path, out: Path, extra: list[str]) -> dict:
    return _run([sys.executable, "-m", "nbrdf_mitsuba.distill", str(source_file), "-o", str(out), "-q", *extra], out)


def _run(command: list[str], out: Path) -> dict:
    start = time.perf_counter()
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"neural-textures: {' '.join(command)} failed:\n{result.stderr[-3000:]}")
    return {"seconds": time.perf_counter() - start, "provenance": json.loads(out.read_text()).get("provenance", {})}


def render_image(bsdf: dict, size: int, spp: int, seed: int = 0) -> np.ndarray:
    """The comparison render of ``bsdf`` (:func:`scene_dict`)."""
    import mitsuba as mi

    return render_passes(mi.load_dict(scene_dict(bsdf, size, spp)), spp, seed=seed, progress=False)


def errors(reference: np.ndarray, image: np.ndarray) -> dict:
    """The page's two image errors (names of :mod:`nbrdf_tools.common.metrics`)."""
    return {"rmse_tonemapped": metrics.rmse_tonemapped(reference, image), "flip_hdr": metrics.flip_hdr(reference, image)}


def rays_per_second(bsdfs: dict[str, dict], size: int, spp: int, repeats: int) -> dict[str, float]:
    """Mrays/s of each BSDF in the same scene: every scene compiled first, then the timed renders
    alternate between them so that the machine's load affects all alike; the best of ``repeats``."""
    import mitsuba as mi

    scenes = {name: mi.load_dict(scene_dict(bsdf, size, spp, "timing")) for name, bsdf in bsdfs.items()}
    for scene in scenes.values():
        warm_up(scene, spp)
    best = {name: float("inf") for name in scenes}
    for k in range(repeats):
        for name, scene in scenes.items():
            best[name] = min(best[name], timed_render(scene, spp, seed=k)[1])
    sync()
    rays = size * (size * 3 // 4) * spp * RAYS_PER_SAMPLE
    return {name: rays / seconds / 1e6 for name, seconds in best.items()}


def source_texture_bytes(bsdf: dict) -> int:
    """Bytes of the source's textures as Mitsuba holds them (float32 per value) plus the files of
    the measurements it reads."""
    import mitsuba as mi

    params = mi.traverse(mi.load_dict(bsdf))
    total = sum(4 * int(np.prod(params[k].shape)) for k in params.keys() if k.endswith(".data"))
    return total + sum(_measurement_bytes(bsdf))


def _measurement_bytes(node):
    if isinstance(node, dict):
        if node.get("type") == "measured":
            yield Path(node["filename"]).stat().st_size
        for value in node.values():
            yield from _measurement_bytes(value)


def neural_bytes(material: Path) -> dict:
    """The decoder's float32 weights and the latent texture (its values as float32 in memory,
    and the EXR file) of a spatially varying material."""
    spec = json.loads(material.read_text())
    decoder = sum(len(layer["weights"]) + len(layer["bias"]) for layer in spec["layers"])
    latent = spec["latent"]
    texture = material.parent / latent["path"]
    lobes = len((spec.get("sampling") or {}).get("lobes", []))
    values = latent["width"] * latent["height"] * (latent["channels"] + 2 * lobes)
    return {"decoder": 4 * decoder, "texture": 4 * values, "texture_file": texture.stat().st_size}


def chi2_at_texels(material: Path, variant: str, sample_count: int = 100_000) -> list[dict]:
    """Mitsuba's chi2 test of the material's sample() against its pdf() at each of
    :data:`CHI2_TEXELS` for each view of :data:`CHI2_THETAS` (a vectorised variant: the test runs
    on Dr.Jit arrays); one row per texel and view, with its p-value."""
    import mitsuba as mi
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    mi.set_variant(variant)
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(material)})
    rows = []
    for uv in CHI2_TEXELS:
        for theta in CHI2_THETAS:
            sample_func, pdf_func = sampling_adapter(bsdf, uv, theta)
            test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                                 sample_dim=3, sample_count=sample_count, res=61, ires=CHI2_IRES)
            passed = bool(test.run(significance_level=0.01, test_count=len(CHI2_TEXELS) * len(CHI2_THETAS),
                                   quiet=True))
            rows.append({"uv": list(uv), "theta": theta, "passed": passed, "p_value": float(test.p_value)})
    return rows


def sampling_adapter(bsdf, uv, theta):
    """sample/pdf functions of ``bsdf`` at the texel ``uv`` and the view ``theta`` for
    ``ChiSquareTest``. Unlike mitsuba.chi2.BSDFAdapter, a sample counts wherever its pdf is
    positive: the adapter drops samples whose weight is 0, which also drops valid directions
    where the BRDF itself is 0 (a network's output clamps there) and fails a sampler whose
    density matches its pdf."""
    import drjit as dr
    import mitsuba as mi

    def interaction(n):
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = mi.Vector3f(float(np.sin(theta)), 0.0, float(np.cos(theta)))
        si.uv = mi.Point2f(float(uv[0]), float(uv[1]))
        return si

    def sample_func(sample, *args):
        bs, _ = bsdf.sample(mi.BSDFContext(), interaction(dr.width(sample)), sample[0],
                            mi.Point2f(sample[1], sample[2]))
        return bs.wo, dr.select(bs.pdf > 0, 1.0, 0.0)

    def pdf_func(wo, *args):
        return bsdf.pdf(mi.BSDFContext(), interaction(dr.width(wo)), wo)

    return sample_func, pdf_func
