"""The neural-textures page (issue 61): its sources split once into tuning and test sets from real
textures and measurements, and its measuring run end to end on one blend at a tiny size, the
page written from what it stored."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nbrdf_tools.pages.neural_textures import main, sources


def test_the_split():
    """Disjoint named sets, a test set with every kind of source the issue names (a kitchen
    material, a blend of two measurements, a textured principled), and no measurement or image
    of a tuning blend reused by a test blend."""
    tuning, test = sources.select("tuning"), sources.select("test")
    assert tuning and test and not {s.name for s in tuning} & {s.name for s in test}
    assert {"kitchen", "blend", "principled"} <= {s.kind for s in test}
    tuned = {m for s in tuning for m in s.measurements}
    assert not tuned & {m for s in test for m in s.measurements}
    assert [s.name for s in sources.select("all", ["kitchen-tabletop"])] == ["kitchen-tabletop"]


def test_a_mask_keeps_the_images_shapes(shared, llvm_variant, tmp_path):
    """A blend's mask is 0 or 1 and about half of each, from blocks of the image."""
    import mitsuba as mi

    path = sources.derived_map("wood.jpg", 0.0, 1.0, tmp_path, "mask", threshold=True)
    mask = np.array(mi.Bitmap(str(path)))
    assert set(np.unique(mask)) == {0.0, 1.0}
    assert 0.3 < mask.mean() < 0.7
    image = sources.luminance("wood.jpg")
    assert mask.reshape(mask.shape[0], -1).shape[0] == image.shape[0] // sources.MASK_BLOCK


def test_the_measuring_run_on_a_blend(shared, llvm_variant, tmp_path):
    """--quick on one blend: every figure is there and finite, the neural texture resembles its
    source far better than a black image does, and --stored-only writes the same page again."""
    out = tmp_path / "page.md"
    assert main(["--quick", "--sources", "blend-paper-napoli", "--work", str(tmp_path / "work"),
                 "--out", str(out)]) == 0
    data = json.loads(out.with_suffix(".json").read_text())
    (source,) = data["sources"]
    errors = source["errors"]
    assert set(errors) == {"neural", "per_material"}
    assert all(np.isfinite(v) for e in errors.values() for v in e.values())
    assert errors["neural"]["rmse_tonemapped"] < 0.5 * black_image_rmse(tmp_path / "work" / "blend-paper-napoli")
    assert len(source["chi2"]) == 6 and all(0 <= r["p_value"] <= 1 for r in source["chi2"])
    assert source["mrays_per_s"]["neural"] > 0 and source["memory"]["decoder"] > 0
    first = out.read_text()
    assert main(["--stored-only", "--data", str(out.with_suffix(".json")), "--out", str(out)]) == 0
    assert out.read_text() == first
    assert "| blend-paper-napoli | tuning |" in first


def black_image_rmse(folder) -> float:
    """The tone-mapped RMSE of a black image against a render of the source."""
    from nbrdf_tools.common import metrics
    from nbrdf_tools.pages.neural_textures import measure

    source = json.loads((folder / "source.json").read_text())
    image = measure.render_image(source, 48, 4)
    return metrics.rmse_tonemapped(image, np.zeros_like(image))


@pytest.mark.parametrize("kind", ["principled", "conductor", "kitchen"])
def test_every_kind_of_source_loads(shared, llvm_variant, tmp_path, kind):
    import mitsuba as mi

    source = next(s for s in sources.SOURCES if s.kind == kind)
    bsdf = mi.load_dict(sources.bsdf(source, tmp_path))
    assert any(k.endswith(".data") for k in mi.traverse(bsdf).keys())
