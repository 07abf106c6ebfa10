"""`nbrdf train X.bsdf`: a network learnt straight from a real RGL measurement (no MERL grid in
between) renders close to Mitsuba's `measured` plugin on the same measurement (the independent
reference), and its provenance names the source."""

from __future__ import annotations

import json
import subprocess

from nbrdf_tools.common import compare_materials
from nbrdf_tools.common.paths import default_cli


def test_short_training_from_a_measurement_matches_measured(llvm_variant, shared, tmp_path):
    source = shared / "data" / "rgl" / "paper_white_rgb.bsdf"
    network = tmp_path / "paper_white.nbrdf.json"
    cli = default_cli()
    assert cli.is_file(), f"{cli} is not built (make setup)"
    done = subprocess.run([str(cli), "train", str(source), "-o", str(network), "--epochs", "3",
                           "--min-epochs", "1", "--samples", "50000", "--quiet"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    provenance = json.loads(network.read_text())["provenance"]
    assert provenance["source_kind"] == "rgl-measurement"
    assert provenance["source"] == str(source)
    assert provenance["epochs"] == 3

    ours = compare_materials.compare(source, network, resolution=48, samples=5000)
    # Loose bounds: this run measured RMSE 7.8e-3, SSIM 0.978 (one epoch on 2,000 samples: 0.14,
    # 0.15; the full default run and the authors' network are near 2.5e-3 and 0.98).
    assert ours.mean.rmse < 0.015, ours.to_json()["mean"]
    assert ours.mean.ssim > 0.9, ours.to_json()["mean"]
