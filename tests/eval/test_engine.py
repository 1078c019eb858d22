"""The engines: the same results in the items' order, in series or on a process pool; a failing
item's own exception."""

from __future__ import annotations

import math

import pytest

from tagloc.eval.engine import ProcessEngine, SerialEngine


def test_a_pool_returns_what_series_returns_in_order() -> None:
    items = [float(i) for i in range(7)]
    done: list[tuple[int, int]] = []
    pooled = ProcessEngine(2).map(math.sqrt, items, lambda k, n: done.append((k, n)))
    assert pooled == SerialEngine().map(math.sqrt, items) == [math.sqrt(x) for x in items]
    assert done[-1] == (7, 7) and all(n == 7 for _, n in done)


def test_a_failing_item_raises_its_own_error() -> None:
    with pytest.raises(ValueError, match="math domain error"):
        ProcessEngine(2).map(math.sqrt, [1.0, -1.0, 4.0])


def test_jobs_must_be_positive() -> None:
    with pytest.raises(ValueError, match="jobs must be >= 1"):
        ProcessEngine(0)
