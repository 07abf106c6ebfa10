"""`python -m nbrdf_mitsuba render`: the `mitsuba` command with the nbrdf/merl plugins.

Its images are checked against Mitsuba's own `mi.load_file` + `mi.render` of the same scene and
parameters (the reference), its PNG against a NumPy sRGB encoding of the EXR, and its user errors
for being one line with exit status 2 (usage or input) and no traceback.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import nbrdf_mitsuba  # noqa: F401  (before mitsuba)
import mitsuba as mi

from nbrdf_mitsuba import render
from nbrdf_testing import write_network

REPO = Path(__file__).resolve().parents[1]
VEACH = REPO / "scenes" / "veach_mis.xml"
TINY = {"resx": "24", "resy": "16"}


def run_cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "nbrdf_mitsuba", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


def defines(parameters: dict) -> list[str]:
    return [item for key, value in parameters.items() for item in ("-D", f"{key}={value}")]


def read_exr(path: Path) -> np.ndarray:
    return np.array(mi.Bitmap(str(path)), dtype=np.float64)


def srgb8(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of values clamped to [0, 1], as 8-bit integers."""
    x = np.clip(linear, 0.0, 1.0)
    encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(encoded * 255).astype(np.int64)


def reference_render(parameters: dict, spp: int, seeds: list[int]) -> np.ndarray:
    """Mitsuba's render of veach_mis.xml with `parameters`, averaged over one pass per seed."""
    mi.set_variant("scalar_rgb")
    scene = mi.load_file(str(VEACH), **parameters)
    return np.mean([np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64) for seed in seeds], axis=0)


def test_defines_follow_mitsuba():
    assert render.parse_defines(["spp=4", "plate=plates/x.xml", "spp=8", "empty="]) == \
        {"spp": "8", "plate": "plates/x.xml", "empty": ""}
    for bad in ["spp", "=4", "a b=1", "parallel=0"]:
        with pytest.raises(render.UsageError):
            render.parse_defines([bad])


def test_pass_sizes_cover_the_spp():
    for spp, passes in [(1, 8), (7, 3), (16, 8), (5, 1), (3, 10)]:
        sizes = render.pass_sizes(spp, passes)
        assert sum(sizes) == spp and min(sizes) >= 1 and len(sizes) == min(spp, passes)
        assert max(sizes) - min(sizes) <= 1


def test_output_paths():
    assert render.output_paths(Path("s/scene.xml"), None) == (Path("s/scene.exr"), Path("s/scene.png"))
    assert render.output_paths(Path("scene.xml"), "out/img") == (Path("out/img.exr"), Path("out/img.png"))
    with pytest.raises(render.UsageError):
        render.output_paths(Path("scene.xml"), "img.png")


def test_renders_veach_like_mitsuba(tmp_path):
    """Default plates, one pass: the same image as mi.render with the same -D parameters, and a PNG
    that is the clamped sRGB encoding of it."""
    parameters = {**TINY, "spp": "4"}
    out = tmp_path / "veach.exr"
    result = run_cli("render", VEACH, "-o", out, "--variant", "scalar_rgb", *defines(parameters), "--no-progress")
    assert result.returncode == 0, result.stderr
    image = read_exr(out)
    assert image.shape == (16, 24, 3)
    expected = reference_render(parameters, spp=4, seeds=[0])
    np.testing.assert_allclose(image, expected, rtol=1e-5, atol=1e-6)
    assert image.max() > 0.05  # the scene is lit: a black image would pass the comparison vacuously

    png = np.array(mi.Bitmap(str(tmp_path / "veach.png")), dtype=np.int64)
    assert png.shape == (16, 24, 3)
    assert np.abs(png - srgb8(image)).max() <= 1


def test_nbrdf_plates_in_passes(tmp_path):
    """An nbrdf plate given by -D (resolved against the scene's folder and the working directory)
    and --spp 4 in two passes: the mean of Mitsuba's renders with seeds 0 and 1 at 2 spp."""
    network = write_network(tmp_path / "net.nbrdf.json")
    parameters = {**TINY, "plate": "plates/nbrdf.xml", "nbrdf": str(network)}
    out = tmp_path / "nbrdf.exr"
    result = run_cli("render", VEACH, "-o", out, "-m", "scalar_rgb", "--spp", 4, "--passes", 2,
                     *defines(parameters))
    assert result.returncode == 0, result.stderr
    assert "2 pass(es)" in result.stderr
    expected = reference_render(parameters, spp=2, seeds=[0, 1])
    np.testing.assert_allclose(read_exr(out), expected, rtol=1e-5, atol=1e-6)


def test_default_variant_and_output(tmp_path):
    """No -m: llvm_ad_rgb where Dr.Jit's LLVM backend works, else scalar_rgb; no -o: the scene's
    name beside the scene."""
    scene = tmp_path / "scene.xml"
    scene.write_text(VEACH.read_text().replace('value="plates/roughplastic.xml"',
                                               f'value="{REPO / "scenes/plates/roughplastic.xml"}"'))
    result = run_cli("render", scene, *defines({**TINY, "spp": "1"}), "--no-progress")
    assert result.returncode == 0, result.stderr
    expected = "llvm_ad_rgb" if nbrdf_mitsuba.llvm.problem() is None else "scalar_rgb"
    assert f"({expected}," in result.stderr
    assert (tmp_path / "scene.exr").is_file() and (tmp_path / "scene.png").is_file()


@pytest.mark.parametrize("args, message", [
    (["render", "missing.xml"], "scene file 'missing.xml' not found"),
    (["render", VEACH, "-D", "spp"], "expected key=value"),
    (["render", VEACH, "-m", "no_such_variant"], "variant 'no_such_variant' is not available"),
    (["render", VEACH, "-o", "out.png"], "OpenEXR"),
    (["render", VEACH, "-m", "scalar_rgb", "-D", "plate=no-such-plate.xml"], "cannot load"),
    (["render", VEACH, "-m", "scalar_rgb", "--spp", "0"], "--spp 0"),
    (["render", VEACH, "-m", "scalar_rgb", "-D", "nosuch=1"], "unused parameters"),
    # The plugin's own error, raised in its Python constructor: Mitsuba embeds the traceback.
    (["render", VEACH, "-m", "scalar_rgb", "-D", "plate=plates/nbrdf.xml", "-D", "nbrdf=missing.nbrdf.json"],
     'RuntimeError: NbrdfBSDF (plugin "nbrdf"): cannot load missing.nbrdf.json: No such file'),
])
def test_user_errors_are_one_line(tmp_path, args, message):
    result = run_cli(*args, cwd=tmp_path)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and 'File "' not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    errors = [line for line in lines if "error:" in line]
    assert len(errors) == 1 and message in errors[0], result.stderr
    assert not list(tmp_path.glob("*.exr"))


def test_command_dispatch():
    assert run_cli().returncode == 2
    listing = run_cli("--help")
    assert listing.returncode == 0 and "render" in listing.stdout
    unknown = run_cli("paint")
    assert unknown.returncode == 2 and "unknown command 'paint'" in unknown.stderr
    helped = run_cli("render", "--help")
    assert helped.returncode == 0 and "-D KEY=VALUE" in helped.stdout
