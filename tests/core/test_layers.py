"""The package layers of DESIGN.md: each imports only from the layers above it.

Order (top first): errors, fileutil, _yaml_loader, config, _types, units; geometry; frames;
camera; tags; messages; lidar; mapping; supervise; localize; sim; eval; io; adapters; cli.
``supervise`` sits above ``localize``: the supervisor's health and ladder policy are generic over
fix sources, and the streaming node in ``localize`` drives it. Imports under
``if TYPE_CHECKING:`` count too (they are real coupling), and so do imports inside functions. No
exception is listed.

No module imports itself through others (an import cycle), within a package too: the same
imports, resolved to modules (``from tagloc.geometry import se3`` is the module ``se3``,
``from tagloc.geometry import SE3`` the package's ``__init__``).
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src" / "tagloc"
ORDER = [
    ("errors", "fileutil", "_yaml_loader", "config", "_types", "units"), ("geometry",),
    ("frames",), ("camera",), ("tags",),
    ("messages",), ("lidar",), ("mapping",), ("supervise",), ("localize",), ("sim",), ("eval",),
    ("io",), ("adapters",), ("cli",),
]  # fmt: skip
RANK = {name: rank for rank, names in enumerate(ORDER) for name in names}


def _package(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "tagloc" and len(parts) > 1 else None


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append((node.lineno, node.module))
    return out


def _violations(root: Path) -> list[str]:
    bad = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root)
        own = rel.parts[0].removesuffix(".py") if rel.parts else ""
        if own not in RANK:
            continue
        for line, module in _imports(path):
            other = _package(module)
            if other is None or other == own or other not in RANK:
                continue
            if RANK[other] > RANK[own]:
                bad.append(f"{rel}:{line}: {own} imports {module} (a lower layer)")
    return bad


def _module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(["tagloc", *parts])


def _imported_names(path: Path, module: str) -> Iterator[str]:
    """Every ``a.b.c`` imported (``from a.b import c`` gives ``a.b.c``; relative ones resolved)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join([*parts[: len(parts) - node.level + 1], *([base] if base else [])])
            yield from (f"{base}.{a.name}" for a in node.names)


def import_graph(root: Path) -> dict[str, set[str]]:
    """``{module: modules it imports}`` over the ``tagloc`` modules under ``root``."""
    paths = {_module_name(root, p): p for p in sorted(root.rglob("*.py"))}

    def resolve(name: str) -> str | None:
        while name and name not in paths:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for module, path in paths.items():
        targets = {resolve(name) for name in _imported_names(path, module)}
        graph[module] = {t for t in targets if t is not None and t != module}
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = [stack.pop()]
            while component[-1] != v:
                component.append(stack.pop())
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(cycles)


def _in_node(cycle: list[str]) -> bool:
    return any(m.startswith("tagloc.localize.node") for m in cycle)


def test_every_package_is_in_the_layer_order() -> None:
    packages = {p.name for p in SRC.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    modules = {p.stem for p in SRC.glob("*.py") if p.stem != "__init__"}
    assert packages | modules <= set(RANK), sorted((packages | modules) - set(RANK))


def test_no_import_against_the_layer_order() -> None:
    assert _violations(SRC) == []


def test_the_check_sees_a_violation(tmp_path: Path) -> None:
    (tmp_path / "geometry").mkdir()
    (tmp_path / "geometry" / "x.py").write_text("from tagloc.localize import node\n")
    expected = "geometry/x.py:1: geometry imports tagloc.localize (a lower layer)"
    assert _violations(tmp_path) == [expected]


@pytest.mark.parametrize("module", ["tagloc.cli.app", "tagloc"])
def test_package_name(module: str) -> None:
    assert _package(module) == (None if module == "tagloc" else "cli")


def test_no_import_cycle_through_the_node() -> None:
    assert [c for c in import_cycles(import_graph(SRC)) if _in_node(c)] == []


def test_no_import_cycle_elsewhere() -> None:
    assert [c for c in import_cycles(import_graph(SRC)) if not _in_node(c)] == []


def test_the_cycle_check_sees_a_cycle(tmp_path: Path) -> None:
    (tmp_path / "geometry").mkdir()
    (tmp_path / "geometry" / "__init__.py").write_text("from tagloc.geometry.a import A\n")
    (tmp_path / "geometry" / "a.py").write_text("from . import b\nA = 1\n")
    (tmp_path / "geometry" / "b.py").write_text(
        "def f():\n    from tagloc.geometry.a import A\n    return A\n"
    )
    (tmp_path / "geometry" / "c.py").write_text("from tagloc.geometry import A\n")
    graph = import_graph(tmp_path)
    assert graph["tagloc.geometry.c"] == {"tagloc.geometry"}
    assert import_cycles(graph) == [["tagloc.geometry.a", "tagloc.geometry.b"]]


def test_the_simulator_is_a_source_only() -> None:
    """``sim`` builds message streams; running the localizer on them is ``eval``'s."""
    found = [
        f"{path.relative_to(SRC)}:{line}: {module}"
        for path in sorted((SRC / "sim").rglob("*.py"))
        for line, module in _imports(path)
        if _package(module) == "localize"
    ]
    assert found == []
