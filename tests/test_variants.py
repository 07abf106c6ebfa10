"""Variants (issue 31): the BSDFs load and render in Mitsuba's RGB, monochrome, spectral and
polarized variants. Values in the monochrome and polarized variants are checked here against the
same BSDF evaluated in the RGB variant, converted with Mitsuba's definitions written out here;
spectral values against an independent uplift in tests/test_spectral.py."""

from __future__ import annotations

import nbrdf_mitsuba  # noqa: F401  (before mitsuba)
import mitsuba as mi
import numpy as np
import pytest

from conftest import bsdf_calls, use_variant
from nbrdf_testing import random_pairs, write_merl, write_network

SPECTRAL = ["scalar_spectral", "scalar_spectral_polarized", "llvm_ad_spectral", "llvm_ad_spectral_polarized"]
# Those the installed wheel lacks are skipped (Mitsuba 3.9's wheels ship llvm_ad_mono and
# llvm_ad_mono_polarized, but no scalar_mono or *_rgb_polarized).
OTHER = ["scalar_mono", "llvm_ad_mono", "scalar_rgb_polarized", "llvm_ad_rgb_polarized", "llvm_ad_mono_polarized"]
# Mitsuba's luminance(Color3f) (include/mitsuba/core/spectrum.h): the CIE Y row of linear
# Rec. 709 RGB, what Mitsuba's monochrome variants make of RGB data.
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])
PHONG = {"sampling": "phong", "exponent": 40.0, "specular_weight": 0.6}
N = 64


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("variants")
    return {"nbrdf": write_network(folder / "n.nbrdf.json"), "merl": write_merl(folder / "m.binary")}


def test_rgb_variant_loads(files, restore_variant):
    """The same files load in scalar_rgb."""
    mi.set_variant("scalar_rgb")
    assert "NbrdfBSDF" in str(mi.load_dict({"type": "nbrdf", "filename": str(files["nbrdf"])}))
    assert "MerlBSDF" in str(mi.load_dict({"type": "merl", "filename": str(files["merl"])}))


def _queries():
    view, light = random_pairs(N, 31)
    u = np.random.default_rng(32).random((3, N))
    return view.astype(np.float32), light.astype(np.float32), u.astype(np.float32)


@pytest.mark.parametrize("backend", ["rust", "jit"])
@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
@pytest.mark.parametrize("variant", OTHER)
def test_values_follow_the_rgb_variant(variant, plugin, backend, files, restore_variant):
    """Monochrome: the luminance of the RGB value; polarized: the depolarizer, i.e. the
    (unpolarized) value at [0, 0] and zero elsewhere; pdfs and sampled directions unchanged."""
    use_variant(variant)
    if backend == "jit" and variant.startswith("scalar"):
        pytest.skip("the jit backend needs a JIT variant")
    scene = {"type": plugin, "filename": str(files[plugin]), "backend": backend, **PHONG}
    view, light, u = _queries()
    got = bsdf_calls(mi.load_dict(scene), view, light, u)
    mi.set_variant("scalar_rgb" if variant.startswith("scalar") else "llvm_ad_rgb")
    rgb = bsdf_calls(mi.load_dict(scene), view, light, u)
    assert np.max(rgb["eval"]) > 0 and np.max(rgb["sample.weight"]) > 0  # something to compare

    for key, value in got.items():
        assert np.all(np.isfinite(value)), key
    for key in ("pdf", "eval_pdf.pdf", "sample.wo", "sample.pdf"):
        np.testing.assert_allclose(got[key], rgb[key], rtol=1e-6, atol=1e-7, err_msg=key)
    for key in ("eval", "eval_pdf.value", "sample.weight"):
        value, expected = got[key], rgb[key]
        if "polarized" in variant:
            assert value.shape[:2] == (4, 4), key
            off_diagonal = value.copy()
            off_diagonal[0, 0] = 0.0
            assert np.all(off_diagonal == 0.0), key
            value = value[0, 0]
        if "mono" in variant:
            expected = (LUMINANCE @ expected)[None]
        assert value.shape == expected.shape, key
        np.testing.assert_allclose(value, expected, rtol=1e-5, atol=1e-7, err_msg=key)


@pytest.mark.parametrize("variant", OTHER + SPECTRAL)
@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
def test_tiny_render_has_no_nan(variant, plugin, files, restore_variant):
    use_variant(variant)
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8},
                   "sampler": {"type": "independent", "sample_count": 4}},
        "light": {"type": "constant"},
        "sphere": {"type": "sphere", "bsdf": {"type": plugin, "filename": str(files[plugin])}},
    })
    image = np.asarray(mi.render(scene))
    assert np.all(np.isfinite(image)) and image.max() > 0


# Run in a fresh process: the note is said once per process, and this one may have said it.
SCALAR_NOTE_SCRIPT = r"""
import sys
import nbrdf_mitsuba
import mitsuba as mi

class Recorder(mi.Appender):
    def __init__(self):
        super().__init__()
        self.lines = []
    def append(self, level, text):
        self.lines.append((level, text))
    def log_progress(self, *args):
        pass

network, table, with_llvm = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
recorder = Recorder()
mi.logger().clear_appenders()  # Mitsuba's own appender would print to stdout too
mi.logger().add_appender(recorder)
said = lambda: [(level, text) for level, text in recorder.lines if "once per direction" in text]
if with_llvm:
    mi.set_variant("llvm_ad_rgb")
    mi.load_dict({"type": "nbrdf", "filename": network})
    print("llvm", len(said()))
mi.set_variant("scalar_rgb")
for _ in range(2):
    mi.load_dict({"type": "nbrdf", "filename": network})
    mi.load_dict({"type": "merl", "filename": table})
print("scalar", len(said()), said()[0][0] == mi.LogLevel.Warn, "in scalar_rgb" in said()[0][1])
"""


def test_scalar_variants_say_their_cost_once(files):
    """A scalar variant evaluates the BSDFs one direction per call through Python: the plugin
    says so with one warning per process, not per BSDF, and says nothing in llvm_ad_rgb."""
    import subprocess
    import sys

    with_llvm = nbrdf_mitsuba.llvm.problem() is None and "llvm_ad_rgb" in mi.variants()
    result = subprocess.run([sys.executable, "-c", SCALAR_NOTE_SCRIPT, str(files["nbrdf"]), str(files["merl"]),
                             "1" if with_llvm else "0"], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    if with_llvm:
        assert "llvm 0" in lines
    assert "scalar 1 True True" in lines, result.stdout + result.stderr
