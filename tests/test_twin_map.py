"""docs/design.md's twin table ("Twins") names files and definitions that exist.

Every backticked name in the table's cells after the first column is ``path::name``: the path is
relative to the repository root, the name a Rust item (``fn``, ``struct``, ``enum``, ``trait``,
``type``, ``const``, ``static``, ``mod`` or an ``impl`` of it; ``Type::item`` needs both) or a
Python definition at any depth (``def``, ``class``, an assigned name; ``Class.attr`` needs the
attribute in that class's body). A name without ``::`` names a file. The checker is run on the
real table, and on copies where one twin was renamed, which it must name.
"""

from __future__ import annotations

import ast
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DESIGN = REPO / "docs" / "design.md"
HEADING = "## Twins"
CODE = re.compile(r"`([^`]+)`")
RUST_VISIBILITY = r"(?:pub(?:\([^)]*\))?\s+)?"
RUST_QUALIFIERS = r"(?:(?:const|unsafe|async|extern\s+\"[^\"]*\")\s+)*"


@dataclass(frozen=True)
class Reference:
    row: str  # the formula, the table's first column
    text: str  # "path::name" as written

    @property
    def path(self) -> str:
        return self.text.split("::", 1)[0]

    @property
    def name(self) -> str | None:
        parts = self.text.split("::", 1)
        return parts[1] if len(parts) == 2 else None


def twin_table(markdown: str) -> list[list[str]]:
    """The twin section's table rows (cells stripped), header and rule left out."""
    start = markdown.index(HEADING)
    end = markdown.find("\n## ", start + len(HEADING))
    section = markdown[start:end if end >= 0 else None]
    rows = [line for line in section.splitlines() if line.startswith("|")]
    return [[cell.strip() for cell in row.strip("|").split("|")] for row in rows[2:]]


def references(markdown: str) -> list[Reference]:
    return [Reference(cells[0], text) for cells in twin_table(markdown)
            for cell in cells[1:] for text in CODE.findall(cell)]


def rust_defines(source: str, name: str) -> bool:
    n = re.escape(name)
    item = rf"^\s*{RUST_VISIBILITY}(?:{RUST_QUALIFIERS}fn|struct|enum|trait|type|const|static|mod)\s+{n}\b"
    # ``impl Trait for Type`` defines Type's items, not Trait.
    impl = rf"^\s*impl(?:<[^>{{]*>)?\s+(?:[\w:<>, ']+\s+for\s+)?{n}\b(?!\s+for\b)"
    return any(re.search(pattern, source, re.M) for pattern in (item, impl))


def _defined_names(body: list[ast.stmt]) -> set[str]:
    """Names a block defines directly: functions, classes and assignment targets."""
    names = set()
    for node in body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names


def python_defines(source: str, name: str) -> bool:
    tree = ast.parse(source)
    *outer, leaf = name.split(".")
    scopes = [tree]
    for part in outer:
        scopes = [node for scope in scopes for node in ast.walk(scope)
                  if isinstance(node, ast.ClassDef) and node.name == part]
    if not outer:
        scopes = [node for node in ast.walk(tree) if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                                                                       ast.AsyncFunctionDef))]
    return any(leaf in _defined_names(scope.body) for scope in scopes)


def problem(reference: Reference, root: Path) -> str | None:
    """Why ``reference`` does not resolve under ``root`` (None when it does)."""
    path = root / reference.path
    if not path.is_file():
        return f"{reference.row}: {reference.text}: no file {reference.path}"
    if reference.name is None:
        return None
    source = path.read_text(encoding="utf-8")
    if path.suffix == ".rs":
        missing = [part for part in reference.name.split("::") if not rust_defines(source, part)]
    elif path.suffix == ".py":
        missing = [] if python_defines(source, reference.name) else [reference.name]
    else:
        return f"{reference.row}: {reference.text}: neither Rust nor Python"
    return f"{reference.row}: {reference.text}: {', '.join(missing)} not defined" if missing else None


def problems(markdown: str, root: Path) -> list[str]:
    return [p for r in references(markdown) if (p := problem(r, root)) is not None]


# ---------------------------------------------------------------------------------------------


def test_every_twin_in_the_table_exists():
    markdown = DESIGN.read_text(encoding="utf-8")
    rows = twin_table(markdown)
    formulas = {row[0] for row in rows}
    for formula in ("network input (isotropic and anisotropic)", "forward pass", "MERL trilinear lookup",
                    "uniform and cosine hemisphere", "two lobes", "anisotropic lobe", "tabulated sampler"):
        assert formula in formulas
    assert all(len(row) == 5 for row in rows), [row[0] for row in rows if len(row) != 5]
    assert len(references(markdown)) > 3 * len(rows)
    assert problems(markdown, REPO) == []


def test_a_renamed_name_in_the_table_is_named():
    markdown = DESIGN.read_text(encoding="utf-8")
    renamed = markdown.replace("jit/network.py::TracedNetwork.eval_input", "jit/network.py::TracedNetwork.eval_inputs", 1)
    assert renamed != markdown
    assert problems(renamed, REPO) == [
        "forward pass: mitsuba-plugin/nbrdf_mitsuba/jit/network.py::TracedNetwork.eval_inputs: TracedNetwork.eval_inputs "
        "not defined"]
    moved = markdown.replace("nbrdf-core/src/merl/lookup.rs::", "nbrdf-core/src/merl.rs::", 1)
    assert problems(moved, REPO) == ["MERL trilinear lookup: nbrdf-core/src/merl.rs::MerlTable::trilinear: "
                                     "no file nbrdf-core/src/merl.rs"]


def test_a_twin_renamed_in_the_code_is_named(tmp_path):
    """The table unchanged, the code renamed: a copy of the files of the forward pass's row."""
    markdown = DESIGN.read_text(encoding="utf-8")
    row = [r for r in references(markdown) if r.row == "forward pass"]
    for reference in row:
        (tmp_path / reference.path).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / reference.path, tmp_path / reference.path)
    only_row = "\n".join(line for line in markdown.splitlines()
                         if not line.startswith("| ") or line.startswith(("| formula", "| forward pass")))
    assert problems(only_row, tmp_path) == []
    kernel = tmp_path / "nbrdf-core/src/network/kernel.rs"
    kernel.write_text(kernel.read_text().replace("fn eval_chunks<", "fn eval_lanes<"))
    network = tmp_path / "mitsuba-plugin/nbrdf_mitsuba/jit/network.py"
    network.write_text(network.read_text().replace("def eval_input(", "def evaluate_input("))
    assert problems(only_row, tmp_path) == [
        "forward pass: nbrdf-core/src/network/kernel.rs::eval_chunks: eval_chunks not defined",
        "forward pass: mitsuba-plugin/nbrdf_mitsuba/jit/network.py::TracedNetwork.eval_input: "
        "TracedNetwork.eval_input "
        "not defined"]


RUST = """\
pub(crate) const unsafe fn packed() {}
// fn in_a_comment() {}
pub struct Table;
impl<'a> Brdf for Table {}
impl Sampler {
    pub(super) fn draw(&self) {}
}
const LIMIT: f32 = 1.0;
"""

PYTHON = """\
LIMIT = 1.0
TOTAL: int = 2


class Outer:
    class Inner:
        def method(self):
            def local():
                pass
"""


@pytest.mark.parametrize("name, found", [
    ("packed", True), ("Table", True), ("Sampler", True), ("draw", True), ("LIMIT", True),
    ("in_a_comment", False), ("Brdf", False), ("pack", False)])
def test_rust_definitions(name, found):
    assert rust_defines(RUST, name) is found


@pytest.mark.parametrize("name, found", [
    ("LIMIT", True), ("TOTAL", True), ("Outer", True), ("Inner", True), ("Outer.Inner", True),
    ("Inner.method", True), ("Outer.Inner.method", True), ("method", True), ("local", True),
    ("Outer.method", False), ("Inner.local", False), ("Missing", False)])
def test_python_definitions(name, found):
    assert python_defines(PYTHON, name) is found
