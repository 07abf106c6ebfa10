"""Fixtures of the end-to-end tests of the Mitsuba plugin (pytest).

* ``variant`` - parametrised over scalar_rgb and llvm_ad_rgb; sets the Mitsuba variant.
* ``jit_variant`` - llvm_ad_rgb and cuda_ad_rgb (the latter skipped, with the reason, without a
  CUDA device); the backend parity tests run in both.
* ``NBRDF_TEST_JIT=cuda`` (environment; ``make test-cuda``) runs every test written for an
  ``llvm_ad_*`` variant in the matching ``cuda_ad_*`` variant instead: ``mi.set_variant`` maps the
  names (test ids keep the llvm names) and the libLLVM check becomes the CUDA check. Tests that run
  the CLI in a subprocess still ask for the llvm variant there.
* ``shared`` - the read-only data directory ``../shared`` next to the repository (or
  $NBRDF_SHARED); tests that need it are skipped, with the reason, when it is absent.
* ``merl_table`` - a MERL-format table synthesised once per session with
  ``target/release/nbrdf synth --model sgd --material gold-metallic-paint`` (or $NBRDF_CLI), or,
  when the CLI is not built, by a NumPy helper tabulating a simple analytic BRDF.
* ``keras_networks`` - a few of the authors' Keras NBRDFs converted by the package's importer.
* ``network_file`` - one network for the tests that need any NBRDF (imported when ../shared is
  there, synthetic otherwise).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import nbrdf_mitsuba  # noqa: F401  (first: points Dr.Jit at a usable libLLVM)
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import nbrdf_testing
from nbrdf_testing import write_merl, write_network
from nbrdf_tools.common.paths import default_cli, shared_dir

SHARED = shared_dir()
JIT_BACKEND = os.environ.get("NBRDF_TEST_JIT", "llvm").strip().lower()
if JIT_BACKEND not in ("llvm", "cuda"):
    raise pytest.UsageError(f"NBRDF_TEST_JIT={JIT_BACKEND!r}: expected llvm or cuda")
KERAS_MATERIALS = ["alum-bronze", "blue-metallic-paint", "specular-black-phenolic", "white-diffuse-bball", "pink-fabric"]
SYNTH_MATERIAL = "gold-metallic-paint"
VARIANTS = ["scalar_rgb", "llvm_ad_rgb"]


def _llvm_problem() -> str | None:
    try:
        return nbrdf_mitsuba.llvm.problem()
    except Exception as error:  # pragma: no cover - defensive
        return str(error)


# (variant, backend): the Rust reference in both variants (wavefront mode in the JIT one) and
# the traced backend in Dr.Jit's default symbolic mode.
CONFIGURATIONS = [("scalar_rgb", "rust"), ("llvm_ad_rgb", "rust"), ("llvm_ad_rgb", "jit")]


def _set_symbolic(enabled: bool) -> None:
    import drjit as dr

    dr.set_flag(dr.JitFlag.SymbolicLoops, enabled)
    dr.set_flag(dr.JitFlag.SymbolicCalls, enabled)


@pytest.fixture(params=CONFIGURATIONS, ids=[f"{v}-{b}" for v, b in CONFIGURATIONS])
def variant(request):
    """Sets each tested Mitsuba variant and BSDF backend in turn; yields the variant name
    (the backend is ``nbrdf_testing.current_backend()``)."""
    name, backend = request.param
    if name.startswith("llvm"):
        problem = _llvm_problem()
        if problem:
            pytest.skip(f"llvm variant unavailable: {problem}")
    mi.set_variant(name)
    previous = nbrdf_mitsuba.set_default_backend(backend)
    nbrdf_testing.CURRENT_BACKEND = backend
    if name.startswith("llvm"):
        _set_symbolic(backend == "jit")
    yield name
    nbrdf_mitsuba.set_default_backend(previous)
    nbrdf_testing.CURRENT_BACKEND = "rust"
    if name.startswith("llvm"):
        _set_symbolic(True)


def _cuda_problem() -> str | None:
    import drjit as dr

    if "cuda_ad_rgb" not in mi.variants():
        return "this Mitsuba build has no cuda_ad_rgb variant"
    if not dr.has_backend(dr.JitBackend.CUDA):
        return "Dr.Jit found no CUDA device and driver on this machine"
    return None


#: The JIT variants the backend parity tests run in: the CUDA one wherever a GPU is present
#: (skipped, with the reason, where there is none).
JIT_VARIANTS = ["llvm_ad_rgb", "cuda_ad_rgb"]


def _variant_run_for(name: str) -> str:
    """The variant a test that asks for ``name`` runs in: its cuda_* twin under NBRDF_TEST_JIT=cuda."""
    if JIT_BACKEND == "cuda" and name.startswith("llvm_"):
        return "cuda_" + name[len("llvm_"):]
    return name


def _redirect_llvm_to_cuda() -> None:
    """The NBRDF_TEST_JIT=cuda mode: every llvm_ad_* variant a test (or the plugin, in process)
    sets becomes its cuda_ad_* twin, and "is the llvm variant usable" asks about CUDA."""
    set_variant = mi.set_variant

    def set_cuda_variant(*names):
        return set_variant(*map(_variant_run_for, names))

    mi.set_variant = set_cuda_variant
    nbrdf_mitsuba.llvm.problem = nbrdf_mitsuba._llvm.problem = _cuda_problem


if JIT_BACKEND == "cuda":
    _redirect_llvm_to_cuda()


def _use_jit_variant(name: str):
    """Sets a JIT variant in symbolic mode for one test (skipped, naming the reason, where the
    variant cannot run) and puts symbolic mode back after it."""
    problem = _llvm_problem() if name.startswith("llvm") else _cuda_problem()
    if problem:
        pytest.skip(f"{_variant_run_for(name)} unavailable: {problem}")
    mi.set_variant(name)
    _set_symbolic(True)
    yield name
    _set_symbolic(True)  # a rust-backed BSDF switches wavefront mode on


@pytest.fixture
def llvm_variant():
    """Only the llvm_ad_rgb variant (for tests that need vectorised Mitsuba machinery)."""
    yield from _use_jit_variant("llvm_ad_rgb")


@pytest.fixture(params=JIT_VARIANTS)
def jit_variant(request):
    """Each JIT variant in turn (symbolic mode), for the parity of the traced and Rust backends."""
    yield from _use_jit_variant(request.param)


@pytest.fixture(scope="session")
def shared() -> Path:
    if not SHARED.is_dir():
        pytest.skip(f"shared data directory {SHARED} is absent (set NBRDF_SHARED to its location)")
    return SHARED


def _cli() -> Path | None:
    """The nbrdf CLI ($NBRDF_CLI, else target/release/nbrdf), or None when it is not built."""
    exe = default_cli()
    return exe if exe.is_file() else None


@pytest.fixture(scope="session")
def merl_table(tmp_path_factory) -> Path:
    """Path of a synthesised MERL-format table (SGD fit via the CLI, else a NumPy BRDF)."""
    out = tmp_path_factory.mktemp("merl") / f"{SYNTH_MATERIAL}.binary"
    cli = _cli()
    if cli is not None:
        subprocess.run([str(cli), "synth", "--model", "sgd", "--material", SYNTH_MATERIAL, "-o", str(out)],
                       check=True, capture_output=True)
    else:
        write_merl(out, analytic=True)
    return out


@pytest.fixture(scope="session")
def keras_networks(shared, tmp_path_factory) -> list[tuple[Path, Path]]:
    """(Keras .h5, imported .nbrdf.json) for a few MERL materials, through the CLI entry point."""
    from nbrdf_mitsuba import import_keras

    source = shared / "data" / "reference-nbrdf" / "merl"
    out = tmp_path_factory.mktemp("keras")
    pairs = []
    for name in KERAS_MATERIALS:
        h5 = source / f"{name}.h5"
        target = out / f"{name}.nbrdf.json"
        assert import_keras.main([str(h5), "-o", str(target), "-q"]) == 0
        pairs.append((h5, target))
    return pairs


@pytest.fixture(scope="session")
def network_file(tmp_path_factory) -> Path:
    """One network without stored sampling parameters: an imported Keras NBRDF when ../shared is
    present, else a small synthetic network (so that only the Keras parity tests need ../shared)."""
    out = tmp_path_factory.mktemp("network")
    h5 = SHARED / "data" / "reference-nbrdf" / "merl" / "blue-metallic-paint.h5"
    if h5.is_file():
        from nbrdf_mitsuba import import_keras

        target = out / "blue-metallic-paint.nbrdf.json"
        assert import_keras.main([str(h5), "-o", str(target), "-q"]) == 0
        return target
    return write_network(out / "synthetic.nbrdf.json")


@pytest.fixture
def restore_variant():
    """Gives the test's caller its Mitsuba variant back (tests here switch between variants)."""
    previous = mi.variant()
    yield
    if previous:
        mi.set_variant(previous)


def use_variant(variant: str) -> None:
    """Sets ``variant``, skipping (with the reason) where this Mitsuba or its libLLVM lacks it."""
    if _variant_run_for(variant) not in mi.variants():
        pytest.skip(f"the installed Mitsuba has no {variant} variant")
    if variant.startswith("llvm"):
        problem = nbrdf_mitsuba.llvm.problem()
        if problem:
            pytest.skip(f"llvm variant unavailable: {problem}")
    mi.set_variant(variant)


def bsdf_calls(bsdf, view, light, u, wavelengths=None, uv=None) -> dict:
    """eval, pdf, eval_pdf and sample of ``bsdf`` at the columns of ``view``/``light``/``u`` (and
    ``wavelengths``: 4 per column, read in spectral variants only; ``uv``: the hits' texture
    coordinates, 0 without), as float64 NumPy arrays whose last axis runs over the columns
    (scalar variants: one call per column)."""
    ctx = mi.BSDFContext()
    if wavelengths is None:
        wavelengths = np.full((4, view.shape[1]), 550.0)
    if uv is None:
        uv = np.zeros((2, view.shape[1]))

    def one(v, l, s, w, t):
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wi = mi.Vector3f(*v)
        si.uv = mi.Point2f(*t)
        if mi.is_spectral:
            si.wavelengths = mi.UnpolarizedSpectrum(*w)
        wo = mi.Vector3f(*l)
        value, pdf = bsdf.eval_pdf(ctx, si, wo)
        bs, weight = bsdf.sample(ctx, si, mi.Float(s[0]), mi.Point2f(s[1], s[2]))
        return {"eval": bsdf.eval(ctx, si, wo), "pdf": bsdf.pdf(ctx, si, wo), "eval_pdf.value": value,
                "eval_pdf.pdf": pdf, "sample.wo": bs.wo, "sample.pdf": bs.pdf, "sample.weight": weight}

    columns = (view, light, u, wavelengths, uv)
    if dr.is_jit_v(mi.Float):
        out = one(*([mi.Float(r) for r in a] for a in columns))
        return {k: np.asarray(v.numpy(), np.float64) for k, v in out.items()}
    rows = [one(*(list(map(float, a[:, i])) for a in columns)) for i in range(view.shape[1])]
    return {k: np.stack([np.asarray(r[k], np.float64) for r in rows], axis=-1) for k in rows[0]}
