"""Python twins of Rust constants hold the Rust values under the Rust names.

Each twin is read from its Python module and compared with the constant parsed from the Rust
source text (``const NAME: T = value;``, evaluated in float64 and compared in the declared type
``T``), so a constant changed or renamed on either side fails here. The parser is checked to find
every constant of the table, and on copies of a Rust file where one was changed or renamed.
"""

from __future__ import annotations

import ast
import importlib
import operator
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Twin:
    rust: str  # the Rust file, relative to the repository root
    module: str  # the Python module holding the twin
    name: str  # the name on both sides

    def __str__(self) -> str:
        return f"{self.rust}::{self.name} = {self.module}.{self.name}"


FASTMATH = "nbrdf-core/src/fastmath.rs"
GRID = "nbrdf-core/src/merl/grid.rs"
TWINS = [
    *(Twin(FASTMATH, "nbrdf_mitsuba.jit.fastmath", name) for name in ("EXP_ARG_MAX", "EXP_ARG_MIN", "LN2_HI", "LN2_LO")),
    Twin(FASTMATH, "nbrdf_tools.common.network", "EXP_ARG_MAX"),
    Twin("nbrdf-core/src/coords.rs", "nbrdf_mitsuba.jit.network", "SIN_THETA_H_EPS_F32"),
    Twin("nbrdf-core/src/sampling/mod.rs", "nbrdf_mitsuba.jit.sampling", "MAX_EXPONENT"),
    Twin("nbrdf-core/src/sampling/mod.rs", "textured_fixture", "MAX_EXPONENT"),
    Twin("nbrdf-core/src/textured/lobes.rs", "nbrdf_mitsuba.jit.textured", "FILTER_SLACK"),
    Twin("nbrdf-core/src/textured/lobes.rs", "textured_fixture", "FILTER_SLACK"),
    Twin("nbrdf-core/src/sampling/two_lobe.rs", "nbrdf_mitsuba.validation", "WEIGHT_SUM_TOLERANCE"),
    *(Twin(GRID, "nbrdf_mitsuba.jit.merl", name) for name in ("N_THETA_H", "N_THETA_D", "N_PHI_D", "SCALE")),
    *(Twin(GRID, "nbrdf_mitsuba.tabulate_rgl", name)
      for name in ("N_THETA_H", "N_THETA_D", "N_PHI_D", "SCALE", "NOT_MEASURED")),
    Twin("nbrdf-core/src/latent/autoencoder/mod.rs", "nbrdf_mitsuba.latent", "FORMAT_NAME"),
    Twin("nbrdf-core/src/latent/family.rs", "nbrdf_tools.data.pretrained", "COMMON"),
    Twin("nbrdf-core/src/analytic/mod.rs", "nbrdf_tools.common.analytic_fit", "MIN_COS"),
    Twin("nbrdf-core/src/metrics.rs", "nbrdf_tools.common.compare_materials", "LIGHT_THETAS_DEG"),
]

# ---------------------------------------------------------------------------------------------
# Reading Rust constants

CONST = re.compile(
    r"^[ \t]*(?:pub(?:\([^)]*\))?[ \t]+)?const[ \t]+(?P<name>[A-Z][A-Z0-9_]*)[ \t]*:[ \t]*(?P<type>[^=]+?)[ \t]*="
    r"[ \t]*(?P<value>(?:\"(?:[^\"\\]|\\.)*\"|[^;\"])+);", re.M)
INTEGERS = {"usize", "isize", "u8", "u16", "u32", "u64", "i8", "i16", "i32", "i64"}
FLOATS = {"f32": np.float32, "f64": np.float64}
STRINGS = {"&str", "&'static str"}
OPERATORS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
             ast.USub: operator.neg, ast.UAdd: operator.pos}


def rust_constants(source: str) -> dict[str, tuple[str, str]]:
    """``{name: (type, value text)}`` of the ``const`` items of a Rust source (any visibility)."""
    found: dict[str, tuple[str, str]] = {}
    for match in CONST.finditer(source):
        item = (" ".join(match["type"].split()), match["value"].strip())
        if found.setdefault(match["name"], item) != item:
            raise ValueError(f"const {match['name']} is defined twice, differently")
    return found


def rust_value(text: str):
    """A Rust constant expression of literals, + - * / and arrays, evaluated in Python (float64)."""
    text = re.sub(r"(?<=[0-9])_(?=[0-9])", "", text)  # 2.121_944_4e-4
    text = re.sub(r"(?<=[0-9.])_?(?:f32|f64|usize|isize|[ui](?:8|16|32|64))\b", "", text)  # 80.0f32, 1_u32

    def evaluate(node):
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float, str)):
            return node.value
        if isinstance(node, ast.UnaryOp) and type(node.op) in OPERATORS:
            return OPERATORS[type(node.op)](evaluate(node.operand))
        if isinstance(node, ast.BinOp) and type(node.op) in OPERATORS:
            return OPERATORS[type(node.op)](evaluate(node.left), evaluate(node.right))
        if isinstance(node, ast.List):
            return tuple(evaluate(element) for element in node.elts)
        raise ValueError(f"not a literal expression: {text}")

    return evaluate(ast.parse(text, mode="eval").body)


def same(python, rust, rust_type: str) -> bool:
    """Whether the Python value is the Rust value of type ``rust_type`` (floats compared in it)."""
    array = re.fullmatch(r"\[(.+);\s*(\d+)\]", rust_type)
    if array:
        python = list(np.asarray(python).tolist()) if isinstance(python, np.ndarray) else list(python)
        return len(python) == len(rust) == int(array[2]) and all(same(p, r, array[1]) for p, r in zip(python, rust))
    if rust_type in FLOATS:
        return isinstance(python, (int, float)) and FLOATS[rust_type](python) == FLOATS[rust_type](rust)
    if rust_type in INTEGERS:
        return isinstance(python, int) and python == rust
    if rust_type in STRINGS:
        return python == rust
    raise ValueError(f"no comparison for Rust type {rust_type}")


def problem(twin: Twin, rust_source: str, python_module) -> str | None:
    """Why ``twin`` does not hold (None when it does)."""
    constants = rust_constants(rust_source)
    if twin.name not in constants:
        return f"{twin}: no const {twin.name} in {twin.rust}"
    if not hasattr(python_module, twin.name):
        return f"{twin}: no {twin.name} in {twin.module}"
    rust_type, text = constants[twin.name]
    rust, python = rust_value(text), getattr(python_module, twin.name)
    if not same(python, rust, rust_type):
        return f"{twin}: Rust {rust_type} {text}, Python {python!r}"
    return None


# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("twin", TWINS, ids=str)
def test_python_twin_equals_the_rust_constant(twin):
    source = (REPO / twin.rust).read_text(encoding="utf-8")
    assert problem(twin, source, importlib.import_module(twin.module)) is None


@pytest.mark.parametrize("twin", TWINS, ids=str)
def test_the_parser_finds_each_rust_constant(twin):
    """Each name of the table is a ``const`` of its Rust file, its value a literal expression."""
    source = (REPO / twin.rust).read_text(encoding="utf-8")
    assert re.search(rf"\bconst\s+{twin.name}\s*:", source), twin
    rust_type, text = rust_constants(source)[twin.name]
    assert rust_value(text) is not None and rust_type


def test_a_changed_or_renamed_constant_fails():
    from nbrdf_mitsuba.jit import fastmath

    twin = Twin(FASTMATH, "nbrdf_mitsuba.jit.fastmath", "EXP_ARG_MAX")
    source = (REPO / FASTMATH).read_text(encoding="utf-8")
    assert "pub const EXP_ARG_MAX: f32 = 80.0;" in source
    assert problem(twin, source, fastmath) is None
    changed = source.replace("pub const EXP_ARG_MAX: f32 = 80.0;", "pub const EXP_ARG_MAX: f32 = 81.0;")
    assert problem(twin, changed, fastmath) == f"{twin}: Rust f32 81.0, Python 80.0"
    renamed = source.replace("EXP_ARG_MAX", "EXP_ARGUMENT_MAX")
    assert problem(twin, renamed, fastmath) == f"{twin}: no const EXP_ARG_MAX in {FASTMATH}"

    class Renamed:  # the Python side renamed
        EXP_ARGUMENT_MAX = 80.0

    assert problem(twin, source, Renamed) == f"{twin}: no EXP_ARG_MAX in nbrdf_mitsuba.jit.fastmath"


RUST = """\
/// The largest value; doc text with const FAKE: f32 = 1.0; inside.
pub const LIMIT: f32 = 80.0;
pub(super) const TOLERANCE: f64 = 1e-6;
const SPLIT: f32 = 355.0 / 512.0;
const TINY: f32 = -2.121_944_4e-4;
pub const GRID: [f64; 3] = [1.0 / 1500.0, 1.15 / 1500.0,
                            1.66 / 1500.0];
pub const COUNT: usize = 90;
const NAME: &str = "a; b";
// const COMMENTED: f32 = 2.0;
fn body() {
    const LOCAL: u32 = 7_u32;
}
"""


def test_the_parser_reads_rust_const_items():
    constants = rust_constants(RUST)
    assert set(constants) == {"LIMIT", "TOLERANCE", "SPLIT", "TINY", "GRID", "COUNT", "NAME", "LOCAL"}
    values = {name: rust_value(text) for name, (_, text) in constants.items()}
    assert values == {"LIMIT": 80.0, "TOLERANCE": 1e-6, "SPLIT": 355.0 / 512.0, "TINY": -2.1219444e-4,
                      "GRID": (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0), "COUNT": 90, "NAME": "a; b", "LOCAL": 7}
    assert constants["GRID"][0] == "[f64; 3]" and constants["NAME"][0] == "&str"
    assert same((1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0), values["GRID"], "[f64; 3]")
    assert not same((1.0 / 1500.0, 1.15 / 1500.0), values["GRID"], "[f64; 3]")
    assert not same(90.0, 90, "usize") and same(90, 90, "usize")
    assert same(80.0, 80.0, "f32") and not same(80.5, 80.0, "f32")
