"""The node's one queue of work waiting for odometry: each fix source's items, by readiness.

An item is ready once the odometry covers its ``ready_ns`` (a camera frame's stamp, a sweep's
last point); ready items run in ``(ready_ns, arrival)`` order, whichever source they are from.
Each source has its own bound (:attr:`~tagloc.localize.sources.FixSource.max_waiting`): beyond
it the source's oldest item is dropped (no odometry reaches it).
"""

from __future__ import annotations

import heapq
from collections import Counter
from collections.abc import Iterator

from tagloc.localize.sources import FixSource, Work

__all__ = ["WorkQueue"]


class WorkQueue:
    """Items of several sources, popped when due (module docstring)."""

    def __init__(self) -> None:
        self._heap: list[tuple[int, int, int, Work]] = []  # (ready, seq, source index, work)
        self._seq = 0
        self._count: Counter[int] = Counter()

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, index: int, source: FixSource, work: Work) -> bool:
        """Queue ``work`` of ``sources[index]``; True when its oldest item was dropped for it."""
        dropped = False
        if self._count[index] >= source.max_waiting:
            own = (item for item in self._heap if item[2] == index)
            oldest = min(own, key=lambda item: (item[3].stamp_ns, item[1]))
            self._heap.remove(oldest)
            heapq.heapify(self._heap)
            self._count[index] -= 1
            dropped = True
        self._seq += 1
        heapq.heappush(self._heap, (work.ready_ns, self._seq, index, work))
        self._count[index] += 1
        return dropped

    def due(self, odom_ns: int | None) -> Iterator[tuple[int, Work]]:
        """Pop ``(source index, work)`` of the items the odometry up to ``odom_ns`` covers (None:
        all), in order; items pushed meanwhile are included when due."""
        while self._heap and (odom_ns is None or self._heap[0][0] <= odom_ns):
            _, _, index, work = heapq.heappop(self._heap)
            self._count[index] -= 1
            yield index, work

    def clear(self) -> Counter[int]:
        """Drop everything; return the number dropped per source index."""
        dropped = Counter({k: v for k, v in self._count.items() if v})
        self._heap.clear()
        self._count.clear()
        return dropped
