"""The Python packages' layers, read from their source, as nbrdf-core/tests/layers.rs reads the crates'.

Each package's top-level modules and subpackages (a subpackage is one node; the package's own
``__init__`` is a node) form a graph by their imports: relative and absolute, at any depth,
function-level ones included, and ``importlib.import_module`` of a constant name. The graph has no
cycle, direct or through others. The plugin never imports the tools (tools sit above the plugin),
and the plugin's rendering modules (the BSDF) never import, even through others, its commands and
training modules.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PLUGIN = REPO / "mitsuba-plugin" / "nbrdf_mitsuba"
TOOLS = REPO / "python" / "nbrdf_tools"

# What Mitsuba loads to render with the BSDF, and what it must not pull in.
RENDERING = ("__init__", "bsdf", "jit", "_native", "_llvm")
COMMANDS = ("estimate", "distill", "render", "import_keras", "tabulate_rgl", "_train_native", "latent")

Graph = dict[str, dict[str, str]]  # node -> (node it imports -> first file that does)


def modules(package_dir: Path) -> dict[str, list[Path]]:
    """Each node of a package (top-level module, subpackage or ``__init__``) and its files."""
    nodes: dict[str, list[Path]] = {}
    for path in sorted(package_dir.rglob("*.py")):
        relative = path.relative_to(package_dir)
        node = relative.parts[0] if len(relative.parts) > 1 else relative.stem
        nodes.setdefault(node, []).append(path)
    return nodes


def dotted_name(package_dir: Path, path: Path) -> list[str]:
    """The module path of a file: ``nbrdf_tools/a/b.py`` is ``[nbrdf_tools, a, b]``, an
    ``__init__.py`` its package's."""
    parts = [package_dir.name, *path.relative_to(package_dir).with_suffix("").parts]
    return parts[:-1] if parts[-1] == "__init__" else parts


def imported_modules(tree: ast.AST, name: list[str], is_package: bool) -> list[list[str]]:
    """The absolute paths a file imports, in the order met: ``import m`` gives ``m``, ``from m
    import x`` gives ``m.x`` (``x`` a submodule or a name ``m`` defines; ``m`` for ``*``)."""
    package = name if is_package else name[:-1]
    found: list[list[str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [alias.name.split(".") for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - (node.level - 1)]
                module = base + (node.module.split(".") if node.module else [])
            else:
                module = node.module.split(".")
            found += [module + ([alias.name] if alias.name != "*" else []) for alias in node.names]
        elif isinstance(node, ast.Call) and _is_import_module(node.func) and node.args:
            target = _constant_module(node.args[0], name)
            if target:
                found.append(target)
    return found


def _is_import_module(func: ast.expr) -> bool:
    return (isinstance(func, ast.Attribute) and func.attr == "import_module") or (
        isinstance(func, ast.Name) and func.id == "import_module")


def _constant_module(arg: ast.expr, name: list[str]) -> list[str] | None:
    """``"a.b"`` or ``f"{__name__}.b"``, as a module path."""
    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
        return arg.value.split(".")
    if isinstance(arg, ast.JoinedStr) and len(arg.values) == 2:
        head, tail = arg.values
        if (isinstance(head, ast.FormattedValue) and isinstance(head.value, ast.Name)
                and head.value.id == "__name__" and isinstance(tail, ast.Constant)):
            return name + tail.value.lstrip(".").split(".")
    return None


def node_of(module: list[str], package: str, nodes: dict[str, list[Path]]) -> str | None:
    """The node of ``package`` an imported path falls in, if any: ``package`` itself is
    ``__init__``; ``package.x...`` is ``x`` when ``x`` is a node, else ``x`` is a name that
    ``__init__`` defines. (Importing a submodule runs its parents' ``__init__`` too; that
    arrow every submodule has is not counted.)"""
    if module[0] != package:
        return None
    if len(module) == 1:
        return "__init__"
    return module[1] if module[1] in nodes else "__init__"


def module_graph(package_dir: Path) -> tuple[Graph, dict[str, set[str]]]:
    """The import graph between a package's nodes, and each node's imports of other top-level
    packages (``nbrdf_tools``, ``mitsuba``, ...)."""
    package = package_dir.name
    nodes = modules(package_dir)
    graph: Graph = {node: {} for node in nodes}
    external: dict[str, set[str]] = {node: set() for node in nodes}
    for node, files in nodes.items():
        for path in files:
            tree = ast.parse(path.read_text(), filename=str(path))
            name = dotted_name(package_dir, path)
            for module in imported_modules(tree, name, path.name == "__init__.py"):
                if not module:
                    continue  # a relative import above the package: Python refuses it
                target = node_of(module, package, nodes)
                if target is None:
                    external[node].add(module[0])
                elif target != node:
                    graph[node].setdefault(target, str(path.relative_to(package_dir.parent)))
    return graph, external


def find_cycle(graph: Graph) -> list[str] | None:
    """A cycle ``[a, b, ..., a]`` of the graph, if there is one (depth-first search)."""
    done: set[str] = set()

    def visit(node: str, path: list[str]) -> list[str] | None:
        if node in path:
            return path[path.index(node):] + [node]
        if node in done:
            return None
        path.append(node)
        for target in graph.get(node, {}):
            cycle = visit(target, path)
            if cycle:
                return cycle
        path.pop()
        done.add(node)
        return None

    for start in graph:
        cycle = visit(start, [])
        if cycle:
            return cycle
    return None


def reachable(graph: Graph, starts: tuple[str, ...]) -> dict[str, list[str]]:
    """Every node reachable from ``starts``, with the chain of imports that reaches it."""
    chains = {start: [start] for start in starts if start in graph}
    queue = list(chains)
    while queue:
        node = queue.pop(0)
        for target in graph[node]:
            if target not in chains:
                chains[target] = chains[node] + [target]
                queue.append(target)
    return chains


@pytest.mark.parametrize("package_dir", [PLUGIN, TOOLS], ids=lambda p: p.name)
def test_top_level_modules_have_no_cycle(package_dir):
    graph, _ = module_graph(package_dir)
    cycle = find_cycle(graph)
    assert cycle is None, " -> ".join(f"{a} ({graph[a][b]})" for a, b in zip(cycle, cycle[1:])) + f" -> {cycle[-1]}"


def test_the_plugin_never_imports_the_tools():
    _, external = module_graph(PLUGIN)
    importers = sorted(node for node, packages in external.items() if TOOLS.name in packages)
    assert importers == [], f"{PLUGIN.name} modules importing {TOOLS.name}: {importers}"
    # The reading itself: the arrow the other way is seen.
    _, tools_external = module_graph(TOOLS)
    assert any(PLUGIN.name in packages for packages in tools_external.values())


def test_the_bsdf_never_imports_the_commands():
    graph, _ = module_graph(PLUGIN)
    assert {"__init__", "bsdf"} <= graph.keys()
    chains = reachable(graph, RENDERING)
    # The reading itself: the BSDF's own imports are seen.
    assert "_native" in chains and "jit" in graph["bsdf"], graph["bsdf"]
    upward = {node: " -> ".join(chains[node]) for node in COMMANDS if node in chains}
    assert upward == {}, upward


PLANTED = {
    "__init__.py": "from . import a\n",
    "a.py": "def f():\n    from .sub import helper\n    return helper\n",
    "sub/__init__.py": "",
    "sub/helper.py": "import importlib\n\nimportlib.import_module('pkg.c')\n",
    "c.py": "from pkg import d\n",
    "d.py": "import pkg.a\nimport other_tools\n",
    "e.py": "from . import VERSION\n",
}


def planted(tmp_path: Path, files: dict[str, str]) -> Path:
    package_dir = tmp_path / "pkg"
    for name, text in files.items():
        (package_dir / name).parent.mkdir(parents=True, exist_ok=True)
        (package_dir / name).write_text(text)
    return package_dir


def test_a_planted_cycle_is_reported(tmp_path):
    """A cycle through a function-level relative import into a subpackage, ``import_module`` of a
    constant, ``from pkg import module`` and ``import pkg.module`` is found; removing one arrow
    removes it."""
    package_dir = planted(tmp_path, PLANTED)
    graph, external = module_graph(package_dir)
    assert {node: set(targets) for node, targets in graph.items()} == {
        "__init__": {"a"}, "a": {"sub"}, "sub": {"c"}, "c": {"d"}, "d": {"a"}, "e": {"__init__"}}
    assert external["d"] == {"other_tools"}
    assert find_cycle(graph) == ["a", "sub", "c", "d", "a"]
    assert reachable(graph, ("__init__",)).get("d") == ["__init__", "a", "sub", "c", "d"]
    graph, _ = module_graph(planted(tmp_path / "fixed", PLANTED | {"d.py": "import other_tools\n"}))
    assert find_cycle(graph) is None
