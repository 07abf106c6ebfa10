"""``python -m nbrdf_tools anisotropic`` at a small budget: the network distilled with
``--anisotropy on`` renders an anisotropic roughconductor on turned surfaces much closer to
Mitsuba's own BSDF than the one distilled with ``--anisotropy off``. Were ``phi_h`` dropped
anywhere (sampling, encoding, plugin), both networks would be isotropic and render alike, and the
test would fail."""

from __future__ import annotations

import json

import pytest

SMALL = ["--samples", "30000", "--epochs", "30", "--size", "64", "--spp", "4", "--no-figure"]


def test_the_anisotropic_network_renders_much_closer_than_the_isotropic_one(llvm_variant, tmp_path):
    from nbrdf_tools.pages.anisotropic import main

    assert main(["--out", str(tmp_path / "anisotropic.md"), "--data", str(tmp_path), *SMALL]) == 0
    result = json.loads((tmp_path / "anisotropic.json").read_text())
    assert "| anisotropic (`--anisotropy on`) |" in (tmp_path / "anisotropic.md").read_text()
    assert result["networks"]["on"]["anisotropic"] is True
    assert result["networks"]["off"]["anisotropic"] is False
    aniso, iso = result["errors"]["anisotropic NBRDF"], result["errors"]["isotropic NBRDF"]
    assert aniso["rmse_tonemapped"] < 0.5 * iso["rmse_tonemapped"], result["errors"]
    assert aniso["flip_hdr"] < iso["flip_hdr"], result["errors"]


def test_bad_arguments_are_usage_errors(tmp_path):
    from nbrdf_tools.pages.anisotropic import main

    with pytest.raises(SystemExit) as exit_info:
        main(["--data", str(tmp_path), "--alpha-u", "0"])
    assert exit_info.value.code == 2
