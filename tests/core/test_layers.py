"""The package layers of DESIGN.md: each imports only from the layers above it.

Order (top first): errors, fileutil, _yaml_loader, config; geometry; frames; camera; tags;
messages; lidar; mapping; supervise; localize; sim; eval; io; adapters; cli. ``supervise`` sits
above ``localize``: the supervisor's health and ladder policy are generic over fix sources, and the
streaming node in ``localize`` drives it. Imports under ``if TYPE_CHECKING:`` count too (they
are real coupling).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src" / "tagloc"
ORDER = [
    ("errors", "fileutil", "_yaml_loader", "config"), ("geometry",), ("frames",), ("camera",),
    ("tags",),
    ("messages",), ("lidar",), ("mapping",), ("supervise",), ("localize",), ("sim",), ("eval",),
    ("io",), ("adapters",), ("cli",),
]  # fmt: skip
RANK = {name: rank for rank, names in enumerate(ORDER) for name in names}
#: Imports against the order that are known and allowed, each with its reason (the list can only
#: shrink: a new violation fails the test).
ALLOWED = {
    ("eval/report.py", "tagloc.io"): "the report writes its TUM files with io's TUM writer",
}


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
            if RANK[other] > RANK[own] and (str(rel), module) not in ALLOWED:
                bad.append(f"{rel}:{line}: {own} imports {module} (a lower layer)")
    return bad


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


def test_the_simulator_is_a_source_only() -> None:
    """``sim`` builds message streams; running the localizer on them is ``eval``'s."""
    found = [
        f"{path.relative_to(SRC)}:{line}: {module}"
        for path in sorted((SRC / "sim").rglob("*.py"))
        for line, module in _imports(path)
        if _package(module) == "localize"
    ]
    assert found == []
