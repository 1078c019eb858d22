"""A default install (``pip install tagloc``, no extras) pulls no GPL package.

tagloc is Apache-2.0. evo (GPL-3.0) is the ATE/RPE test oracle and lives in the ``dev`` extra
only; nothing under ``src/`` imports it. The closure of the default dependencies is walked
through the installed metadata (``importlib.metadata``); a package whose licence metadata says
nothing is skipped (it cannot be judged here), one that says GPL (not LGPL) fails.
"""

from __future__ import annotations

import ast
import re
import tomllib
from importlib import metadata
from pathlib import Path

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[2]
GPL = re.compile(r"\bA?GPL|GNU (Affero )?General Public", re.IGNORECASE)
LGPL = re.compile(r"\bLGPL|Lesser General Public|Library General Public", re.IGNORECASE)
COPYLEFT_ONLY = {"evo"}


def _default_requirements() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    return [Requirement(r) for r in project["dependencies"]]


def _licence_text(dist: metadata.Distribution) -> str:
    meta = dist.metadata
    fields = [meta.get("License-Expression") or "", meta.get("License") or ""]
    fields += [c for c in meta.get_all("Classifier") or [] if c.startswith("License ::")]
    return " ".join(f.splitlines()[0] if f else "" for f in fields)


def _closure() -> dict[str, metadata.Distribution]:
    seen: dict[str, metadata.Distribution] = {}
    todo = _default_requirements()
    while todo:
        req = todo.pop()
        name = req.name.lower().replace("_", "-")
        if name in seen or (req.marker is not None and not req.marker.evaluate({"extra": ""})):
            continue
        try:
            dist = metadata.distribution(req.name)
        except metadata.PackageNotFoundError:
            continue  # not installed on this platform: nothing to judge
        seen[name] = dist
        todo += [Requirement(r) for r in dist.requires or []]
    return seen


def _is_gpl(text: str) -> bool:
    return bool(GPL.search(LGPL.sub("", text)))


def test_default_dependencies_name_no_gpl_package() -> None:
    names = {r.name.lower() for r in _default_requirements()}
    assert not names & COPYLEFT_ONLY


def test_the_default_dependency_closure_has_no_gpl_licence() -> None:
    closure = _closure()
    assert "numpy" in closure  # the walk found the installed packages
    gpl = {name: _licence_text(d) for name, d in closure.items() if _is_gpl(_licence_text(d))}
    assert gpl == {}


def test_the_licence_check_sees_gpl() -> None:
    assert _is_gpl("License :: OSI Approved :: GNU General Public License v3 (GPLv3)")
    assert _is_gpl("GPL-3.0-or-later")
    assert not _is_gpl("License :: OSI Approved :: GNU Lesser General Public License v3 (LGPLv3)")
    assert not _is_gpl("Apache-2.0")
    try:
        evo = metadata.distribution("evo")
    except metadata.PackageNotFoundError:
        return
    assert _is_gpl(_licence_text(evo))  # the oracle itself (installed with the dev extra)


def test_no_module_under_src_imports_evo() -> None:
    offenders = []
    for path in sorted((ROOT / "src").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = (
                [a.name for a in node.names] if isinstance(node, ast.Import)
                else [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            )  # fmt: skip
            if any(n == "evo" or n.startswith("evo.") for n in names):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert offenders == []
