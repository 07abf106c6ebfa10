"""Running the ``nbrdf`` command-line tool (and other commands) from the scripts.

One wrapper: :func:`run` captures the output and, when the command fails, raises
:class:`CommandError` whose message holds the command line, the exit status and the command's
stderr (the scripts print it), so no failure is swallowed.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from nbrdf_tools.common.paths import MissingDataError


class CommandError(RuntimeError):
    """A command exited with a non-zero status; ``str()`` includes its stderr."""

    def __init__(self, command: list[str], returncode: int, stderr: str):
        self.command, self.returncode, self.stderr = command, returncode, stderr
        super().__init__(f"`{' '.join(command)}` failed (exit status {returncode}):\n{stderr.strip()}")


def run(command: list, capture: bool = True, **kwargs) -> subprocess.CompletedProcess:
    """Runs ``command`` (items converted to str); raises :class:`CommandError` on failure. With
    ``capture=False`` its output and progress go to the terminal as they come (the error then
    points at them instead of repeating them)."""
    argv = [str(c) for c in command]
    pipe = subprocess.PIPE if capture else None
    result = subprocess.run(argv, stdout=pipe, stderr=pipe, text=True, check=False, **kwargs)
    if result.returncode != 0:
        raise CommandError(argv, result.returncode, result.stderr if capture else "(its messages are above)")
    return result


def nbrdf(cli: Path, *args) -> str:
    """Runs ``nbrdf ARGS`` and returns its stdout."""
    check_cli(cli)
    return run([cli, *args]).stdout


def check_cli(cli: Path) -> Path:
    """``cli`` when it is a file, else :class:`MissingDataError` saying how to build it."""
    if not Path(cli).is_file():
        raise MissingDataError(f"the nbrdf CLI {cli} is missing: build it with `make build` "
                               "(or `cargo build --release -p nbrdf-core --features cli`), or pass --cli / set NBRDF_CLI")
    return Path(cli)


def commands(cli: Path) -> set[str]:
    """The subcommands that ``nbrdf --help`` lists."""
    listed, names = False, set()
    for line in nbrdf(cli, "--help").splitlines():
        if line.strip().startswith("Commands:"):
            listed = True
            continue
        if listed:
            if not line.startswith("  "):
                break
            names.add(line.split()[0])
    return names
