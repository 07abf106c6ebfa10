"""``python -m nbrdf_mitsuba``: the front door lists and runs every command of the package, and
every command follows one exit-status policy: 0 done (``--help`` too), 2 for a usage or input
error (a bad flag, a missing file) with ``error: ...`` on stderr, 1 where the work itself failed.

Each case runs ``python -m nbrdf_mitsuba NAME`` in a subprocess. The failed work of a render, an
import and the libLLVM check is cheap here; that of a training and of an estimate needs the work
to fail midway, and is tested in-process (tests/test_distill.py, tests/test_estimate.py)."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nbrdf_mitsuba.__main__ import COMMANDS

PACKAGE = Path(__file__).resolve().parents[1] / "mitsuba-plugin" / "nbrdf_mitsuba"
#: Per command, arguments naming an input file that does not exist (none for ``llvm``).
MISSING_INPUT = {
    "render": ["missing.xml"],
    "import-keras": ["missing.h5", "-o", "out.nbrdf.json"],
    "tabulate-rgl": ["missing.bsdf"],
    "distill": ["missing.json", "-o", "out.nbrdf.json"],
    "estimate": ["missing.xml", "--images", "view.exr", "--bsdf-id", "mat", "-o", "out.json"],
}
TINY_SCENE = """<scene version="3.0.0">
    <integrator type="path"/>
    <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/>
        <integer name="height" value="4"/></film></sensor>
    <shape type="sphere"><transform name="to_world"><translate z="4"/></transform></shape>
    <emitter type="constant"/>
</scene>"""


def run(*args, cwd: Path | None = None, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "nbrdf_mitsuba", *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=cwd, env=None if env is None else {**os.environ, **env})


def error_lines(result: subprocess.CompletedProcess) -> list[str]:
    assert "Traceback" not in result.stderr, result.stderr
    return [line for line in result.stderr.splitlines() if "error: " in line]


def runnable_modules() -> set[str]:
    """The package's public modules that ``python -m`` runs: a ``__main__`` guard, or a package
    with a ``__main__.py``."""
    names = set()
    for path in PACKAGE.iterdir():
        if path.name.startswith("_"):
            continue
        if path.is_dir() and (path / "__main__.py").is_file():
            names.add(f"nbrdf_mitsuba.{path.name}")
        elif path.suffix == ".py" and any(
                isinstance(node, ast.If) and "__main__" in ast.unparse(node.test)
                for node in ast.parse(path.read_text()).body):
            names.add(f"nbrdf_mitsuba.{path.stem}")
    return names


def test_the_front_door_lists_every_command():
    import nbrdf_mitsuba.__main__ as front

    assert {module for module, _ in COMMANDS.values()} == runnable_modules()
    listing = run("--help")
    assert listing.returncode == 0, listing.stderr
    for name in COMMANDS:
        assert f"\n  {name} " in listing.stdout and f"\n    {name} " in front.__doc__, name


def test_no_command_and_an_unknown_one_are_usage_errors():
    for args, needle in (((), "no command given"), (("paint",), "unknown command 'paint'")):
        result = run(*args)
        assert result.returncode == 2 and needle in error_lines(result)[0], result.stderr


@pytest.mark.parametrize("name", COMMANDS)
def test_help_exits_0(name):
    result = run(name, "--help")
    assert result.returncode == 0 and "usage:" in result.stdout, result.stderr


@pytest.mark.parametrize("name", COMMANDS)
def test_a_bad_flag_exits_2(name):
    result = run(name, "--no-such-flag")
    assert result.returncode == 2 and error_lines(result), result.stderr


@pytest.mark.parametrize("name", MISSING_INPUT)
def test_a_missing_input_file_exits_2_naming_it(name, tmp_path):
    args = MISSING_INPUT[name]
    result = run(name, *args, cwd=tmp_path)
    errors = error_lines(result)
    assert result.returncode == 2 and len(errors) == 1 and args[0] in errors[0], result.stderr
    assert not list(tmp_path.iterdir())  # nothing written


def test_a_render_whose_image_cannot_be_written_is_failed_work(tmp_path):
    scene = tmp_path / "tiny.xml"
    scene.write_text(TINY_SCENE)
    (tmp_path / "file").write_text("a file, not a folder")
    result = run("render", scene, "-m", "scalar_rgb", "--spp", "1", "--no-progress", "-o", tmp_path / "file" / "out.exr")
    errors = error_lines(result)
    assert result.returncode == 1 and len(errors) == 1 and "cannot write" in errors[0], result.stderr


def test_an_import_whose_network_cannot_be_written_is_failed_work(tmp_path):
    h5py = pytest.importorskip("h5py")
    source = tmp_path / "plain.h5"
    with h5py.File(source, "w") as f:
        for k, (n_in, n_out) in enumerate([(6, 21), (21, 21), (21, 3)], start=1):
            f[f"dense_{k}/dense_{k}/kernel:0"] = np.zeros((n_in, n_out), np.float32)
            f[f"dense_{k}/dense_{k}/bias:0"] = np.zeros(n_out, np.float32)
    (tmp_path / "file").write_text("a file, not a folder")
    result = run("import-keras", source, "-o", tmp_path / "file" / "plain.nbrdf.json")
    assert result.returncode == 1 and len(error_lines(result)) == 1, result.stderr


def test_llvm_without_a_usable_libllvm_is_failed_work():
    result = run("llvm", "--quiet", env={"DRJIT_LIBLLVM_PATH": "/nonexistent/libLLVM.so"})
    assert result.returncode == 1 and "LLVM backend" in error_lines(result)[0], result.stderr
