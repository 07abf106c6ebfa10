"""``python -m nbrdf_tools demo`` (``make demo``): a run leaves the checkout as it was (every file
under its output folder, the README's picture only with ``--docs-figure``), and the network's
panel names the sampling strategy its BSDF uses, read back from the BSDF the scene loaded.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import mitsuba as mi
import pytest

from nbrdf_testing import write_network
from nbrdf_tools import demo
from nbrdf_tools.common.paths import default_cli
from nbrdf_tools.common.scenes.veach import veach_scene_dict

REPO = Path(__file__).resolve().parents[1]
README_PICTURE = REPO / "docs" / "images" / "demo.png"
CLI = default_cli()
LOBE = {"model": "blinn-phong", "exponent": 900.0, "specular_weight": 0.5, "source": "manual"}
SECOND_LOBE = {"second_lobe": {"exponent": 40.0, "specular_weight": 0.3}}


def _planned(argv: list[str]) -> dict[str, Path]:
    args = demo.parse_args(argv)
    return demo.output_paths(args.out, args.material, args.model, args.figure)


def test_default_run_writes_only_under_out_demo():
    planned = _planned([])
    assert set(planned) == {"table", "network", "table_exr", "nbrdf_exr", "side_by_side", "figure"}
    assert all(path.resolve().is_relative_to(REPO / "out" / "demo") for path in planned.values()), planned
    asked = _planned(["--docs-figure"])
    assert asked["figure"] == README_PICTURE
    assert {k: v for k, v in asked.items() if k != "figure"} == {k: v for k, v in planned.items() if k != "figure"}
    elsewhere = _planned(["--out", "/tmp/somewhere"])
    assert all(path.is_relative_to(Path("/tmp/somewhere")) for path in elsewhere.values()), elsewhere
    with pytest.raises(SystemExit):
        demo.parse_args(["--docs-figure", "--figure", "x.png"])


@pytest.mark.parametrize(("sampling", "expected"), [
    ({**LOBE, **SECOND_LOBE, "default": "two_lobe"}, "two_lobe"),
    ({**LOBE, **SECOND_LOBE, "default": "tabulated"}, "tabulated"),
    ({**LOBE, "default": "tabulated"}, "tabulated"),
    # No stored default: the plugin samples the file's one lobe.
    (LOBE, "phong"),
], ids=["two-lobe-default", "tabulated-over-two-lobes", "tabulated", "one-lobe-no-default"])
def test_the_network_label_names_the_strategy_the_bsdf_uses(llvm_variant, tmp_path, sampling, expected):
    network = write_network(tmp_path / "n.nbrdf.json", sampling=sampling)
    scene = mi.load_dict(veach_scene_dict({"type": "nbrdf", "filename": str(network)}, resolution=(8, 8)))
    assert demo.scene_sampling(scene) == expected
    label = demo.network_label(demo.scene_sampling(scene))
    assert expected in label and "Phong-sampled" not in label


def _status() -> set[str]:
    """The checkout's changes (modified, added, untracked; ignored folders such as out/ aside)."""
    result = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=REPO,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    return set(result.stdout.splitlines())


def test_a_small_run_leaves_the_checkout_as_it_was(tmp_path):
    """The whole demo at a tiny size: its files are the planned ones, all in its folder; the
    checkout (the README's picture included) is unchanged; it names the file's default strategy."""
    if not CLI.is_file():
        pytest.skip(f"the nbrdf CLI {CLI} is not built (make build)")
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip(f"{REPO} is not a git checkout (or git is missing): its changes cannot be listed")
    before, picture = _status(), hashlib.sha256(README_PICTURE.read_bytes()).hexdigest()
    out = tmp_path / "demo"
    argv = ["--spp", "4", "--passes", "1", "--width", "48", "--samples", "20000", "--out", str(out), "--no-progress"]
    result = subprocess.run([sys.executable, "-m", "nbrdf_tools", "demo", *argv], capture_output=True, text=True,
                            timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert _status() == before
    assert hashlib.sha256(README_PICTURE.read_bytes()).hexdigest() == picture
    planned = demo.output_paths(out, demo.DEFAULT_MATERIAL, "sgd")
    assert sorted(p for p in out.rglob("*") if p.is_file()) == sorted(planned.values())
    stored = json.loads(planned["network"].read_text())["sampling"]["default"]
    rendered = [line for line in result.stdout.splitlines() if line.startswith("render:  nbrdf,")]
    assert len(rendered) == 1 and rendered[0].endswith(f"(llvm_ad_rgb, {stored} sampling)"), result.stdout
