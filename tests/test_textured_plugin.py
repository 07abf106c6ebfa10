"""Spatially varying materials (issue 61) in the ``nbrdf`` BSDF, scalar variants and the library:
the test files (tests/textured_fixture.py) load through the C ABI and evaluate as the float64
oracle says; the plugin loads them, evaluates, samples and gives the pdf at ``si.uv``; bad input
gives clear errors or finite values."""

from __future__ import annotations

import nbrdf_mitsuba  # noqa: F401  (before mitsuba)
import mitsuba as mi
import numpy as np
import pytest

from conftest import bsdf_calls, use_variant
from nbrdf_testing import f32, random_pairs, sph, write_network
from textured_fixture import (chi2_pvalue, encode_exponent, eval_oracle, lobe_parameters, lookup, pdf_oracle,
                              random_decoder, random_texture, render, write_textured)

SKEW = [[2.0, 0.5, 0.25], [0.0, -3.0, 0.5], [0.0, 0.0, 1.0]]


def column(values, n: int) -> np.ndarray:
    """``n`` copies of a vector as a planar (len, n) array."""
    return np.tile(np.asarray(values, np.float64).reshape(-1, 1), n)


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


# ---------------------------------------------------------------------------------------------
# The plugin in scalar variants (the library through its C ABI)


@pytest.fixture
def scalar_rgb(restore_variant):
    mi.set_variant("scalar_rgb")
    yield "scalar_rgb"


def test_scene_xml_and_load_dict_load_a_textured_file(tmp_path, scalar_rgb):
    material = write_textured(tmp_path / "wood.nbrdf.json")
    xml = (f'<bsdf version="3.0.0" type="nbrdf"><string name="filename" value="{material.path}"/></bsdf>')
    for bsdf in (mi.load_string(xml), mi.load_dict({"type": "nbrdf", "filename": str(material.path)})):
        assert mi.has_flag(bsdf.flags(), mi.BSDFFlags.SpatiallyVarying)
        assert mi.has_flag(bsdf.flags(), mi.BSDFFlags.GlossyReflection)
        assert "kind = spatially varying (format version 4)" in str(bsdf)
    homogeneous = mi.load_dict({"type": "nbrdf", "filename": str(write_network(tmp_path / "n.nbrdf.json"))})
    assert "hidden_width = 21" in str(homogeneous)
    assert not mi.has_flag(homogeneous.flags(), mi.BSDFFlags.SpatiallyVarying)


def test_to_string_says_kind_channels_size_and_mapping(tmp_path, scalar_rgb):
    material = write_textured(tmp_path / "m.nbrdf.json", texture=random_texture(6, 2, 4, 2), channels=4, lobes=2,
                              wrap="mirror", filter="nearest", to_uv=SKEW)
    text = str(mi.load_dict({"type": "nbrdf", "filename": str(material.path)}))
    for line in ("kind = spatially varying (format version 4)", "latent_channels = 4", "texture_size = 6 x 2",
                 "mapping = wrap mirror, filter nearest, to_uv [[2.0, 0.5, 0.25], [0.0, -3.0, 0.5], [0.0, 0.0, 1.0]]",
                 "decoder = 10 -> 12 -> 12 -> 3", "sampling = texture lobes (two Blinn-Phong lobes and cosine)",
                 "backend = rust"):
        assert line in text, text


@pytest.mark.parametrize("lobes", [0, 1, 2])
def test_scalar_values_match_the_oracle(tmp_path, scalar_rgb, lobes):
    """eval, pdf, eval_pdf and sample of the plugin at si.uv against the float64 oracle; sampled
    directions carry the pdf of their direction and the weight eval / pdf."""
    texture = random_texture(5, 4, 3, lobes, seed=11)
    texture[2, 3, 0] = np.nan
    material = write_textured(tmp_path / "m.nbrdf.json", texture=texture, lobes=lobes, wrap="mirror")
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(material.path)})
    n = 80
    view, light = (f32(a) for a in random_pairs(n, 7))
    u = np.random.default_rng(8).random((3, n)).astype(np.float32)
    uv = hits(n, 9)
    uv[:, -4:] = [[3.5 / 5], [2.5 / 4]]  # the NaN texel's centre
    got = bsdf_calls(bsdf, view, light, u, uv=uv)
    expected = eval_oracle(material, uv, view, light)
    assert np.all(expected[:, -4:] == 0) and expected.max() > 0
    for key in ("eval", "eval_pdf.value"):
        np.testing.assert_allclose(got[key], expected, rtol=3e-6, atol=1e-6, err_msg=key)
    for key in ("pdf", "eval_pdf.pdf"):
        np.testing.assert_allclose(got[key], pdf_oracle(material, uv, view, light), rtol=1e-5, atol=1e-6, err_msg=key)
    wo, pdf, weight = got["sample.wo"], got["sample.pdf"], got["sample.weight"]
    valid = pdf > 0
    assert valid.mean() > 0.5 and np.all(weight[:, ~valid] == 0)
    np.testing.assert_allclose(pdf[valid], pdf_oracle(material, uv[:, valid], view[:, valid], f32(wo[:, valid])),
                               rtol=1e-4, atol=1e-6)
    f = eval_oracle(material, uv[:, valid], view[:, valid], f32(wo[:, valid]))
    np.testing.assert_allclose(weight[:, valid], f / pdf[valid], rtol=1e-4, atol=1e-6)


def _moderate_lobes(seed: int) -> np.ndarray:
    """A 3 x 2 texture of 2 latent channels and one lobe per texel, exponents 8 to 40."""
    texture = random_texture(3, 2, 2, 1, seed=seed)
    texture[..., 2] = encode_exponent(np.linspace(8.0, 40.0, 6).reshape(2, 3))
    texture[..., 3] = np.linspace(0.3, 0.8, 6).reshape(2, 3)
    return texture


TEXELS = [(0.5 / 3, 0.5 / 2), (1.5 / 3, 1.5 / 2), (2.5 / 3, 0.5 / 2)]  # centres of three texels


@pytest.mark.parametrize("uv", TEXELS)
def test_scalar_samples_pass_chi2_at_texels(tmp_path, scalar_rgb, uv):
    """The scalar plugin's sampled directions at a texel against the density the oracle gives
    there (a chi^2 test); against another texel's density, the same samples fail."""
    material = write_textured(tmp_path / "m.nbrdf.json", texture=_moderate_lobes(3), channels=2, lobes=1)
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(material.path)})
    n = 8000
    wi = sph([0.6], [0.4])
    u = np.random.default_rng(4).random((3, n)).astype(np.float32)
    si = mi.SurfaceInteraction3f()
    si.wi, si.uv = mi.Vector3f(*f32(wi)[:, 0]), mi.Point2f(*uv)
    samples = [bsdf.sample(mi.BSDFContext(), si, float(a), mi.Point2f(float(b), float(c)))[0] for a, b, c in u.T]
    light = np.array([list(bs.wo) for bs in samples]).T
    valid = np.array([bs.pdf > 0 for bs in samples])

    def density_at(texel):
        return lambda l: pdf_oracle(material, column(texel, l.shape[1]), np.repeat(wi, l.shape[1], axis=1), l)

    assert chi2_pvalue(light, valid, density_at(uv)) > 0.01 / len(TEXELS)
    other = TEXELS[(TEXELS.index(uv) + 1) % len(TEXELS)]
    assert chi2_pvalue(light, valid, density_at(other)) < 1e-6


@pytest.mark.parametrize("uv", TEXELS)
def test_pdf_integrates_to_the_lobes_mass_above_the_horizon(tmp_path, scalar_rgb, uv):
    """Quadrature of the plugin's pdf at a texel for a view at the normal, in coordinates centred
    on the mirror direction: each lobe of exponent n leaves (1/sqrt 2)^(n + 1) of its mass below
    the horizon (half vectors beyond 45 degrees), the cosine lobe none."""
    material = write_textured(tmp_path / "m.nbrdf.json", texture=_moderate_lobes(5), channels=2, lobes=1)
    bsdf = mi.load_dict({"type": "nbrdf", "filename": str(material.path)})
    n_t, n_p = 40, 24
    t = (np.arange(n_t) + 0.5) / n_t
    alpha, d_alpha = np.pi / 2 * t**2, np.pi * t / n_t
    phi = (np.arange(n_p) + 0.5) / n_p * 2 * np.pi
    A, P = np.meshgrid(alpha, phi, indexing="ij")
    light = f32(sph(A.ravel(), P.ravel()))
    view = column([0.0, 0.0, 1.0], light.shape[1])
    got = bsdf_calls(bsdf, view, light, np.zeros_like(view), uv=column(uv, light.shape[1]))
    integral = np.sum(got["pdf"].reshape(n_t, n_p) * np.sin(A) * d_alpha[:, None] * (2 * np.pi / n_p))
    n1, w1, _, _ = lobe_parameters(material, column(uv, 1))[0]
    assert w1 > 0
    assert integral == pytest.approx(1 - w1 * np.sqrt(0.5) ** (n1 + 1), abs=5e-3)


@pytest.mark.parametrize("variant", ["scalar_rgb", "scalar_mono", "scalar_spectral", "scalar_spectral_polarized"])
def test_scalar_renders_are_finite_and_deterministic(tmp_path, variant, restore_variant):
    """Renders over a texture holding NaN and inf texels, read far outside [0, 1] (to_uv scales
    the sphere's UVs by 1e6): finite, not black, and the same for the same seed."""
    use_variant(variant)
    texture = random_texture(5, 4, 3, 1, seed=2)
    texture[1, 1, 0], texture[2, 3, 2] = np.nan, np.inf
    for to_uv in (None, [[1e6, 0, 0], [0, 1e6, 0], [0, 0, 1]]):
        material = write_textured(tmp_path / "m.nbrdf.json", texture=texture, to_uv=to_uv, wrap="mirror")
        image = render(material.path, seed=3)
        assert np.all(np.isfinite(image)) and image.max() > 0
        np.testing.assert_array_equal(render(material.path, seed=3), image)


# ---------------------------------------------------------------------------------------------
# Bad input


def _load(path, **parameters):
    return mi.load_dict({"type": "nbrdf", "filename": str(path), **parameters})


def test_a_missing_texture_is_named(tmp_path, scalar_rgb):
    material = write_textured(tmp_path / "oak.nbrdf.json")
    material.exr.unlink()
    with pytest.raises(Exception, match=r'latent.path "oak.latent.exr": .*oak.latent.exr: No such file'):
        _load(material.path)


def test_a_texture_of_the_wrong_channels_or_size_names_the_field(tmp_path, scalar_rgb):
    latent = {"path": "m.latent.exr", "width": 5, "height": 4, "channels": 3}
    wrong_count = write_textured(tmp_path / "m.nbrdf.json", layers=random_decoder(4),
                                 document={"latent": {**latent, "channels": 4}})
    with pytest.raises(Exception, match=r"m.latent.exr: no channel 'latent.3'"):
        _load(wrong_count.path)
    decoder_mismatch = write_textured(tmp_path / "m.nbrdf.json", document={"latent": {**latent, "channels": 4}})
    with pytest.raises(Exception, match=r"layer 1 has 9 inputs, expected 6 direction features \+ latent.channels = 10"):
        _load(decoder_mismatch.path)
    wrong_size = write_textured(tmp_path / "m.nbrdf.json", document={"latent": {**latent, "width": 6}})
    with pytest.raises(Exception, match=r"5 x 4 texels, but latent.width x latent.height is 6 x 4"):
        _load(wrong_size.path)
    wrong_lobe = write_textured(tmp_path / "m.nbrdf.json", exr_names=["latent.0", "latent.1", "latent.2", "lobe.n", "w"])
    with pytest.raises(Exception, match=r"no channel 'lobe.w'"):
        _load(wrong_lobe.path)


def test_homogeneous_only_parameters_are_refused(tmp_path, scalar_rgb):
    material = write_textured(tmp_path / "m.nbrdf.json")
    with pytest.raises(Exception, match='"sampling" is a parameter of homogeneous networks only; this file is a '
                                        "spatially varying material"):
        _load(material.path, sampling="phong")
    with pytest.raises(Exception, match='"exponent", "specular_weight" are parameters of homogeneous networks only'):
        _load(material.path, exponent=10.0, specular_weight=0.5)
    with pytest.raises(Exception, match="the merl BSDF reads MERL .binary tables"):
        mi.load_dict({"type": "merl", "filename": str(material.path)})
