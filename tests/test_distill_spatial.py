"""``python -m nbrdf_mitsuba.distill SOURCE --spatial``: spatially varying materials learnt from
textured Mitsuba BSDFs, evaluated by the C library (``nbrdf_material_eval_uv``, the Rust
reference) against the source's own ``BSDF.eval`` at UVs and directions not trained on.

Each accuracy check also measures what a wrong pipeline would give (the texture read upside down,
or one code for the whole texture) against the same bound, so that the bound is shown to fail for
them. Small budgets (32 x 32 texels, 60,000 pairs, a few epochs, no lobe fits) keep each
distillation to seconds.
"""

from __future__ import annotations

import json

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from nbrdf_testing import random_pairs
from textured_material import TexturedMaterial

SIDE = 32
BUDGET = ["--samples", "60000", "--epochs", "12", "--lobes", "0", "--seed", "1", "-q"]
# Mean |ln(1 + f_net cos) - ln(1 + f cos)| over random UVs and directions: a distilled material's
# is 0.0025-0.004; the texture read upside down, or one code everywhere, give 0.024 to 0.06.
LOG_ERROR_BOUND = 0.006


def write_image(path, values: np.ndarray) -> str:
    mi.Bitmap(np.ascontiguousarray(values, dtype=np.float32)).write(str(path))
    return str(path)


def base_colour(folder) -> str:
    """A 32 x 32 RGB texture that changes along v much more than along u, and not symmetrically."""
    y, x = np.mgrid[0:SIDE, 0:SIDE] / SIDE
    rgb = np.stack([0.03 + 0.9 * y * y, 0.85 - 0.8 * y, 0.1 + 0.3 * x], axis=-1)
    return write_image(folder / "colour.exr", rgb)


def blend_weight(folder) -> str:
    """A 32 x 32 mask: 0 in the lower quarter of v, 1 in the upper half, a ramp between."""
    y = (np.mgrid[0:SIDE, 0:SIDE][0] + 0.5) / SIDE
    return write_image(folder / "mask.exr", np.clip((y - 0.25) * 4, 0, 1)[..., None])


def principled(folder) -> dict:
    return {"type": "principled", "base_color": {"type": "bitmap", "filename": base_colour(folder)},
            "roughness": 0.3}


def blend(folder) -> dict:
    return {"type": "blendbsdf", "weight": {"type": "bitmap", "filename": blend_weight(folder)},
            "bsdf_0": {"type": "roughplastic", "alpha": 0.3,
                       "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.2, 0.1]}},
            "bsdf_1": {"type": "roughconductor", "alpha": 0.15, "material": "Au"}}


def write_source(folder, spec: dict):
    path = folder / "source.json"
    path.write_text(json.dumps(spec))
    return path


def run_main(capsys, *args) -> tuple[int, str, str]:
    from nbrdf_mitsuba import distill as command

    status = command.main([str(a) for a in args])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def source_eval(spec: dict, uv: np.ndarray, view: np.ndarray, light: np.ndarray) -> np.ndarray:
    """Mitsuba's ``BSDF.eval`` of the source at planar UVs and local directions."""
    bsdf = mi.load_dict(spec)
    si = dr.zeros(mi.SurfaceInteraction3f, uv.shape[1])
    si.sh_frame = mi.Frame3f(mi.Vector3f(1, 0, 0), mi.Vector3f(0, 1, 0), mi.Vector3f(0, 0, 1))
    si.uv = mi.Point2f(np.ascontiguousarray(uv, dtype=np.float32))
    si.wi = mi.Vector3f(np.ascontiguousarray(view, dtype=np.float32))
    value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(np.ascontiguousarray(light, dtype=np.float32)))
    return np.asarray(value.numpy(), dtype=np.float64).reshape(3, -1)


def log_error(estimate: np.ndarray, reference: np.ndarray) -> float:
    return float(np.mean(np.abs(np.log1p(np.maximum(estimate, 0)) - np.log1p(reference))))


def errors(path, spec: dict, n: int = 20000) -> dict:
    """The material's log error against the source at random UVs (not texel centres) and
    directions, and that of the same material read with v flipped and at one UV everywhere."""
    rng = np.random.default_rng(4)
    uv = rng.uniform(0.02, 0.98, (2, n))
    view, light = random_pairs(n, seed=8, min_cos=0.05)
    reference = source_eval(spec, uv, view, light)
    material = TexturedMaterial(path)
    flipped = np.stack([uv[0], 1 - uv[1]])
    constant = np.full_like(uv, 0.5)
    return {name: log_error(material.eval_cos(at, view, light), reference)
            for name, at in (("material", uv), ("flipped", flipped), ("constant", constant))}


def assert_fits(found: dict) -> None:
    assert found["material"] < LOG_ERROR_BOUND, found
    for wrong in ("flipped", "constant"):
        assert found[wrong] > 2 * LOG_ERROR_BOUND and found[wrong] > 3 * found["material"], found


@pytest.fixture(scope="module")
def distilled(tmp_path_factory):
    """The textured principled distilled in-process: (folder, spec, output, stdout)."""
    from nbrdf_mitsuba import distill as command

    mi.set_variant("llvm_ad_rgb")
    folder = tmp_path_factory.mktemp("spatial")
    spec = principled(folder)
    out = folder / "tiles.nbrdf.json"
    status = command.main([str(write_source(folder, spec)), "--spatial", "-o", str(out), *BUDGET])
    assert status == 0
    return folder, spec, out


def test_a_textured_principled_matches_its_source_where_it_was_not_trained(llvm_variant, distilled):
    folder, spec, out = distilled
    material = json.loads(out.read_text())
    assert material["version"] == 4 and material["name"] == "tiles"
    assert (material["latent"]["width"], material["latent"]["height"], material["latent"]["channels"]) == (32, 32, 8)
    assert material["latent"]["path"] == "tiles.latent.exr" and (folder / "tiles.latent.exr").is_file()
    details = material["provenance"]["distilled_from"]
    assert details["parameters"] == "signature" and details["texture_size"] == [32, 32] and details["notes"] == []
    assert_fits(errors(out, spec))


def test_the_same_seed_writes_the_same_files(llvm_variant, distilled, tmp_path, capsys):
    folder, spec, out = distilled
    again = tmp_path / "tiles.nbrdf.json"
    status, _, err = run_main(capsys, folder / "source.json", "--spatial", "-o", again, *BUDGET, "--threads", "1")
    assert status == 0, err
    assert (tmp_path / "tiles.latent.exr").read_bytes() == (folder / "tiles.latent.exr").read_bytes()
    first, second = json.loads(out.read_text()), json.loads(again.read_text())
    for material in (first, second):  # durations are the only fields that may differ
        del material["provenance"]["seconds"], material["provenance"]["distilled_from"]["evaluation_seconds"]
    assert first == second


def test_a_blend_of_two_bsdfs_by_a_texture_is_learnt(llvm_variant, tmp_path, capsys):
    spec = blend(tmp_path)
    out = tmp_path / "blend.nbrdf.json"
    status, stdout, err = run_main(capsys, write_source(tmp_path, spec), "--spatial", "-o", out, *BUDGET,
                                   "--lobes", "1", "--representatives", "2")
    assert status == 0, err
    assert "32 x 32 texels" in stdout
    material = json.loads(out.read_text())
    assert [lobe["exponent"] for lobe in material["sampling"]["lobes"]] == ["lobe.n"]
    assert material["provenance"]["representatives"] == 2
    assert_fits(errors(out, spec))


def test_texture_values_describe_texels_too(llvm_variant, tmp_path, capsys):
    spec = blend(tmp_path)
    out = tmp_path / "blend.nbrdf.json"
    status, _, err = run_main(capsys, write_source(tmp_path, spec), "--spatial", "-o", out, *BUDGET,
                              "--parameters", "textures", "--resolution", "16")
    assert status == 0, err
    material = json.loads(out.read_text())
    # One grey texture, read as RGB: one parameter once the repeated channels are left out.
    assert material["provenance"]["parameters"] == 1 and material["latent"]["width"] == 16
    assert material["provenance"]["distilled_from"]["parameters"] == "textures"


def test_a_homogeneous_source_is_refused_with_the_command_that_fits_it(llvm_variant, tmp_path, capsys):
    out = tmp_path / "plastic.nbrdf.json"
    source = write_source(tmp_path, {"type": "roughplastic", "alpha": 0.2})
    status, _, err = run_main(capsys, source, "--spatial", "-o", out, *BUDGET)
    assert status == 2
    assert "homogeneous" in err and "without --spatial" in err and "nbrdf_mitsuba.distill" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


def test_a_bumpmap_is_left_to_mitsuba_and_a_twosided_gives_its_front(llvm_variant, tmp_path, capsys):
    spec = principled(tmp_path)
    height = write_image(tmp_path / "height.exr", np.random.default_rng(0).random((SIDE, SIDE, 1)))
    wrapped = {"type": "twosided", "bsdf": {"type": "bumpmap", "bsdf": spec,
                                            "arbitrary": {"type": "bitmap", "filename": height, "raw": True}}}
    out = tmp_path / "bumpy.nbrdf.json"
    status, stdout, err = run_main(capsys, write_source(tmp_path, wrapped), "--spatial", "-o", out, *BUDGET)
    assert status == 0, err
    assert "note: twosided: its front BSDF is distilled" in stdout
    assert "note: bumpmap: the BSDF it wraps is distilled; keep the bumpmap in the scene" in stdout
    notes = json.loads(out.read_text())["provenance"]["distilled_from"]["notes"]
    assert len(notes) == 2 and "bumpmap" in notes[1]
    # What is learnt is the wrapped principled, without the bumps.
    assert_fits(errors(out, spec))


def test_a_bumpmap_inside_a_blend_cannot_be_left_out(llvm_variant, tmp_path, capsys):
    spec = blend(tmp_path)
    height = write_image(tmp_path / "height.exr", np.ones((4, 4, 1)))
    spec["bsdf_0"] = {"type": "bumpmap", "bsdf": spec["bsdf_0"],
                      "arbitrary": {"type": "bitmap", "filename": height, "raw": True}}
    status, _, err = run_main(capsys, write_source(tmp_path, spec), "--spatial", "-o", tmp_path / "x.nbrdf.json",
                              *BUDGET)
    assert status == 2 and "bumpmap inside a BlendBSDF" in err, err


def test_spatial_options_need_spatial_and_settings_are_checked(llvm_variant, tmp_path, capsys):
    source = write_source(tmp_path, principled(tmp_path))
    out = tmp_path / "x.nbrdf.json"
    for args, words in (
        (["--channels", "4"], "--channels: only with --spatial"),
        (["--spatial", "--channels", "33"], "--channels 33"),
        (["--spatial", "--resolution", "0"], "--resolution 0"),
        (["--spatial", "--representatives", "300"], "--representatives 300"),
        (["--spatial", "--reciprocal"], "--reciprocal: not available with --spatial"),
    ):
        status, _, err = run_main(capsys, source, "-o", out, *args)
        assert status == 2 and words in err, (args, err)
    assert not out.exists()


def test_the_default_resolution_is_the_largest_bitmap_with_its_tiling(llvm_variant, tmp_path):
    from nbrdf_mitsuba.distill.spatial import texture_size

    small = write_image(tmp_path / "small.exr", np.random.default_rng(1).random((4, 8, 1)))
    large = write_image(tmp_path / "large.exr", np.random.default_rng(2).random((12, 6, 3)))
    bsdf = mi.load_dict({"type": "principled", "base_color": {"type": "bitmap", "filename": large},
                         "roughness": {"type": "bitmap", "filename": small,
                                       "to_uv": mi.ScalarTransform4f().scale([4, 2, 1])}})
    # The roughness map tiles 4 x 2 times: 32 x 8 texels per unit of UV, more than 6 x 12.
    assert texture_size(bsdf, None) == (32, 8)
    assert texture_size(bsdf, 20) == (20, 20)
    assert texture_size(mi.load_dict({"type": "roughplastic"}), None) == (256, 256)


def test_stratified_texels_cover_the_texture_evenly():
    from nbrdf_mitsuba.distill.spatial import stratified_texels

    rng = np.random.default_rng(0)
    counts = np.bincount(stratified_texels(2 * 64 + 20, 8, 8, rng), minlength=64)
    assert counts.min() == 2 and counts.max() == 3 and counts.sum() == 148
    picks = stratified_texels(400, 64, 64, rng)
    quadrants = np.bincount((picks % 64 >= 32) + 2 * (picks // 64 >= 32), minlength=4)
    assert len(set(picks.tolist())) == 400 and quadrants.min() >= 85, quadrants
