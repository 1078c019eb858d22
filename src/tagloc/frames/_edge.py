"""Storage of one time-indexed (dynamic) edge: sorted stamps and samples in growing numpy arrays.

The live samples are ``[head, tail)`` of two arrays: ``stamps (capacity,) int64`` (strictly
increasing) and ``samples (capacity, 7) float64`` rows ``[qx, qy, qz, qw, tx, ty, tz]``.
Appending writes at ``tail``; eviction advances ``head``; when ``tail`` reaches the capacity the
live block is copied into fresh arrays of twice its size. So appends cost amortized O(1), a
late sample costs O(samples after it), and memory stays below about twice the live samples,
which the window bounds.
"""

from __future__ import annotations

from typing import TypeAlias

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.frames import _kernels
from tagloc.frames._validate import span
from tagloc.frames.errors import StaleSampleError

IntArray: TypeAlias = npt.NDArray[np.int64]
BoolArray: TypeAlias = npt.NDArray[np.bool_]

_MIN_CAPACITY = 16


class DynamicEdge:
    """The samples of ``T_parent_child`` over the window; see the module docstring.

    ``oldest`` and ``newest`` are the live stamps' ends as Python ints (valid when
    ``count > 0``; an edge is created with its first sample).
    """

    __slots__ = ("_data", "_head", "_stamps", "_tail", "child", "newest", "oldest", "parent")

    def __init__(self, parent: str, child: str) -> None:
        self.parent = parent
        self.child = child
        self._stamps: IntArray = np.empty(_MIN_CAPACITY, dtype=np.int64)
        self._data: FloatArray = np.empty((_MIN_CAPACITY, 7))
        self._head = 0
        self._tail = 0
        self.oldest = 0
        self.newest = 0

    # ----- inspection ------------------------------------------------------------------------
    @property
    def count(self) -> int:
        """Number of live samples."""
        return self._tail - self._head

    @property
    def nbytes(self) -> int:
        """Bytes allocated for this edge's samples (capacity, not just live samples)."""
        return int(self._stamps.nbytes + self._data.nbytes)

    # ----- insertion -------------------------------------------------------------------------
    def insert(self, stamp: int, sample: list[float], window_ns: int) -> None:
        """Insert one sample in stamp order; a sample at an existing stamp replaces it.

        Raises
        ------
        StaleSampleError
            If ``stamp < newest - window_ns``.
        """
        if self._tail == self._head or stamp > self.newest:
            self._reserve(1)
            self._stamps[self._tail] = stamp
            self._data[self._tail] = sample
            if self._tail == self._head:
                self.oldest = stamp
            self._tail += 1
            self.newest = stamp
            self._evict(window_ns)
            return
        if stamp < self.newest - window_ns:
            raise self._stale(stamp, self.newest, window_ns)
        live = self._stamps[self._head : self._tail]
        pos = self._head + int(np.searchsorted(live, stamp, "left"))
        if self._stamps[pos] == stamp:  # pos < tail because stamp <= newest
            self._data[pos] = sample
            return
        offset = pos - self._head
        self._reserve(1)  # may move the live block to index 0
        pos, pos_end = self._head + offset, self._tail
        self._stamps[pos + 1 : pos_end + 1] = self._stamps[pos:pos_end]
        self._data[pos + 1 : pos_end + 1] = self._data[pos:pos_end]
        self._stamps[pos] = stamp
        self._data[pos] = sample
        self._tail += 1
        self.oldest = min(self.oldest, stamp)

    def insert_many(self, stamps: IntArray, samples: FloatArray, window_ns: int) -> None:
        """Insert ``(N,)`` stamps with ``(N, 7)`` samples, as ``N`` calls of :meth:`insert` in
        the given order would (a later sample at an equal stamp wins), but vectorized.

        All or nothing: on error the edge is unchanged.

        Raises
        ------
        StaleSampleError
            Naming the first sample older than the newest stamp before it minus the window.
        """
        seed = self.newest if self.count else int(stamps[0])
        newest_before = np.maximum.accumulate(np.concatenate([[seed], stamps[:-1]]))
        stale = np.flatnonzero(stamps < newest_before - window_ns)
        if stale.size:
            i = int(stale[0])
            raise self._stale(int(stamps[i]), int(newest_before[i]), window_ns, index=i)
        if (self.count == 0 or stamps[0] > self.newest) and bool(np.all(np.diff(stamps) > 0)):
            n = len(stamps)
            self._reserve(n)
            self._stamps[self._tail : self._tail + n] = stamps
            self._data[self._tail : self._tail + n] = samples
            if self.count == 0:
                self.oldest = int(stamps[0])
            self._tail += n
            self.newest = int(stamps[-1])
            self._evict(window_ns)
            return
        # General case: merge, keep the last sample of each stamp, evict, store afresh.
        all_stamps = np.concatenate([self._stamps[self._head : self._tail], stamps])
        all_data = np.concatenate([self._data[self._head : self._tail], samples])
        order = np.argsort(all_stamps, kind="stable")
        sorted_stamps = all_stamps[order]
        keep = np.append(sorted_stamps[1:] != sorted_stamps[:-1], True)
        sorted_stamps, sorted_data = sorted_stamps[keep], all_data[order[keep]]
        start = int(np.searchsorted(sorted_stamps, sorted_stamps[-1] - window_ns, "left"))
        self._store(sorted_stamps[start:], sorted_data[start:])

    def _reserve(self, extra: int) -> None:
        """Make room for ``extra`` samples after ``tail`` (reallocating to twice the need)."""
        if self._tail + extra <= len(self._stamps):
            return
        self._store(
            self._stamps[self._head : self._tail], self._data[self._head : self._tail], extra
        )

    def _store(self, stamps: IntArray, data: FloatArray, extra: int = 0) -> None:
        n = len(stamps)
        capacity = max(_MIN_CAPACITY, 2 * (n + extra))
        self._stamps = np.empty(capacity, dtype=np.int64)
        self._data = np.empty((capacity, 7))
        self._stamps[:n] = stamps
        self._data[:n] = data
        self._head, self._tail = 0, n
        if n:
            self.oldest, self.newest = int(stamps[0]), int(stamps[-1])

    def _evict(self, window_ns: int) -> None:
        """Drop the samples older than ``newest - window_ns`` (the newest always stays)."""
        cutoff = self.newest - window_ns
        if self.oldest >= cutoff:
            return
        live = self._stamps[self._head : self._tail]
        self._head += int(np.searchsorted(live, cutoff, "left"))
        self.oldest = int(self._stamps[self._head])

    def _stale(
        self, stamp: int, newest: int, window_ns: int, index: int | None = None
    ) -> StaleSampleError:
        which = "" if index is None else f" (sample {index} of the batch)"
        return StaleSampleError(
            f"edge '{self.parent}' -> '{self.child}': sample at {span(stamp)}{which} is older "
            f"than the window allows: newest is {span(newest)}, window {span(window_ns)}, so "
            f"the oldest accepted stamp is {span(newest - window_ns)}"
        )

    # ----- lookup ----------------------------------------------------------------------------
    def covers(self, stamp: int, tolerance_ns: int) -> bool:
        """True if ``stamp`` is within ``[oldest - tolerance, newest + tolerance]``."""
        return self.oldest - tolerance_ns <= stamp <= self.newest + tolerance_ns

    def sample(self, stamp: int, tolerance_ns: int) -> list[float] | None:
        """The interpolated sample at ``stamp``, the end sample within the tolerance beyond
        either end, or ``None`` further out."""
        if stamp >= self.newest:
            if stamp - self.newest > tolerance_ns:
                return None
            row: list[float] = self._data[self._tail - 1].tolist()
            return row
        if stamp <= self.oldest:
            if self.oldest - stamp > tolerance_ns:
                return None
            row = self._data[self._head].tolist()
            return row
        live = self._stamps[self._head : self._tail]
        i = self._head + int(np.searchsorted(live, stamp, "right"))  # stamps[i-1] <= stamp
        t0, t1 = self._stamps[i - 1 : i + 1].tolist()
        s0, s1 = self._data[i - 1 : i + 1].tolist()
        if stamp == t0:
            return list(s0)
        return _kernels.interpolate_sample(s0, s1, (stamp - t0) / (t1 - t0))

    def outside(self, stamps: IntArray, tolerance_ns: int) -> BoolArray:
        """Mask of ``stamps`` beyond the tolerance outside the buffered range."""
        mask: BoolArray = (stamps < self.oldest - tolerance_ns) | (
            stamps > self.newest + tolerance_ns
        )
        return mask

    def sample_many(self, stamps: IntArray) -> FloatArray:
        """Samples ``(N, 7)`` at ``stamps``, holding the end samples beyond the range (check
        :meth:`outside` first)."""
        live = self._stamps[self._head : self._tail]
        data = self._data[self._head : self._tail]
        if len(live) == 1:
            return np.repeat(data, len(stamps), axis=0)
        i = np.clip(np.searchsorted(live, stamps, "right"), 1, len(live) - 1)
        t0, t1 = live[i - 1], live[i]
        alpha = np.clip((stamps - t0) / (t1 - t0), 0.0, 1.0)
        return _kernels.interpolate_samples_many(data[i - 1], data[i], alpha)
