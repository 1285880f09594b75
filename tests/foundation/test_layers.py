"""The library's import graph: no cycles, no upward imports, no Prefect / flows / tasks.

Walks every module of ``physanim`` with ``ast`` (imports inside functions included) and
checks each import of another physanim module against the layer order below.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2] / "physanim"

#: Layers, lowest first. A unit (a subpackage, or a top-level module of ``physanim``) may
#: import its own modules and any unit of a LOWER layer, never one of its own layer or above.
LAYERS: list[set[str]] = [
    {"__init__", "native", "processes", "transforms", "names", "config", "spline"},  # core
    {"store", "dynamics"},
    {"pipeline", "muscle"},
    {"mesh"},  # surface / tet geometry, scans, regions, materials per tet
    {"fem", "capture"},  # FEM solver (uses mesh's seam sides); recordings and demo actor
    {"face"},  # face model, fit and FEM drive (uses mesh, fem, capture's actor)
    {"tracking"},  # tracking backends (use the face model's landmarks)
    {"evaluate"},
    {"render"},  # the run report compares evaluations
    {"warm"},  # the setup's compile-ahead entry point (runs fem's and capture's kernels)
]
FORBIDDEN = ("prefect", "flows", "tasks", "cli")


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


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


def _graph() -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    known = _modules()
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


def test_checks_can_fail() -> None:
    """The checks see a loop and an upward arrow when there is one."""
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _layer("fem") > _layer("mesh")
    with pytest.raises(AssertionError, match="no layer"):
        _layer("not_a_package")
