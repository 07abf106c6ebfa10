"""``python -m nbrdf_tools``: the dispatcher lists every command, each runs (``--help``), and
every page of docs/results has its generator in ``nbrdf_tools.pages`` named after it."""

from __future__ import annotations

import importlib
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from nbrdf_tools.__main__ import COMMANDS, main

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "docs" / "results"


def tools(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "nbrdf_tools", *args], capture_output=True, text=True,
                          timeout=300)


def test_listing_names_every_command():
    result = tools()
    assert result.returncode == 2  # no command is a usage error
    listed = {line.split()[0] for line in result.stdout.splitlines() if line.startswith("  ")}
    assert listed == set(COMMANDS)


def test_unknown_command_is_a_usage_error(capsys):
    assert main(["no-such-command"]) == 2
    assert "unknown command 'no-such-command'" in capsys.readouterr().err


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_each_command_has_a_main(command):
    module = importlib.import_module(COMMANDS[command][0])
    assert callable(getattr(module, "main", None)), f"{COMMANDS[command][0]} has no main()"


@pytest.mark.parametrize("command", ["demo", "library", "estimation", "fidelity", "bench-rays"])
def test_help_runs_through_the_dispatcher(command):
    result = tools(command, "--help")
    assert result.returncode == 0, result.stderr
    assert f"python -m nbrdf_tools {command}" in result.stdout


@pytest.mark.parametrize("page", sorted(p.stem for p in RESULTS.glob("*.md")))
def test_every_results_page_has_its_generator(page):
    module = f"nbrdf_tools.pages.{page.replace('-', '_')}"
    assert importlib.util.find_spec(module) is not None, f"docs/results/{page}.md has no generator {module}"
    assert page in COMMANDS, f"python -m nbrdf_tools lists no command '{page}' for docs/results/{page}.md"
