"""The BSDFs are RGB-only (docs/mitsuba.md): in a spectral, monochrome or polarised variant of the
installed Mitsuba, loading `nbrdf` or `merl` fails with one clear message that names the variant
and the variants to use, instead of rendering wrong colours."""

from __future__ import annotations

import nbrdf_mitsuba  # noqa: F401  (before mitsuba)
import mitsuba as mi
import pytest

from nbrdf_testing import write_merl, write_network

# Variants that are not RGB (Mitsuba 3.9's wheels ship scalar_spectral, llvm_ad_mono, ...).
NON_RGB = ["scalar_spectral", "scalar_spectral_polarized", "llvm_ad_spectral", "llvm_ad_mono"]


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("variants")
    return {"nbrdf": write_network(folder / "n.nbrdf.json"), "merl": write_merl(folder / "m.binary")}


@pytest.fixture
def restore_variant():
    previous = mi.variant()
    yield
    if previous:
        mi.set_variant(previous)


@pytest.mark.parametrize("variant", NON_RGB)
@pytest.mark.parametrize("plugin", ["nbrdf", "merl"])
def test_non_rgb_variants_are_refused_clearly(variant, plugin, files, restore_variant):
    if variant not in mi.variants():
        pytest.skip(f"the installed Mitsuba has no {variant} variant")
    if variant.startswith("llvm"):
        problem = nbrdf_mitsuba.llvm.problem()
        if problem:
            pytest.skip(f"llvm variant unavailable: {problem}")
    mi.set_variant(variant)
    with pytest.raises(RuntimeError) as error:
        mi.load_dict({"type": plugin, "filename": str(files[plugin])})
    message = str(error.value)
    assert f'(plugin "{plugin}"): only RGB variants are supported' in message
    assert f"the current variant is {variant};" in message and "scalar_rgb or llvm_ad_rgb" in message


def test_rgb_variant_loads(files, restore_variant):
    """The same files load in scalar_rgb (the refusal above is about the variant, not the file)."""
    mi.set_variant("scalar_rgb")
    assert "NbrdfBSDF" in str(mi.load_dict({"type": "nbrdf", "filename": str(files["nbrdf"])}))
    assert "MerlBSDF" in str(mi.load_dict({"type": "merl", "filename": str(files["merl"])}))


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
