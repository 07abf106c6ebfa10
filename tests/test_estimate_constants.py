"""The estimate's Python twins of nbrdf-core's constants equal the Rust source's values.

``nbrdf_mitsuba.estimate.models`` redraws the trainer's common initialisation (``paper_init``)
in NumPy, so its half-width, the network's hidden width, SplitMix64's increment and mixer and the
initialisation's stream number must be the Rust ones. Each is read from the Rust text by a small
parser, which fails where it no longer finds the definition; a second test changes each value in
a copy of the text and checks the comparison sees it."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

RUST = Path(__file__).resolve().parents[1] / "nbrdf-core" / "src"
SOURCES = {"network": RUST / "network" / "mod.rs", "rng": RUST / "rng.rs"}


def rust_const(source: str, name: str) -> str:
    """The value text of ``[pub] const NAME: TYPE = VALUE;``."""
    match = re.search(rf"^\s*(?:pub(?:\([^)]*\))?\s+)?const\s+{name}\s*:\s*\w+\s*=\s*([^;]+);", source, re.M)
    assert match, f"no `const {name}` in the Rust source"
    return match.group(1).strip()


def rust_int(text: str) -> int:
    return int(text.replace("_", ""), 0)


def rust_enum_value(source: str, enum: str, variant: str) -> int:
    body = re.search(rf"\benum\s+{enum}\s*\{{([^}}]*)\}}", source)
    assert body, f"no `enum {enum}` in the Rust source"
    match = re.search(rf"^\s*{variant}\s*=\s*([0-9_]+)\s*,", body.group(1), re.M)
    assert match, f"no `{enum}::{variant} = N` in the Rust source"
    return rust_int(match.group(1))


def rust_mix64(source: str) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """The shifts and multipliers of ``fn mix64``, in order: ``z ^ (z >> s)`` thrice, two of
    them followed by ``.wrapping_mul(m)``."""
    body = re.search(r"\bfn\s+mix64\s*\([^)]*\)\s*->\s*u64\s*\{(.*?)^\}", source, re.S | re.M)
    assert body, "no `fn mix64` in the Rust source"
    shifts = tuple(int(s) for s in re.findall(r"z\s*\^\s*\(z\s*>>\s*(\d+)\)", body.group(1)))
    multipliers = tuple(rust_int(m) for m in re.findall(r"\.wrapping_mul\((0x[0-9a-fA-F_]+)\)", body.group(1)))
    assert len(shifts) == 3 and len(multipliers) == 2, (shifts, multipliers)
    return shifts, multipliers


def rust_values(sources: dict[str, str]) -> dict[str, object]:
    shifts, multipliers = rust_mix64(sources["rng"])
    return {
        "INIT_RANGE": float(rust_const(sources["network"], "INIT_RANGE")),
        "HIDDEN": rust_int(rust_const(sources["network"], "DEFAULT_HIDDEN")),
        "_GAMMA": rust_int(rust_const(sources["rng"], "GOLDEN_GAMMA")),
        "_INIT_STREAM": rust_enum_value(sources["rng"], "Stream", "Init"),
        "_MIX_SHIFTS": shifts,
        "_MIX_MULTIPLIERS": multipliers,
    }


def python_values() -> dict[str, object]:
    from nbrdf_mitsuba.estimate import models

    return {name: getattr(models, name) for name in
            ("INIT_RANGE", "HIDDEN", "_GAMMA", "_INIT_STREAM", "_MIX_SHIFTS", "_MIX_MULTIPLIERS")}


def read_sources() -> dict[str, str]:
    return {key: path.read_text() for key, path in SOURCES.items()}


def test_python_twins_equal_the_rust_constants():
    assert python_values() == rust_values(read_sources())


# One edit of the Rust text per constant: the comparison must see each.
EDITS = [
    ("network", "const INIT_RANGE: f32 = 0.05;", "const INIT_RANGE: f32 = 0.06;", "INIT_RANGE"),
    ("network", "pub const DEFAULT_HIDDEN: usize = 21;", "pub const DEFAULT_HIDDEN: usize = 22;", "HIDDEN"),
    ("rng", "0x9e37_79b9_7f4a_7c15", "0x9e37_79b9_7f4a_7c17", "_GAMMA"),
    ("rng", "Init = 3,", "Init = 8,", "_INIT_STREAM"),
    ("rng", "(z ^ (z >> 27))", "(z ^ (z >> 28))", "_MIX_SHIFTS"),
    ("rng", "0x94d0_49bb_1331_11eb", "0x94d0_49bb_1331_11ec", "_MIX_MULTIPLIERS"),
]


@pytest.mark.parametrize("source, old, new, name", EDITS, ids=[e[3] for e in EDITS])
def test_a_changed_rust_constant_is_seen(source, old, new, name):
    sources = read_sources()
    assert sources[source].count(old) == 1, f"the edit's text is not in {SOURCES[source]}: update EDITS"
    sources[source] = sources[source].replace(old, new)
    python, rust = python_values(), rust_values(sources)
    assert [k for k in python if python[k] != rust[k]] == [name]


def test_a_missing_rust_definition_is_an_error():
    sources = read_sources()
    sources["network"] = sources["network"].replace("DEFAULT_HIDDEN", "DEFAULT_WIDTH")
    with pytest.raises(AssertionError, match="DEFAULT_HIDDEN"):
        rust_values(sources)
