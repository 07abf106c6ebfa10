"""Every page under docs/results is generated output: it opens with the command that writes it,
in full, from results stored in the repository (``--stored-only``), and running that command
again changes no byte. The command is run with its ``--out`` pointed at a temporary file."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "docs" / "results"
PAGES = sorted(RESULTS.glob("*.md"))
FENCE = re.compile(r"```sh\n(.*?)```", re.S)


def opening_command(page: Path) -> list[str]:
    """The first command of the page's first ``sh`` block, which must come before any table."""
    text = page.read_text()
    block = FENCE.search(text)
    assert block, f"{page.name} has no ```sh block"
    assert "|---" not in text[:block.start()], f"{page.name}: a table comes before the opening command"
    line = block.group(1).strip().splitlines()[0]
    return shlex.split(line.split("#", 1)[0])


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_opening_command_regenerates_the_page(page, tmp_path):
    argv = opening_command(page)
    name = page.stem
    assert argv[:4] == ["python", "-m", "nbrdf_tools", name], \
        f"{page.name} opens with {' '.join(argv)!r}, not `python -m nbrdf_tools {name} ...`"
    assert "--stored-only" in argv, f"{page.name}: the opening command must regenerate from stored results"
    assert "--out" in argv, f"{page.name}: the opening command names its output with --out"
    at = argv.index("--out") + 1
    assert Path(argv[at]) == page.relative_to(REPO), f"{page.name}: --out {argv[at]} is not the page itself"
    argv[at] = str(tmp_path / page.name)
    result = subprocess.run([sys.executable, *argv[1:]], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    written = (tmp_path / page.name).read_text()
    if written != page.read_text():
        import difflib

        diff = difflib.unified_diff(page.read_text().splitlines(), written.splitlines(), "committed", "regenerated",
                                    lineterm="", n=1)
        pytest.fail(f"{page.name} differs from what its command writes:\n" + "\n".join(list(diff)[:60]))
