"""Scenes with many distinct networks (issue 31, "Many materials"): the kernel shared by every
network of a shape (``jit_weights`` ``auto`` beyond ``jit.network.AUTO_LITERAL_MAX`` live networks, and
``opaque``) evaluates each network as its own literal kernel does and as the float64 NumPy
oracle and the Rust library do; a scene of distinct networks renders each sphere like the same
network alone; a broken file among many is named."""

from __future__ import annotations

import json

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from nbrdf_testing import f32, nbrdf_reference, random_layers, random_pairs, write_network

NETWORKS = 5


@pytest.fixture
def llvm():
    from conftest import _llvm_problem

    problem = _llvm_problem()
    if problem:
        pytest.skip(problem)
    mi.set_variant("llvm_ad_rgb")
    import nbrdf_mitsuba

    nbrdf_mitsuba.register()


@pytest.fixture
def networks(tmp_path):
    """Distinct networks: random layers of different seeds, each with planted dead units so that
    literal kernels (pruned) and the shared kernel (every unit) trace different code."""
    files = []
    for k in range(NETWORKS):
        layers = random_layers(seed=100 + k)
        layers[0][1][k] = -10.0 - np.abs(layers[0][0][:, k]).sum()  # never fires
        files.append(write_network(tmp_path / f"net{k}.nbrdf.json", layers, name=f"net{k}"))
    return files


@pytest.fixture
def shared_kernel(monkeypatch):
    """``auto`` traces the shared kernel whatever the number of live networks."""
    from nbrdf_mitsuba.jit import network

    monkeypatch.setattr(network, "AUTO_LITERAL_MAX", 0)


def _dispatch_eval(bsdfs, view, light):
    """``eval`` through Mitsuba's symbolic call over every BSDF (lane i: BSDF i mod n), the way a
    scene calls them."""
    n = view.shape[1]
    index = mi.UInt32(np.arange(n) % len(bsdfs))
    pointers = dr.gather(mi.BSDFPtr, mi.BSDFPtr(bsdfs), index)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(np.ascontiguousarray(view, dtype=np.float32))
    value = pointers.eval(mi.BSDFContext(), si, mi.Vector3f(np.ascontiguousarray(light, dtype=np.float32)))
    return np.asarray(value.numpy(), dtype=np.float64).reshape(3, -1)


def test_shared_kernel_equals_each_literal_kernel_the_oracle_and_the_library(llvm, networks, shared_kernel):
    from nbrdf_mitsuba import _native
    from nbrdf_tools.common import network as nbrdf_network

    view, light = random_pairs(4000, 31)
    view, light = f32(view), f32(light)
    auto = [mi.load_dict({"type": "nbrdf", "filename": str(f), "backend": "jit"}) for f in networks]
    opaque = [mi.load_dict({"type": "nbrdf", "filename": str(f), "backend": "jit", "jit_weights": "opaque"})
              for f in networks]
    literal = [mi.load_dict({"type": "nbrdf", "filename": str(f), "backend": "jit", "jit_weights": "literal"})
               for f in networks]
    assert {b._traced.kernel() for b in auto} == {"parameters"}
    assert all(not np.all(b._traced.active[0]) for b in literal)  # the literal kernels are pruned
    shared = _dispatch_eval(auto, view, light)
    np.testing.assert_array_equal(shared, _dispatch_eval(opaque, view, light))
    np.testing.assert_array_equal(shared, _dispatch_eval(literal, view, light))
    lane = np.arange(view.shape[1]) % NETWORKS
    for k, path in enumerate(networks):
        mine = lane == k
        ref = nbrdf_reference(nbrdf_network.read_layers(path), light[:, mine], view[:, mine])
        got = shared[:, mine]
        assert ref.max() > 0
        assert np.all(np.abs(got - ref) <= 1e-5 * (1 + ref)), np.max(np.abs(got - ref) / (1 + ref))
        rust = _native.Material(path).eval(view[:, mine], light[:, mine])
        np.testing.assert_allclose(got, rust, rtol=2e-5, atol=1e-6)


def test_auto_chooses_by_the_number_of_live_networks(llvm, networks, monkeypatch):
    from nbrdf_mitsuba.jit import network

    bsdfs = [mi.load_dict({"type": "nbrdf", "filename": str(f), "backend": "jit"}) for f in networks]
    monkeypatch.setattr(network, "AUTO_LITERAL_MAX", network.live_networks())
    assert {b._traced.kernel() for b in bsdfs} == {"literal"}
    monkeypatch.setattr(network, "AUTO_LITERAL_MAX", network.live_networks() - 1)
    assert {b._traced.kernel() for b in bsdfs} == {"parameters"}
    assert "kernel = parameters" in str(bsdfs[0])
    # Explicit modes are kept whatever the count; only opaque weights are differentiable.
    opaque = mi.load_dict({"type": "nbrdf", "filename": str(networks[0]), "jit_weights": "opaque"})
    literal = mi.load_dict({"type": "nbrdf", "filename": str(networks[0]), "jit_weights": "literal"})
    assert (opaque._traced.kernel(), literal._traced.kernel()) == ("parameters", "literal")
    flags = {name: mi.traverse(b).flags("weights") for name, b in
             (("auto", bsdfs[0]), ("opaque", opaque), ("literal", literal))}
    assert [bool(f & mi.ParamFlags.NonDifferentiable) for f in flags.values()] == [True, False, True]


def test_the_library_gives_the_parameters_without_the_proof(llvm, networks):
    from nbrdf_mitsuba import _native

    material = _native.Material(networks[0])
    layers, active = material.network(prove=False)
    assert active is None
    proved_layers, proved = material.network()
    for (W, b), (W2, b2) in zip(layers, proved_layers, strict=True):
        np.testing.assert_array_equal(W, W2)
        np.testing.assert_array_equal(b, b2)
    assert not proved[0][0]  # the planted dead unit of network 0


def _spheres(bsdfs: list[dict], width: int = 96) -> dict:
    """Spheres in a row under a directional light and a constant environment; ``direct``
    integrator, so a sphere's pixels depend on its own material only."""
    scene = {
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "orthographic",
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 10], target=[0, 0, 0], up=[0, 1, 0])
                   @ mi.ScalarTransform4f().scale([len(bsdfs) * 1.1, 1.1, 1]),
                   "film": {"type": "hdrfilm", "width": width * len(bsdfs) // 2, "height": width // 2,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 4}},
        "environment": {"type": "constant", "radiance": {"type": "rgb", "value": 0.2}},
        "sun": {"type": "directional", "direction": [-1, -1, -2], "irradiance": {"type": "rgb", "value": 2.0}},
    }
    for k, bsdf in enumerate(bsdfs):
        scene[f"sphere{k}"] = {"type": "sphere", "radius": 1.0, "bsdf": bsdf,
                               "center": [2.2 * (k - (len(bsdfs) - 1) / 2), 0.0, 0.0]}
    return scene


def test_a_scene_of_distinct_networks_renders_each_sphere_like_the_network_alone(llvm, networks, shared_kernel):
    from nbrdf_tools.common.render import primary_hit_mask

    black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}}
    networks = networks[:3]  # each sphere alone compiles its own kernel: keep the test small
    scene = mi.load_dict(_spheres([{"type": "nbrdf", "filename": str(f)} for f in networks]))
    together = np.array(mi.render(scene, seed=3), dtype=np.float64)
    assert np.all(np.isfinite(together))
    for k, path in enumerate(networks):
        # The same geometry, only sphere k with its network, as a literal kernel of its own.
        alone_bsdfs = [black] * len(networks)
        alone_bsdfs[k] = {"type": "nbrdf", "filename": str(path), "jit_weights": "literal"}
        alone_scene = mi.load_dict(_spheres(alone_bsdfs))
        alone = np.array(mi.render(alone_scene, seed=3), dtype=np.float64)
        mask = primary_hit_mask(alone_scene, shape_ids=[f"sphere{k}"])
        assert mask.sum() > 100 and alone[mask].mean() > 0
        # Same paths (seed, geometry, sampler); the two kernels evaluate the same values.
        assert np.abs(together[mask] - alone[mask]).max() <= 1e-4 * alone[mask].max(), k
        others = primary_hit_mask(alone_scene, shape_ids=[f"sphere{j}" for j in range(len(networks)) if j != k])
        assert together[others].mean() > 10 * alone[others].mean()  # black there (but edge pixels)


def test_a_broken_file_among_many_is_named(llvm, tmp_path):
    files = [write_network(tmp_path / f"good{k}.nbrdf.json", random_layers(seed=k), name=f"good{k}")
             for k in range(20)]
    broken = tmp_path / "broken13.nbrdf.json"
    document = json.loads(files[13].read_text())
    document["layers"][1]["weights"] = document["layers"][1]["weights"][:-5]  # too few weights
    broken.write_text(json.dumps(document))
    truncated = tmp_path / "truncated7.nbrdf.json"
    truncated.write_text(files[7].read_text()[:500])
    for bad in (broken, truncated):
        scene_files = list(files)
        scene_files[13 if bad is broken else 7] = bad
        scene = _spheres([{"type": "nbrdf", "filename": str(f)} for f in scene_files], width=16)
        with pytest.raises(Exception) as error:
            mi.load_dict(scene)
        message = str(error.value)
        assert str(bad) in message, message
        assert not any(str(f) in message for f in scene_files if f != bad), message


def test_bench_many_quick_json(llvm, tmp_path):
    """The benchmark's CI size: every figure present and finite, the kernel auto chose named."""
    import subprocess
    import sys

    from nbrdf_tools.common.paths import default_cli

    if not default_cli().exists():
        pytest.skip(f"the nbrdf CLI {default_cli()} is not built (make build)")
    out = tmp_path / "bench.json"
    run = subprocess.run([sys.executable, "-m", "nbrdf_tools.bench.many", "--quick", "--no-progress",
                          "--modes", "auto,roughconductor", "--out", str(tmp_path), "--json", str(out)],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    rows = json.loads(out.read_text())["rows"]
    assert [(r["count"], r["mode"]) for r in rows] == [(1, "auto"), (1, "roughconductor"), (4, "auto"),
                                                       (4, "roughconductor")]
    for row in rows:
        for key in ("load_s", "first_render_s", "later_render_s", "later_render_cpu_s", "rss_per_material"):
            assert np.isfinite(row[key]) and row[key] >= 0, (row, key)
        assert row["mean"] > 0
        # The kernel cache starts empty, so the first render compiles, inside its own wall time.
        assert 0 < row["first_compile_s"] <= row["first_render_s"], row
        assert 0 < row["first_codegen_s"] <= row["first_render_s"], row
        assert 0 <= row["first_main_thread_cpu_s"] <= row["first_render_cpu_s"] + 1e-3, row
    for row in rows:
        one = next(r for r in rows if r["count"] == 1 and r["mode"] == row["mode"])
        assert row["first_cpu_vs_one_network"] == pytest.approx(row["first_render_cpu_s"] / one["first_render_cpu_s"])
    auto = [r for r in rows if r["mode"] == "auto"]
    assert all(r["kernel"] == "literal" and r["weights_bytes"] == 4 * 675 for r in auto)
