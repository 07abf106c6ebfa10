"""No doc that rots: every command in README.md and docs/**/*.md is exercised here or elsewhere.

* Every line of a fenced shell block (sh, bash, console, shell) and every inline-code command
  starting with ``nbrdf ``, ``python -m `` or ``make `` is extracted and checked against the
  program it names: ``nbrdf SUBCOMMAND`` must exist (``nbrdf [SUB] --help``) and accept every
  option used; ``python -m MODULE [COMMAND]`` must import and its ``--help`` must list every
  option used; ``make TARGET`` must be a target of the Makefile it runs. Shell lines of any other
  kind must be listed in ``EXERCISED_ELSEWHERE`` with the test that runs them.
* The README's five-minute path runs literally in a temporary folder (synth, train, fit-phong,
  the render command at a tiny resolution, the Python snippet).
* docs/c-abi.md's example program is compiled with the page's own command and run.
"""

from __future__ import annotations

import functools
import importlib
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from nbrdf_testing import write_network
from nbrdf_tools.common.paths import default_cli

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
SHELL_LANGUAGES = {"sh", "bash", "console", "shell"}
FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```", re.M | re.S)
INLINE = re.compile(r"`((?:nbrdf|python -m|make) [^`]+)`")
# Placeholders of the docs' usage lines ([optional], alternatives a|b, A ...): not arguments.
ELLIPSIS = {"...", "…"}

# Shell lines that are not nbrdf/python -m/make commands: each names the test (file, and a
# string that file contains) that runs it.
EXERCISED_ELSEWHERE = {
    "pip install ./mitsuba-plugin": ("tests/test_packaging.py", "pip"),
    "examples/c/nbrdf_example ": ("tests/test_c_example.py", "nbrdf_example"),
    "cc -std=c99 example.c": ("tests/test_docs.py", "test_c_abi_example_compiles_and_runs"),
    "./example my.nbrdf.json": ("tests/test_docs.py", "test_c_abi_example_compiles_and_runs"),
}


@dataclass(frozen=True)
class Command:
    source: str  # "docs/cli.md:17"
    text: str  # one command, continuations joined, comment dropped

    def __str__(self) -> str:
        return f"{self.source}: {self.text}"


def _relative(path: Path) -> str:
    return str(path.relative_to(REPO))


def _shell_lines(block: str) -> list[tuple[int, str]]:
    """(line offset, command) of a shell block: continuations joined, comments and prompts dropped."""
    commands, pending, start = [], "", 0
    for offset, line in enumerate(block.splitlines()):
        if not pending:
            start = offset
        line = re.sub(r"^\s*\$ ", "", line)
        line = re.sub(r"(^|\s)#.*$", "", line).rstrip()
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        text = (pending + line).strip()
        pending = ""
        if text:
            commands.append((start, re.sub(r"\s+", " ", text)))
    return commands


def extract_commands() -> tuple[list[Command], list[Command]]:
    """(commands of shell blocks, inline commands) of every page."""
    blocks, inline = [], []
    for page in DOCS:
        text = page.read_text()
        for fence in FENCE.finditer(text):
            if fence.group(1).lower() in SHELL_LANGUAGES:
                first = text.count("\n", 0, fence.start(2)) + 1
                blocks += [Command(f"{_relative(page)}:{first + offset}", line)
                           for offset, line in _shell_lines(fence.group(2))]
        prose = FENCE.sub(lambda m: "\n" * m.group(0).count("\n"), text)
        for match in INLINE.finditer(prose):
            line = prose.count("\n", 0, match.start()) + 1
            inline.append(Command(f"{_relative(page)}:{line}", match.group(1).replace("\\|", "|")))
    return blocks, inline


BLOCK_COMMANDS, INLINE_COMMANDS = extract_commands()


def _program_words(text: str) -> list[str]:
    """The command's words after leading environment assignments (``VAR=value make ...``)."""
    words = tokens(text)
    while words and re.fullmatch(r"[A-Za-z_]\w*=\S*", words[0]):
        words = words[1:]
    return words


def _checked(command: Command) -> bool:
    words = _program_words(command.text)
    return bool(words) and (words[0] in ("nbrdf", "make") or words[:2] == ["python", "-m"])


def tokens(text: str) -> list[str]:
    """Arguments of a documented command: brackets of optional parts and ellipses removed."""
    try:
        words = shlex.split(text)
    except ValueError:
        words = text.split()
    words = [w.strip("[]") for w in words]
    return [w for w in words if w and w not in ELLIPSIS]


def options_of(words: list[str]) -> list[str]:
    """The options among a command's words (a quoted value such as "--epochs 20" is not one)."""
    return sorted({m.group(1) for w in words for m in [re.fullmatch(r"(--?[A-Za-z][\w-]*)(=\S*)?", w)] if m})


def lists_option(help_text: str, option: str) -> bool:
    return re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", help_text) is not None


# -- the programs' own help ---------------------------------------------------------------------


def nbrdf_program() -> Path:
    installed = Path(sys.executable).parent / "nbrdf"
    return installed if installed.exists() else default_cli()


@functools.cache
def nbrdf_help(*path: str) -> str:
    result = subprocess.run([str(nbrdf_program()), *path, "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, f"nbrdf {' '.join(path)} --help failed: {result.stderr}"
    return result.stdout


def nbrdf_subcommands(*path: str) -> set[str]:
    """The commands clap lists under 'Commands:' in ``nbrdf [PATH] --help``."""
    text = nbrdf_help(*path)
    if "Commands:" not in text:
        return set()
    section = text.split("Commands:", 1)[1].split("\n\n", 1)[0]
    return {m.group(1) for m in re.finditer(r"^\s{2}([a-z][\w-]*)", section, re.M)} - {"help"}


@functools.cache
def module_help(*argv: str) -> tuple[int, str]:
    result = subprocess.run([sys.executable, "-m", *argv, "--help"], capture_output=True, text=True, timeout=120,
                            cwd=REPO)
    return result.returncode, result.stdout + result.stderr


@functools.cache
def make_targets(makefile: Path) -> set[str]:
    targets = set()
    for line in makefile.read_text().splitlines():
        match = re.match(r"^([\w./$()-][\w./$() -]*?)\s*::?(?!=)", line)
        if match:
            targets.update(match.group(1).split())
    return targets


# -- checks -------------------------------------------------------------------------------------


def check_nbrdf(words: list[str]) -> list[str]:
    """Problems of ``nbrdf ...`` (words after 'nbrdf'); alternatives 'a|b' are checked one by one.
    An upper-case word where a command is expected is a placeholder (``nbrdf COMMAND --help``)."""
    if words and "|" in words[0] and not words[0].startswith("-"):
        return [p for alternative in words[0].split("|") for p in check_nbrdf([alternative, *words[1:]])]
    path, rest = [], words
    while rest and rest[0] in nbrdf_subcommands(*path):
        path, rest = [*path, rest[0]], rest[1:]
    name = " ".join(["nbrdf", *path])
    if rest and not rest[0].startswith("-") and not rest[0].isupper() and nbrdf_subcommands(*path):
        return [f"'{name}' has no command '{rest[0]}'"]
    help_text = nbrdf_help(*path)
    return [f"'{name}' has no option {option}" for option in options_of(rest)
            if option not in ("-h", "--help") and not lists_option(help_text, option)]


def check_python_module(words: list[str]) -> list[str]:
    """Problems of ``python -m MODULE [COMMAND] ...`` (words after '-m')."""
    module, rest = words[0], words[1:]
    status, help_text = module_help(module)
    if status != 0:
        return [f"python -m {module} --help failed ({status}): {help_text[-400:]}"]
    argv = [module]
    if rest and re.fullmatch(r"[a-z][\w-]*", rest[0]) and re.search(rf"^\s+{re.escape(rest[0])}\s", help_text, re.M):
        status, help_text = module_help(module, rest[0])
        if status != 0:
            return [f"python -m {module} {rest[0]} --help failed ({status}): {help_text[-400:]}"]
        argv, rest = [module, rest[0]], rest[1:]
    return [f"'python -m {' '.join(argv)}' has no option {option}" for option in options_of(rest)
            if option not in ("-h", "--help") and not lists_option(help_text, option)]


def check_make(words: list[str]) -> list[str]:
    directory, targets, i = REPO, [], 0
    while i < len(words):
        word = words[i]
        if word == "-C":
            directory, i = REPO / words[i + 1], i + 2
            continue
        if not word.startswith("-") and "=" not in word:
            targets.append(word)
        i += 1
    known = make_targets(directory / "Makefile")
    return [f"{_relative(directory / 'Makefile')} has no target '{t}'" for t in targets if t not in known]


def check(command: Command) -> list[str]:
    words = _program_words(command.text)
    if words[0] == "nbrdf":
        return check_nbrdf(words[1:])
    if words[:2] == ["python", "-m"]:
        return check_python_module(words[2:])
    if words[0] == "make":
        return check_make(words[1:])
    raise AssertionError(f"not a checked command: {command}")


# -- tests --------------------------------------------------------------------------------------


def test_commands_are_found():
    """The extraction sees the commands it is meant to check (a regression guard for the parser)."""
    texts = [c.text for c in BLOCK_COMMANDS]
    assert "nbrdf train my.binary -o my.nbrdf.json" in texts
    assert any(t.startswith("python -m nbrdf_mitsuba render scenes/veach_mis.xml -D plate=") for t in texts)
    assert any(c.text.startswith("nbrdf synth --model sgd|abc") for c in INLINE_COMMANDS)
    assert len(BLOCK_COMMANDS) + len(INLINE_COMMANDS) > 100


def test_every_documented_command_exists_with_its_options():
    if not nbrdf_program().exists():
        pytest.skip(f"the nbrdf CLI is not built ({nbrdf_program()}); run make setup")
    problems = []
    for command in [*BLOCK_COMMANDS, *INLINE_COMMANDS]:
        if _checked(command):
            problems += [f"{command.source}: {problem}  [{command.text}]" for problem in check(command)]
    assert not problems, "documented commands that do not exist:\n" + "\n".join(problems)


def test_other_shell_lines_are_exercised_elsewhere():
    problems = []
    for command in BLOCK_COMMANDS:
        if _checked(command):
            continue
        owner = next((v for k, v in EXERCISED_ELSEWHERE.items() if command.text.startswith(k)), None)
        if owner is None:
            problems.append(f"{command}: no test runs it (add it to EXERCISED_ELSEWHERE with its test)")
        elif owner[1] not in (REPO / owner[0]).read_text():
            problems.append(f"{command}: {owner[0]} does not contain {owner[1]!r}")
    assert not problems, "\n".join(problems)


PYTHON_NAME = re.compile(r"\b(nbrdf_(?:tools|mitsuba)(?:\.[A-Za-z_]\w*)+)")


def resolves(dotted: str) -> bool:
    """Whether ``package.module[.attribute...]`` names an importable module and its attributes."""
    parts = dotted.split(".")
    for split in range(len(parts), 0, -1):
        try:
            target = importlib.import_module(".".join(parts[:split]))
        except ModuleNotFoundError:
            continue
        for attribute in parts[split:]:
            if not hasattr(target, attribute):
                return False
            target = getattr(target, attribute)
        return True
    return False


def test_documented_python_names_exist():
    """Modules and functions the pages name (``nbrdf_tools.common.scenes.kitchen``,
    ``nbrdf_mitsuba.use_wavefront_mode``, ...) exist: renamed ones are caught."""
    names = {(name, f"{_relative(page)}:{page.read_text().count(chr(10), 0, match.start()) + 1}")
             for page in DOCS for match in PYTHON_NAME.finditer(page.read_text())
             for name in [match.group(1).rstrip(".")]}
    assert len(names) > 10
    missing = sorted(f"{source}: {name}" for name, source in names if not resolves(name))
    assert not missing, "documented Python names that do not exist:\n" + "\n".join(missing)


def test_results_pages_open_with_their_command():
    """docs/results/*.md: a shell block with a checked command comes before the first section."""
    pages = sorted((REPO / "docs" / "results").glob("*.md"))
    assert pages
    for page in pages:
        text = page.read_text()
        first_section = text.find("\n## ")
        fence = next((f for f in FENCE.finditer(text) if f.group(1) in SHELL_LANGUAGES), None)
        assert fence is not None and (first_section < 0 or fence.start() < first_section), \
            f"{_relative(page)} does not open with the command that regenerates it"
        commands = [line for _, line in _shell_lines(fence.group(2))]
        assert any(_checked(Command(_relative(page), line)) for line in commands), _relative(page)


# -- the README's five-minute path, run literally -------------------------------------------------

# Appended to the README's render command: a tiny image (the scene's resx/resy parameters).
TINY_RENDER = ["-D", "resx=48", "-D", "resy=32", "--spp", "4"]


def readme_block_command(prefix: str) -> str:
    found = [c.text for c in BLOCK_COMMANDS if c.source.startswith("README.md:") and c.text.startswith(prefix)]
    assert len(found) == 1, f"README.md: expected one command starting with {prefix!r}, found {found}"
    return found[0]


def readme_python_snippet() -> str:
    text = (REPO / "README.md").read_text()
    snippets = [m.group(2) for m in FENCE.finditer(text) if m.group(1) == "python"]
    assert len(snippets) == 1
    return snippets[0]


def test_readme_five_minute_path(tmp_path):
    if not nbrdf_program().exists():
        pytest.skip(f"the nbrdf CLI is not built ({nbrdf_program()}); run make setup")
    # The README's commands run from the repository root (scenes/...) in an activated venv.
    (tmp_path / "scenes").symlink_to(REPO / "scenes")
    env = {**os.environ, "PATH": f"{nbrdf_program().parent}{os.pathsep}{Path(sys.executable).parent}"
                                 f"{os.pathsep}{os.environ.get('PATH', '')}"}
    render = readme_block_command("python -m nbrdf_mitsuba render ")
    steps = [readme_block_command("nbrdf synth "), readme_block_command("nbrdf train "),
             readme_block_command("nbrdf fit-phong "), f"{render} {shlex.join(TINY_RENDER)}"]
    for step in steps:
        result = subprocess.run(["bash", "-c", step.replace("python -m", f"{shlex.quote(sys.executable)} -m", 1)],
                                cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, f"README step failed: {step}\n{result.stdout}\n{result.stderr}"
    assert (tmp_path / "my.binary").stat().st_size == 34_992_012  # MERL: 12-byte header + 3 x 90x90x180 doubles
    assert '"sampling"' in (tmp_path / "my.nbrdf.json").read_text()  # fit-phong stored the lobe
    assert (tmp_path / "out.exr").stat().st_size > 0 and (tmp_path / "out.png").stat().st_size > 0

    snippet = readme_python_snippet() + "\nassert bsdf is not None and 'nbrdf' in str(bsdf).lower()\n"
    result = subprocess.run([sys.executable, "-c", snippet], cwd=tmp_path, env=env, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr


# -- docs/c-abi.md's example program ---------------------------------------------------------------


def c_abi_blocks() -> tuple[str, list[str]]:
    """docs/c-abi.md's example program and the shell block after it (how to build and run it)."""
    fences = list(FENCE.finditer((REPO / "docs" / "c-abi.md").read_text()))
    index = next(i for i, fence in enumerate(fences) if fence.group(1) == "c")
    shell = next(fence for fence in fences[index + 1:] if fence.group(1) in SHELL_LANGUAGES)
    return fences[index].group(2), [line for _, line in _shell_lines(shell.group(2))]


@pytest.mark.skipif(shutil.which("cc") is None or shutil.which("pkg-config") is None,
                    reason="needs a C compiler (cc) and pkg-config")
def test_c_abi_example_compiles_and_runs(tmp_path):
    """The page's `make install PREFIX=$HOME/.local` (HOME a temporary folder), then its build and
    run commands for the example program, as written."""
    program, shell = c_abi_blocks()
    install = next(c.text for c in BLOCK_COMMANDS if c.source.startswith("docs/c-abi.md:")
                   and c.text.startswith("make install PREFIX="))
    home = Path.home()  # rustup and cargo find their toolchain through HOME unless told
    env = {"RUSTUP_HOME": str(home / ".rustup"), "CARGO_HOME": str(home / ".cargo"),
           **{k: v for k, v in os.environ.items() if k != "LD_LIBRARY_PATH"}, "HOME": str(tmp_path)}
    result = subprocess.run(["bash", "-c", f"make -s {install[len('make '):]}"], cwd=REPO, env=env,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    env["PKG_CONFIG_PATH"] = str(tmp_path / ".local" / "lib" / "pkgconfig")
    (tmp_path / "example.c").write_text(program)
    write_network(tmp_path / "my.nbrdf.json", sampling={"model": "blinn-phong", "exponent": 40.0,
                                                        "specular_weight": 0.3, "source": "fit"})
    for line in shell:
        result = subprocess.run(["bash", "-c", line], cwd=tmp_path, env=env, capture_output=True, text=True,
                                timeout=120)
        assert result.returncode == 0, f"{line}\n{result.stdout}\n{result.stderr}"
    lines = result.stdout.splitlines()
    assert len(lines) == 4 and lines[0].startswith("f_r cos = (") and lines[2].startswith("light (")
    pdfs = [re.search(r"pdf (\S+) = (\S+),", line).groups() for line in lines[2:]]
    assert all(float(a) > 0 and abs(float(a) - float(b)) <= 1e-5 * float(a) for a, b in pdfs)

    missing = subprocess.run(["./example", "missing.json"], cwd=tmp_path, env=env, capture_output=True, text=True)
    page = re.sub(r"\s+", " ", (REPO / "docs" / "c-abi.md").read_text())
    assert missing.returncode == 1 and "exits with status 1" in page
    assert f"`{missing.stderr.strip()}`" in page
