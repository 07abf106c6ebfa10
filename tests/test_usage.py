"""Using the plugins as a Mitsuba user would: XML and dictionaries, scenes and renders, scene
parameters, error messages, registration across variants."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import nbrdf_mitsuba
from nbrdf_testing import bsdf_pdf, f32, phong_pdf, random_pairs, read_merl, write_merl


def xml_bsdf(plugin: str, filename, extra: str = "") -> str:
    return (f'<bsdf version="3.0.0" type="{plugin}"><string name="filename" value="{filename}"/>'
            f"{extra}</bsdf>")


def test_xml_and_dict_give_the_same_bsdf(variant, network_file, merl_table):
    from_xml = mi.load_string(xml_bsdf("nbrdf", network_file, '<string name="sampling" value="uniform"/>'))
    from_dict = mi.load_dict({"type": "nbrdf", "filename": str(network_file), "sampling": "uniform"})
    assert str(from_xml) == str(from_dict)
    assert str(from_xml).startswith("NbrdfBSDF[") and "sampling = uniform" in str(from_xml)
    merl = mi.load_string(xml_bsdf("merl", merl_table, '<string name="sampling" value="phong"/>'
                                   '<float name="exponent" value="30"/><float name="specular_weight" value="0.25"/>'))
    text = str(merl)
    assert text.startswith("MerlBSDF[") and "exponent = 30" in text and "specular_weight = 0.25" in text
    assert merl_table.name in text


def test_network_with_stored_sampling_defaults_to_phong(variant, network_file, tmp_path):
    document = json.loads(network_file.read_text())
    document["sampling"] = {"model": "blinn-phong", "exponent": 210.0, "specular_weight": 0.31, "source": "fit"}
    path = tmp_path / "with-sampling.nbrdf.json"
    path.write_text(json.dumps(document))
    text = str(mi.load_dict({"type": "nbrdf", "filename": str(path)}))
    assert "sampling = phong" in text and "exponent = 210" in text and "specular_weight = 0.31" in text
    # Overrides win over the stored parameters.
    text = str(mi.load_dict({"type": "nbrdf", "filename": str(path), "exponent": 12.0}))
    assert "exponent = 12" in text and "specular_weight = 0.31" in text
    text = str(mi.load_dict({"type": "nbrdf", "filename": str(path), "sampling": "cosine"}))
    assert "sampling = cosine" in text and "exponent" not in text


def scene_dict(bsdf: dict, integrator: str) -> dict:
    integrator_dict = {"type": integrator}
    if integrator == "path":
        integrator_dict["max_depth"] = 4
    return {
        "type": "scene",
        "integrator": integrator_dict,
        "sensor": {
            "type": "perspective", "fov": 45,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, -2.5, 2.0], target=[0, 0, 0.2], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": 10, "height": 8, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": 4},
        },
        "floor": {"type": "rectangle", "bsdf": bsdf},
        "ball": {"type": "sphere", "center": [0, 0, 0.5], "radius": 0.4, "bsdf": bsdf},
        "light": {"type": "point", "position": [1.0, -1.0, 3.0], "intensity": {"type": "rgb", "value": 8.0}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.2}},
    }


def test_loading_a_network_reads_the_file_once_in_the_library(variant, network_file, monkeypatch):
    """The plugin takes the parsed, validated and pruned network from the C library: its own load
    path opens no file (the library's read does not go through Python)."""
    import builtins
    import io

    opened = []
    real_open = builtins.open

    def spy(file, *args, **kwargs):
        opened.append(str(file))
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", spy)
    monkeypatch.setattr(io, "open", spy)
    for backend in ("rust", "jit") if mi.variant().startswith(("llvm", "cuda")) else ("rust",):
        bsdf = mi.load_dict({"type": "nbrdf", "filename": str(network_file), "backend": backend})
        assert bsdf is not None
    assert not [path for path in opened if path.endswith(network_file.name)], opened


@pytest.mark.parametrize("integrator", ["direct", "path"])
def test_tiny_scene_renders(variant, integrator, network_file, merl_table):
    for bsdf in ({"type": "nbrdf", "filename": str(network_file)},
                 {"type": "merl", "filename": str(merl_table), "sampling": "phong", "exponent": 40.0,
                  "specular_weight": 0.5}):
        scene = mi.load_dict(scene_dict(bsdf, integrator))
        image = np.asarray(mi.render(scene, seed=1))
        assert image.shape == (8, 10, 3)
        assert np.all(np.isfinite(image)), f"{bsdf['type']}/{integrator}: NaN or inf in the image"
        assert image.mean() > 0.01


def test_scene_file_with_relative_paths(variant, network_file, merl_table, tmp_path):
    """An XML scene, loaded by Mitsuba's (parallel) loader, finds the files next to it; the
    render runs on this thread."""
    (tmp_path / "net.nbrdf.json").write_bytes(network_file.read_bytes())
    (tmp_path / "table.binary").symlink_to(merl_table)
    (tmp_path / "scene.xml").write_text("""<scene version="3.0.0">
        <integrator type="path"><integer name="max_depth" value="3"/></integrator>
        <sensor type="perspective">
            <transform name="to_world"><lookat origin="0, -2.5, 2" target="0, 0, 0" up="0, 0, 1"/></transform>
            <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/></film>
            <sampler type="independent"><integer name="sample_count" value="2"/></sampler>
        </sensor>
        <shape type="rectangle"><bsdf type="nbrdf"><string name="filename" value="net.nbrdf.json"/></bsdf></shape>
        <shape type="sphere"><point name="center" value="0, 0, 0.5"/><float name="radius" value="0.4"/>
            <bsdf type="merl"><string name="filename" value="table.binary"/></bsdf></shape>
        <emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
    </scene>""")
    scene = mi.load_file(str(tmp_path / "scene.xml"))
    image = np.asarray(mi.render(scene))
    assert np.all(np.isfinite(image)) and image.mean() > 0.01


def test_scene_parameters_update_the_sampler(variant, merl_table):
    bsdf = mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "phong", "exponent": 20.0,
                         "specular_weight": 0.5})
    params = mi.traverse(bsdf)
    assert {"exponent", "specular_weight"} <= set(params.keys())
    assert params.flags("exponent") & int(mi.ParamFlags.NonDifferentiable)
    params["exponent"] = 80.0
    params["specular_weight"] = 0.9
    params.update()
    assert "exponent = 80" in str(bsdf) and "specular_weight = 0.9" in str(bsdf)
    view, light = (f32(a) for a in random_pairs(6, 2))
    np.testing.assert_allclose(bsdf_pdf(bsdf, view, light), phong_pdf(view, light, 80.0, 0.9), rtol=1e-4, atol=1e-7)
    params["specular_weight"] = 1.5
    with pytest.raises(Exception, match="invalid sampling parameters"):
        params.update()
    assert "specular_weight = 0.9" in str(bsdf)  # the previous sampler stays in use


# ---------------------------------------------------------------------------------------------
# Errors


def load_error(params: dict) -> str:
    with pytest.raises(Exception) as info:
        mi.load_dict(params)
    return str(info.value)


def test_missing_files_name_the_plugin_and_the_file(variant, tmp_path):
    for plugin, cls, name in (("nbrdf", "NbrdfBSDF", "absent.nbrdf.json"), ("merl", "MerlBSDF", "absent.binary")):
        message = load_error({"type": plugin, "filename": str(tmp_path / name)})
        assert cls in message and f'plugin "{plugin}"' in message and name in message, message
        assert "NBRDF_ERROR_IO" in message, message
    message = load_error({"type": "merl"})
    assert '"filename" parameter is required' in message and "MerlBSDF" in message


def test_bad_merl_files(variant, merl_table, tmp_path):
    good = merl_table.read_bytes()
    truncated = tmp_path / "truncated.binary"
    truncated.write_bytes(good[: len(good) // 3])
    header = tmp_path / "header.binary"
    header.write_bytes(np.array([90, 90, 90], "<i4").tobytes() + good[12:])
    stored = read_merl(merl_table).copy()
    stored[2, 10, 10, 10] = np.nan
    nan = write_merl(tmp_path / "nan.binary", stored)
    empty = tmp_path / "empty.binary"
    empty.write_bytes(b"")
    for path in (truncated, header, nan, empty):
        message = load_error({"type": "merl", "filename": str(path)})
        assert "MerlBSDF" in message and path.name in message and "NBRDF_ERROR_FORMAT" in message, message


def test_bad_network_files(variant, network_file, tmp_path):
    text = network_file.read_text()
    truncated = tmp_path / "truncated.nbrdf.json"
    truncated.write_text(text[: len(text) // 2])
    document = json.loads(text)
    document["layers"][1]["weights"] = document["layers"][1]["weights"][:-1]
    shapes = tmp_path / "shapes.nbrdf.json"
    shapes.write_text(json.dumps(document))
    document = json.loads(text)
    document["format"] = "keras"
    wrong_format = tmp_path / "format.nbrdf.json"
    wrong_format.write_text(json.dumps(document))
    binary = tmp_path / "binary.nbrdf.json"
    binary.write_bytes(b"\x00\xff\x10garbage")
    for path in (truncated, shapes, wrong_format, binary):
        message = load_error({"type": "nbrdf", "filename": str(path)})
        assert "NbrdfBSDF" in message and path.name in message and "NBRDF_ERROR_FORMAT" in message, message


def test_bad_sampling_parameters(variant, network_file, merl_table):
    for plugin, filename in (("nbrdf", network_file), ("merl", merl_table)):
        message = load_error({"type": plugin, "filename": str(filename), "sampling": "ggx"})
        assert 'unknown sampling "ggx"' in message, message
        assert filename.name in message and plugin in message
        assert re.search(r"uniform.*cosine.*phong", message), message
        message = load_error({"type": plugin, "filename": str(filename), "sampling": "phong", "exponent": -3.0,
                              "specular_weight": 0.5})
        assert "invalid sampling parameters" in message and filename.name in message, message
        message = load_error({"type": plugin, "filename": str(filename), "sampling": "phong", "exponent": 10.0,
                              "specular_weight": 1.5})
        assert "invalid sampling parameters" in message, message
        message = load_error({"type": plugin, "filename": str(filename), "exponent": "big", "specular_weight": 0.5})
        assert '"exponent" must be a number' in message, message
    message = load_error({"type": "merl", "filename": str(merl_table), "sampling": "phong"})
    assert 'sampling "phong" needs "exponent" and "specular_weight"' in message
    # Sampling names are case-insensitive.
    assert "sampling = cosine" in str(mi.load_dict({"type": "merl", "filename": str(merl_table), "sampling": "Cosine"}))


# ---------------------------------------------------------------------------------------------
# Registration, wavefront mode, LLVM discovery, the native layer


def test_register_is_idempotent_across_variants(network_file):
    for name in ("scalar_rgb", "llvm_ad_rgb", "scalar_rgb"):
        if name.startswith("llvm") and nbrdf_mitsuba.llvm.problem():
            continue
        mi.set_variant(name)
        assert nbrdf_mitsuba.register() is True
        assert nbrdf_mitsuba.register() is True
        bsdf = mi.load_dict({"type": "nbrdf", "filename": str(network_file)})
        assert type(bsdf).__name__ == "NbrdfBSDF" and isinstance(bsdf, mi.BSDF)


def test_constructing_either_backend_leaves_dr_jit_flags_alone(llvm_variant, network_file, merl_table):
    """Flags are per thread and plugins are built on worker threads: switching them at
    construction would help only sometimes (issue 16), so neither backend touches them."""
    for plugin, path in (("nbrdf", network_file), ("merl", merl_table)):
        bsdf = mi.load_dict({"type": plugin, "filename": str(path)})
        assert "backend = jit" in str(bsdf)
        mi.load_dict({"type": plugin, "filename": str(path), "backend": "rust"})
        assert dr.flag(dr.JitFlag.SymbolicLoops) and dr.flag(dr.JitFlag.SymbolicCalls)


def test_scene_with_builtin_bsdfs_renders_in_symbolic_mode(llvm_variant, network_file, merl_table):
    """The default (traced) backend needs no Dr.Jit flag: symbolic loops and calls stay on."""
    assert dr.flag(dr.JitFlag.SymbolicLoops) and dr.flag(dr.JitFlag.SymbolicCalls)
    for integrator in ("direct", "path"):
        description = scene_dict({"type": "nbrdf", "filename": str(network_file)}, integrator)
        description["floor"]["bsdf"] = {"type": "roughconductor", "alpha": 0.2}
        description["merl_ball"] = {"type": "sphere", "center": [0.6, 0, 0.3], "radius": 0.2,
                                    "bsdf": {"type": "merl", "filename": str(merl_table)}}
        image = np.array(mi.render(mi.load_dict(description), spp=4))
        assert np.all(np.isfinite(image)) and image.max() > 0
    assert dr.flag(dr.JitFlag.SymbolicLoops) and dr.flag(dr.JitFlag.SymbolicCalls)


def test_unknown_backend_and_jit_in_scalar_are_errors(network_file):
    mi.set_variant("scalar_rgb")
    with pytest.raises(Exception, match="unknown backend"):
        mi.load_dict({"type": "nbrdf", "filename": str(network_file), "backend": "gpu"})
    with pytest.raises(Exception, match="needs a JIT variant"):
        mi.load_dict({"type": "nbrdf", "filename": str(network_file), "backend": "jit"})


def test_rust_backend_in_symbolic_mode_uses_its_traced_twin(llvm_variant, network_file):
    """Inside a symbolic scope the library cannot run; the rust-backed BSDF evaluates its traced
    twin there (tests/test_hardening_plugin.py compares it with the wavefront render)."""
    scene = mi.load_dict(scene_dict({"type": "nbrdf", "filename": str(network_file), "backend": "rust"}, "path"))
    assert dr.flag(dr.JitFlag.SymbolicLoops) and dr.flag(dr.JitFlag.SymbolicCalls)
    image = np.array(mi.render(scene, spp=4))
    assert np.all(np.isfinite(image)) and image.max() > 0


def test_bundled_header_matches_the_repository():
    """A stale installed package (rebuilt library, old header) would mis-declare functions."""
    from pathlib import Path

    from nbrdf_mitsuba import _native

    repo_header = Path(__file__).resolve().parents[1] / "nbrdf-ffi" / "include" / "nbrdf.h"
    assert _native.header_path().read_text() == repo_header.read_text(), (
        "the installed nbrdf_mitsuba is out of date: reinstall with `pip install ./mitsuba-plugin`")


def test_native_layer_errors(tmp_path):
    from nbrdf_mitsuba import _native

    with pytest.raises(_native.NbrdfError) as info:
        _native.Material(tmp_path / "nothing.nbrdf.json")
    assert info.value.status_name == "NBRDF_ERROR_IO" and "nothing.nbrdf.json" in str(info.value)
    with pytest.raises(_native.NbrdfError) as info:
        _native.Sampler("phong", float("nan"), 0.5)
    assert info.value.status_name == "NBRDF_ERROR_INVALID_ARGUMENT"
    with pytest.raises(ValueError, match="unknown sampling strategy"):
        _native.Sampler("ggx")
    assert re.fullmatch(r"\d+\.\d+\.\d+.*", _native.version())
    s = _native.Sampler("cosine")
    np.testing.assert_allclose(s.pdf(np.array([0.0, 0, 1]), np.array([0.0, 0, 1])), [1 / np.pi], rtol=1e-6)
    with pytest.raises(ValueError, match="differ in shape"):
        s.pdf(np.zeros((3, 2)), np.zeros((3, 3)))


def test_native_layer_takes_the_vocabulary_from_the_library():
    """The strategy names and codes, and the material kinds, come from the library (its header's
    enums and nbrdf_sampling_kind_name), not from a Python table: the canonical vocabulary."""
    from nbrdf_mitsuba import _native, jit

    names = ["uniform", "cosine", "phong", "two_lobe", "tabulated", "anisotropic_phong"]
    assert _native.SAMPLING_KINDS == {name: code for code, name in enumerate(names)}
    assert _native.MATERIAL_KINDS == {"network": 0, "merl": 1, "textured": 2}
    assert set(jit.STRATEGIES) == set(names)
    assert _native.STATUS_NAMES[2] == "NBRDF_ERROR_INVALID_ARGUMENT"


def test_strip_preprocessor_keeps_declarations_only():
    from nbrdf_mitsuba._native import header_path, strip_preprocessor

    text = strip_preprocessor(header_path().read_text())
    assert "#" not in re.sub(r"//.*|/\*.*?\*/", "", text, flags=re.S)
    assert 'extern "C"' not in text
    assert "int32_t nbrdf_material_eval(" in text
    nested = "#ifdef __cplusplus\n#if X\nint bad;\n#endif\nint bad2;\n#endif\nint good;"
    assert strip_preprocessor(nested).split() == ["int", "good;"]


def test_missing_native_library_warns_on_set_variant_and_raises_on_register(tmp_path):
    code = ("import warnings; warnings.simplefilter('always')\n"
            "import nbrdf_mitsuba, mitsuba as mi\n"
            "mi.set_variant('scalar_rgb')\n"
            "print('set_variant ok')\n"
            "nbrdf_mitsuba.register()\n")
    missing = tmp_path / "libnbrdf_ffi.so"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                            env={**os.environ, "NBRDF_LIBRARY": str(missing)})
    assert "set_variant ok" in result.stdout
    assert "could not register the nbrdf/merl BSDFs" in result.stderr
    assert result.returncode != 0 and f"native library {missing} is missing" in result.stderr
