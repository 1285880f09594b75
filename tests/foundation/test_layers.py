"""The import graph of the library and the layers above it: no cycles, no upward imports.

Walks every module of ``physanim``, ``tasks``, ``flows`` and ``cli`` with ``ast`` (imports
inside functions included) and checks each import of another of their modules against the
layer order below: inside the library by subpackage (``LAYERS``), above it by package
(``PACKAGES``). The stage layer (``tasks``) never touches the stage store: a stage reads other
stages' outputs only through its declared inputs.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
ROOT = REPO / "physanim"
#: the packages, lowest first: each imports only lower ones (and itself), never a cycle
PACKAGES = ["physanim", "tasks", "flows", "cli"]

#: Layers, lowest first. A unit (a subpackage, or a top-level module of ``physanim``) may
#: import its own modules and any unit of a LOWER layer, never one of its own layer or above.
LAYERS: list[set[str]] = [
    {"__init__", "native", "processes", "transforms", "cameras", "names", "config", "spline"},
    {"store", "dynamics"},
    {"pipeline", "muscle"},
    {"mesh"},  # surface / tet geometry, scans, regions, materials per tet
    {"fem", "capture"},  # FEM solver (uses mesh's seam sides); recordings and demo actor
    {"face"},  # face model, fit and FEM drive (uses mesh, fem, capture's actor)
    {"tracking"},  # tracking backends (use the face model's landmarks)
    {"evaluate"},
    {"export"},  # USD, glTF and Alembic files of animated meshes (use mesh)
    {"render"},  # the run report compares evaluations
    {"warm"},  # the setup's compile-ahead entry point (fem's, capture's, export's kernels)
]
FORBIDDEN = ("prefect", "flows", "tasks", "cli")


def _module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules(packages: list[str] = PACKAGES[:1]) -> dict[str, Path]:
    return {_module_name(p): p for pkg in packages for p in sorted((REPO / pkg).rglob("*.py"))}


def _type_only(tree: ast.Module) -> set[ast.AST]:
    """Nodes under ``if TYPE_CHECKING:`` (annotations only, never imported at run time)."""
    nodes: set[ast.AST] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            nodes.update(n for stmt in node.body for n in ast.walk(stmt))
    return nodes


def _imports(path: Path, name: str, known: dict[str, Path]) -> set[str]:
    """Every module ``path`` imports at run time (physanim modules resolved)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    tree = ast.parse(path.read_text())
    skip = _type_only(tree)
    for node in ast.walk(tree):
        if node in skip:
            continue
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{anchor}.{base}" if base else anchor
            subs = [f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in known]
            found.update(subs or [base])
    return found


def _graph(packages: list[str] = PACKAGES[:1]) -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """(module -> the modules of ``packages`` it imports, module -> other top-level names)."""
    known = _modules(packages)
    internal, external = {}, {}
    for name, path in known.items():
        imports = _imports(path, name, known)
        internal[name] = {m for m in imports if m in known and m != name}
        external[name] = {m.split(".")[0] for m in imports if m not in known}
    return internal, external


def _unit(module: str) -> str:
    parts = module.split(".")
    return "__init__" if len(parts) == 1 else parts[1]


def _layer(unit: str) -> int:
    for i, layer in enumerate(LAYERS):
        if unit in layer:
            return i
    raise AssertionError(f"physanim.{unit} is in no layer: add it to LAYERS in {__file__}")


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` as [a, b, ..., a], or None."""
    state: dict[str, int] = {}  # 1 on the DFS stack, 2 done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_every_unit_has_a_layer() -> None:
    for module in _graph()[0]:
        _layer(_unit(module))


def test_no_import_cycles() -> None:
    internal, _ = _graph()
    cycle = _cycle(internal)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)
    units: dict[str, set[str]] = {}
    for module, targets in internal.items():
        units.setdefault(_unit(module), set()).update(_unit(t) for t in targets)
    for unit, targets in units.items():
        targets.discard(unit)
    cycle = _cycle(units)
    assert cycle is None, "subpackage cycle: " + " -> ".join(cycle)


def test_imports_respect_the_layers() -> None:
    internal, _ = _graph()
    upward = [
        f"{m} -> {t}"
        for m, targets in sorted(internal.items())
        for t in sorted(targets)
        if _unit(m) != _unit(t) and _layer(_unit(t)) >= _layer(_unit(m))
    ]
    assert not upward, "imports of the same or a higher layer:\n" + "\n".join(upward)


def test_library_never_imports_prefect_flows_or_tasks() -> None:
    _, external = _graph()
    bad = [
        f"{m} -> {x}" for m, xs in sorted(external.items()) for x in sorted(xs) if x in FORBIDDEN
    ]
    assert not bad, "\n".join(bad)


def test_no_import_cycles_and_no_upward_imports_across_the_packages() -> None:
    """physanim < tasks < flows < cli: no module cycle anywhere, no package imports a higher
    one (the CLI may import flows, the flows the stages, the stages the library)."""
    internal, _ = _graph(PACKAGES)
    cycle = _cycle(internal)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)
    rank = {pkg: i for i, pkg in enumerate(PACKAGES)}
    upward = [
        f"{m} -> {t}"
        for m, targets in sorted(internal.items())
        for t in sorted(targets)
        if rank[t.split(".")[0]] > rank[m.split(".")[0]]
    ]
    assert not upward, "imports of a higher package:\n" + "\n".join(upward)


#: what a stage module may not use: the store and its codec, and keys computed by hand
STORE_NAMES = {"StageStore", "read_dataclass", "write_dataclass", "write_array", "stage_key"}
STORE_MODULES = ("physanim.store.stage_store", "physanim.store.codec", "physanim.pipeline.plan")


def _store_access(path: Path) -> list[str]:
    """Lines of ``path`` that reach the stage store: ``<x>.store``, a store class or codec
    function imported, a store or planner module imported."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Attribute) and node.attr == "store":
            found.append(f"{path.name}:{node.lineno} .store")
        elif isinstance(node, ast.ImportFrom):
            names = {a.name for a in node.names} & STORE_NAMES
            if names or (node.module or "").startswith(STORE_MODULES):
                found.append(f"{path.name}:{node.lineno} from {node.module} import {names}")
        elif isinstance(node, ast.Import) and any(
            a.name.startswith(STORE_MODULES) for a in node.names
        ):
            found.append(f"{path.name}:{node.lineno} import")
    return found


def test_stages_never_touch_the_store() -> None:
    """``tasks/`` reads inputs as typed arguments and returns its output: it opens no store
    group, computes no key and reads no other stage's output by hand."""
    bad = [hit for p in sorted((REPO / "tasks").glob("*.py")) for hit in _store_access(p)]
    assert not bad, "stage modules reaching the store:\n" + "\n".join(bad)


def test_no_type_ignore_in_production_code() -> None:
    """No ``type: ignore`` in the library, the stages, the flows or the CLI."""
    hits = [
        f"{p.relative_to(REPO)}:{i}"
        for pkg in PACKAGES
        for p in sorted((REPO / pkg).rglob("*.py"))
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if "type: ignore" in line
    ]
    assert not hits, "\n".join(hits)


def test_checks_can_fail(tmp_path: Path) -> None:
    """The checks see a loop, an upward arrow and a store access when there is one."""
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _layer("fem") > _layer("mesh")
    with pytest.raises(AssertionError, match="no layer"):
        _layer("not_a_package")
    stage = tmp_path / "stage.py"
    stage.write_text("from physanim.store import read_dataclass\nx = ctx.store.open('a')\n")
    assert len(_store_access(stage)) == 2
