"""Spatially varying materials (issue 61) in the ``nbrdf`` BSDF, scalar variants and the library:
the test files (tests/textured_fixture.py) load through the C ABI and evaluate as the float64
oracle says; the plugin loads them, evaluates, samples and gives the pdf at ``si.uv``; bad input
gives clear errors or finite values."""

from __future__ import annotations

import numpy as np
import pytest

from nbrdf_testing import f32, random_pairs
from textured_fixture import eval_oracle, lookup, pdf_oracle, random_texture, write_textured

SKEW = [[2.0, 0.5, 0.25], [0.0, -3.0, 0.5], [0.0, 0.0, 1.0]]


def hits(n: int, seed: int, huge: bool = True) -> np.ndarray:
    """Planar float32 UVs: most in [-3, 3], some far outside (1e6, 1e30) and some not finite."""
    rng = np.random.default_rng(seed)
    uv = rng.uniform(-3.0, 3.0, (2, n)).astype(np.float32)
    if huge:
        uv[:, : n // 10] *= np.float32(1e6)
        uv[:, n // 10 : n // 5] *= np.float32(1e30)
    uv[0, n // 5 : n // 5 + 5] = np.nan
    uv[1, n // 5 + 5 : n // 5 + 10] = np.inf
    return uv


def test_the_oracle_reads_texel_centres_and_wraps(tmp_path):
    """The oracle itself on hand-made cases: a texel's centre reads it alone, a bilinear lookup
    half way between two centres is their mean, and each wrap mode's image of a far UV."""
    texture = np.arange(4 * 3 * 2, dtype=np.float32).reshape(3, 4, 2)
    centre = lambda i, j: [(i + 0.5) / 4, (j + 0.5) / 3]  # noqa: E731
    for wrap in ("repeat", "mirror", "clamp"):
        material = write_textured(tmp_path / f"{wrap}.nbrdf.json", texture=texture, channels=2, lobes=0, wrap=wrap,
                                  precision="float32")
        values, mapped = lookup(material, np.array([centre(1, 2), [0.5, 0.5]]).T)
        assert mapped.all()
        np.testing.assert_array_equal(values[0], texture[2, 1])
        np.testing.assert_allclose(values[1], (texture[1, 1] + texture[1, 2]) / 2)
        far = np.array([[2.0 + (0.5 / 4), -2.0 + (2.5 / 3)]]).T  # texel (0, 2) two periods away
        expected = {"repeat": texture[2, 0], "mirror": texture[2, 0], "clamp": texture[0, 3]}[wrap]
        np.testing.assert_allclose(lookup(material, far)[0][0], expected, atol=1e-5)
        reflected = np.array([[-(0.5 / 4), 0.5 / 3]]).T  # mirror: texel 0 again; repeat: texel 3
        expected = {"repeat": texture[0, 3], "mirror": texture[0, 0], "clamp": texture[0, 0]}[wrap]
        np.testing.assert_allclose(lookup(material, reflected)[0][0], expected, atol=1e-5)


@pytest.mark.parametrize("lobes", [0, 1, 2])
@pytest.mark.parametrize("filter_", ["bilinear", "nearest"])
@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp"])
def test_the_library_loads_the_fixture_and_matches_the_oracle(tmp_path, wrap, filter_, lobes):
    """The C ABI (nbrdf_material_eval_uv) against the float64 oracle: eval and pdf at UVs near,
    far from (1e6, 1e30) and outside [0, 1], not finite, over texels holding NaN and inf."""
    from nbrdf_mitsuba import _native

    texture = random_texture(7, 3, 4, lobes, seed=3)
    texture[1, 2, 1] = np.nan
    texture[2, 5, 4 if lobes else 0] = np.inf
    n = 2000
    view, light = (f32(a) for a in random_pairs(n, 1))
    for to_uv, huge in ((None, True), (SKEW, False)):
        material = write_textured(tmp_path / "m.nbrdf.json", texture=texture, channels=4, lobes=lobes, wrap=wrap,
                                  filter=filter_, to_uv=to_uv, precision="float32")
        native = _native.Material(material.path)
        assert (native.kind, native.latent_channels, native.texture_size) == ("textured", 4, (7, 3))
        uv = hits(n, 5, huge)
        at_nan = slice(n // 5 + 10, n // 5 + 15)
        uv[:, at_nan] = [[2.5 / 7], [1.5 / 3]]  # the NaN texel's centre (identity to_uv)
        rgb, pdf = native.eval_uv(uv, view, light)
        expected = eval_oracle(material, uv, view, light)
        assert np.all(np.isfinite(rgb)) and np.all(np.isfinite(pdf))
        np.testing.assert_allclose(rgb, expected, rtol=3e-6, atol=1e-6)
        np.testing.assert_allclose(pdf, pdf_oracle(material, uv, view, light), rtol=1e-5, atol=1e-6)
        assert np.all(rgb[:, n // 5 : n // 5 + 10] == 0)  # non-finite UVs read no texel
        if to_uv is None:
            assert np.all(rgb[:, at_nan] == 0)
