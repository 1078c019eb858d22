"""Records and rows kept on disk while a run streams, read back when the evaluation asks.

:class:`RunRecorder <tagloc.localize.outputs.RunRecorder>` keeps a whole run for evaluation;
held as Python objects, a 700 s drive's records take hundreds of MB. It spools them instead:

- :class:`RecordSpool`: whole records (fix attempts, camera frames, events), each pickled and
  framed by its length, read back as a read-only :class:`SpooledRecords` sequence that decodes
  a record when it is read (memory: one offset per record);
- :class:`RowSpool`: fixed-width numeric rows (the estimate at each odometry sample), read
  back at once into one contiguous array.

Both write to an unnamed temporary file (``tempfile.TemporaryFile`` in ``TMPDIR``: removed
from the directory as it is created, so nothing is left on disk, whatever the run's end); the
file is freed when the last reader is gone. A spool whose bytes do not read back (a short
write, a damaged file) raises :class:`SpoolError` naming the spool and the record.
"""

from __future__ import annotations

import pickle
import struct
import tempfile
from array import array
from collections.abc import Iterator, Sequence
from typing import IO, Any, Generic, TypeVar, overload

import numpy as np
import numpy.typing as npt

from tagloc.localize.fix import LocalizeError

__all__ = ["RecordSpool", "RowSpool", "SpoolError", "SpooledRecords"]

T = TypeVar("T")
_LEN = struct.Struct("<I")
_BLOCK = 1 << 20  # bytes read at once when iterating


class SpoolError(LocalizeError):
    """A spool's bytes do not read back as what was written (truncated or damaged)."""


def _store(store: IO[bytes] | None) -> IO[bytes]:
    return store if store is not None else tempfile.TemporaryFile(prefix="tagloc-spool-")


class RecordSpool(Generic[T]):
    """Appends records to a temporary file (module docstring).

    Parameters
    ----------
    name : str
        For error messages (``"fixes"``).
    store : binary file, optional
        Read-write, seekable; default an unnamed temporary file.
    """

    def __init__(self, name: str, store: IO[bytes] | None = None) -> None:
        self.name, self._store = name, _store(store)
        self._offsets = array("q")
        self._end = 0
        self._buffer: list[bytes] = []
        self._buffered = 0

    def __len__(self) -> int:
        return len(self._offsets)

    def append(self, record: T) -> None:
        data = pickle.dumps(record, protocol=pickle.HIGHEST_PROTOCOL)
        self._offsets.append(self._end + self._buffered)
        self._buffer += (_LEN.pack(len(data)), data)
        self._buffered += _LEN.size + len(data)
        if self._buffered >= _BLOCK:
            self._flush()

    def _flush(self) -> None:
        if not self._buffer:
            return
        self._store.seek(self._end)
        try:
            self._store.write(b"".join(self._buffer))
            self._store.flush()
        except OSError as exc:
            raise SpoolError(
                f"run spool {self.name!r}: cannot write: {exc.strerror or exc}"
            ) from None
        self._end += self._buffered
        self._buffer, self._buffered = [], 0

    def records(self) -> SpooledRecords[T]:
        """The records written so far, as a read-only sequence.

        Raises
        ------
        SpoolError
            If the file holds fewer bytes than were written.
        """
        self._flush()
        return SpooledRecords(self.name, self._store, self._offsets[:], self._end)


class SpooledRecords(Sequence[T]):
    """A read-only sequence of spooled records, decoded as they are read (see
    :class:`RecordSpool`)."""

    def __init__(self, name: str, store: IO[bytes], offsets: array[int], end: int) -> None:
        self.name, self._store, self._offsets, self._end = name, store, offsets, end
        size = store.seek(0, 2)
        if size < end:
            raise SpoolError(
                f"run spool {name!r}: truncated: {size} bytes of {end} written "
                f"({len(offsets)} records)"
            )

    def __len__(self) -> int:
        return len(self._offsets)

    @overload
    def __getitem__(self, index: int) -> T: ...
    @overload
    def __getitem__(self, index: slice) -> list[T]: ...
    def __getitem__(self, index: int | slice) -> T | list[T]:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        n = len(self)
        i = index + n if index < 0 else index
        if not 0 <= i < n:
            raise IndexError(f"run spool {self.name!r}: index {index} of {n} records")
        start = self._offsets[i]
        stop = self._offsets[i + 1] if i + 1 < n else self._end
        self._store.seek(start)
        return self._decode(i, self._store.read(stop - start))

    def __iter__(self) -> Iterator[T]:
        n, i = len(self), 0
        while i < n:
            j = i + 1  # a block of whole records, at least one
            while j < n and self._offsets[j] - self._offsets[i] < _BLOCK:
                j += 1
            start = self._offsets[i]
            stop = self._offsets[j] if j < n else self._end
            self._store.seek(start)
            block = self._store.read(stop - start)
            for k in range(i, j):
                a = self._offsets[k] - start
                b = (self._offsets[k + 1] if k + 1 < n else self._end) - start
                yield self._decode(k, block[a:b])
            i = j

    def __reduce__(self) -> tuple[type[list[T]], tuple[list[T]]]:
        return list, (list(self),)  # pickled (to another process) as a plain list

    def __repr__(self) -> str:
        return f"SpooledRecords({self.name!r}, {len(self)} records)"

    def _decode(self, i: int, data: bytes) -> T:
        bad = f"run spool {self.name!r}: record {i} of {len(self)} is damaged"
        if len(data) < _LEN.size or _LEN.unpack_from(data)[0] != len(data) - _LEN.size:
            raise SpoolError(f"{bad} (its length does not match)")
        try:
            record: T = pickle.loads(data[_LEN.size:])
        except Exception as exc:  # any unpickling failure of damaged bytes
            raise SpoolError(f"{bad} ({exc.__class__.__name__})") from None
        return record


class RowSpool:
    """Appends fixed-width rows of one dtype to a temporary file (module docstring).

    Parameters
    ----------
    name : str
    width : int
        Values per row.
    dtype : numpy dtype
    store : binary file, optional
    """

    def __init__(
        self, name: str, width: int, dtype: npt.DTypeLike = np.float64,
        store: IO[bytes] | None = None,
    ) -> None:  # fmt: skip
        self.name, self.width, self.dtype = name, width, np.dtype(dtype)
        self._store = _store(store)
        self._rows = 0
        self._buffer = np.empty((4096, width), dtype=self.dtype)
        self._k = 0

    def __len__(self) -> int:
        return self._rows + self._k

    def append(self, row: npt.ArrayLike) -> None:
        self._buffer[self._k] = row
        self._k += 1
        if self._k == len(self._buffer):
            self._flush()

    def _flush(self) -> None:
        if not self._k:
            return
        self._store.seek(self._rows * self.width * self.dtype.itemsize)
        try:
            self._store.write(self._buffer[: self._k].tobytes())
            self._store.flush()
        except OSError as exc:
            raise SpoolError(
                f"run spool {self.name!r}: cannot write: {exc.strerror or exc}"
            ) from None
        self._rows += self._k
        self._k = 0

    def read(self) -> np.ndarray:
        """``(N, width)``: every row written, in one new array.

        Raises
        ------
        SpoolError
            If the file holds fewer bytes than were written.
        """
        self._flush()
        want = self._rows * self.width * self.dtype.itemsize
        out = np.empty((self._rows, self.width), dtype=self.dtype)
        store: Any = self._store  # a binary file: readinto, straight into the array
        store.seek(0)
        got = store.readinto(out.data.cast("B")) if want else 0
        if got != want:
            raise SpoolError(
                f"run spool {self.name!r}: truncated: {got} bytes of {want} written "
                f"({self._rows} rows)"
            )
        return out
