"""Shared pieces of the fuzz tests: hypothesis settings, byte and value damage, the one-line check.

Byte damage inserts, deletes, replaces and truncates bytes (YAML tokens such as anchors, aliases,
brackets, tabs and invalid UTF-8 among the inserts); value damage replaces one field of a valid
document by NaN, 1e308, a huge integer, a string, a list, a nested mapping...
"""

from __future__ import annotations

import contextlib
import math
import tracemalloc
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml
from hypothesis import HealthCheck, event, settings
from hypothesis import strategies as st

from tagloc.config import MAX_QUOTED_CHARS
from tagloc.errors import TaglocError

FUZZ = settings(
    max_examples=35,
    database=None,
    derandomize=True,  # the same examples on every run; campaigns raise max_examples instead
    deadline=None,  # the shared test machine is slow at times; the suite's time is bounded by
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
TOKENS = [
    b"&a ", b"*a", b"<<: *a", b"[", b"]", b"{", b"}", b": ", b"- ", b"\n", b"\t", b"  ", b"#",
    b"'", b'"', b"!!binary ", b"!!python/object ", b"? ", b"|", b">", b"---\n", b"...\n",
    b"nan", b".inf", b"1e308", b"-1e308", b"0x" + b"f" * 40, b"9" * 30, b"\xff", b"\xc3",
    b"\x00", b"\xef\xbb\xbf", b"~", b"null", b"true", b"2001-02-31",
]  # fmt: skip
_edit = st.tuples(
    st.integers(0, 2**20),
    st.integers(0, 12),
    st.one_of(st.binary(max_size=6), st.sampled_from(TOKENS)),
)
EDITS = st.tuples(
    st.lists(_edit, min_size=1, max_size=5), st.one_of(st.none(), st.integers(0, 2**20))
)
S = 1_000_000_000
NASTY = st.one_of(
    st.sampled_from([1e308, -1e308, 1e300, 1e-300, 1e-9, 2**63 - 1, 10**18]),
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, 0, -1, 2**63, -(2**63),
                     2**64 - 1, True, None, "", "x" * 300, [], {}, [[[[]]]], {"a": {"b": 1}}]),
    st.floats(),
    st.integers(-(2**64), 2**64),
    st.text(max_size=20),
    st.lists(st.floats(allow_nan=True), max_size=8),
)  # fmt: skip


def damaged(data: bytes, edits: tuple[list[tuple[int, int, bytes]], int | None]) -> bytes:
    changes, cut = edits
    for position, deleted, inserted in changes:
        at = position % (len(data) + 1)
        data = data[:at] + inserted + data[at + deleted :]
    return data if cut is None else data[: cut % (len(data) + 1)]


def leaf_paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path into a parsed document (mappings and lists), inner nodes included."""
    paths = [prefix] if prefix else []
    items = (
        node.items()
        if isinstance(node, dict)
        else enumerate(node)
        if isinstance(node, list)
        else []
    )
    for key, child in items:
        paths += leaf_paths(child, (*prefix, key))
    return paths


def replaced(doc: Any, path: tuple[Any, ...], value: Any) -> Any:
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return doc


def expect_one_line(exc: TaglocError, path: Path) -> None:
    message = str(exc)
    assert "\n" not in message, message
    assert message.startswith(f"{path}: "), message
    assert len(message) < len(str(path)) + 400 + 2 * MAX_QUOTED_CHARS, message


def load_or_refuse(loader: Any, path: Path, data: bytes) -> Any:
    path.write_bytes(data)
    try:
        value = loader(path)
    except TaglocError as exc:
        expect_one_line(exc, path)
        event(f"refused: {type(exc).__name__}")
        return None
    event("accepted")
    return value


def value_damage(text: str, data: st.DataObject) -> str:
    doc = yaml.safe_load(text)
    path = data.draw(st.sampled_from(leaf_paths(doc)), label="path")
    return yaml.safe_dump(replaced(doc, path, data.draw(NASTY, label="value")), sort_keys=False)


@contextlib.contextmanager
def bounded_memory(limit_bytes: int) -> Iterator[None]:
    """Fail if the block's Python and numpy allocations peak above ``limit_bytes``
    (``tracemalloc``: what a size claim in a file would make a reader allocate)."""
    tracemalloc.start()
    try:
        yield
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak <= limit_bytes, f"allocated {peak} bytes, more than {limit_bytes}"
