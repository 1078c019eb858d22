"""The headers of PLY and PCD files: where the points are and what they hold (no point read).

:func:`ply_layout` / :func:`pcd_layout` read at most :data:`MAX_HEADER_BYTES` of an open file and
return its :class:`Layout`, after checking the fields (``x``, ``y``, ``z`` present, at most
:data:`MAX_FIELDS`, no duplicates) and that the file holds every record the header announces.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np

from tagloc.config import short_repr
from tagloc.io.errors import TaglocIOError

#: Longest header read, bytes (a header is a few hundred).
MAX_HEADER_BYTES = 64 * 1024
#: Most fields (PCD ``COUNT`` repeats included) a point may have.
MAX_FIELDS = 256
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2", "int16": "<i2",
    "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4", "uint": "<u4",
    "uint32": "<u4", "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8",
}  # fmt: skip
_PCD_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "i1", ("I", 2): "<i2",
              ("I", 4): "<i4", ("I", 8): "<i8", ("U", 1): "u1", ("U", 2): "<u2",
              ("U", 4): "<u4", ("U", 8): "<u8"}  # fmt: skip


class PointCloudFileError(TaglocIOError, ValueError):
    """A PLY / PCD file that cannot be read or written; the message names the file."""


@dataclass(frozen=True, slots=True)
class Layout:
    """Where the points of a file are: ``count`` records of ``dtype`` from byte ``offset``."""

    name: str
    offset: int
    dtype: np.dtype
    count: int


def _head(name: str, handle: BinaryIO) -> bytes:
    try:
        return handle.read(MAX_HEADER_BYTES + 1)
    except OSError as exc:
        raise PointCloudFileError(f"{name}: cannot read: {exc.strerror or exc}") from None


def ply_layout(name: str, handle: BinaryIO) -> Layout:
    raw = _head(name, handle)
    lines, offset = _header(name, raw, b"end_header\n", "PLY")
    if not lines or lines[0] != "ply":
        raise PointCloudFileError(f"{name}: not a PLY file (no 'ply' magic line)")
    fields: list[tuple[str, str]] = []
    count, element, fmt = -1, "", ""
    for line in lines[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info", "end_header"):
            continue
        if words[0] == "format":
            fmt = words[1] if len(words) > 1 else ""
        elif words[0] == "element" and len(words) == 3:
            if count >= 0 and element == "vertex":
                break  # later elements (faces) come after the vertices: not read
            element, count = words[1], _int(name, words[2], "element count")
            if element != "vertex":
                raise PointCloudFileError(
                    f"{name}: first element is {short_repr(element)}, not 'vertex'"
                )
        elif words[0] == "property" and element == "vertex":
            if len(words) != 3 or words[1] not in _PLY_TYPES:
                raise PointCloudFileError(f"{name}: unsupported vertex property {short_repr(line)}")
            fields.append((words[2], _PLY_TYPES[words[1]]))
        else:
            raise PointCloudFileError(f"{name}: malformed PLY header line {short_repr(line)}")
    if fmt != "binary_little_endian":
        raise PointCloudFileError(
            f"{name}: PLY format {short_repr(fmt or 'missing')}; only binary_little_endian is read"
        )
    if count < 0:
        raise PointCloudFileError(f"{name}: no 'element vertex' in the PLY header")
    return _layout(name, handle, offset, fields, count)


def pcd_layout(name: str, handle: BinaryIO) -> Layout:
    raw = _head(name, handle)
    keys: dict[str, list[str]] = {}
    end = raw.find(b"\nDATA ")
    if end < 0 or end > MAX_HEADER_BYTES:
        raise PointCloudFileError(f"{name}: not a PCD file (no DATA line in the header)")
    lines, offset = _header(name, raw, b"\n", "PCD", start=end + 1)
    for line in lines:
        words = line.split()
        if words and not words[0].startswith("#"):
            keys[words[0].upper()] = words[1:]
    for key in ("FIELDS", "SIZE", "TYPE", "POINTS", "DATA"):
        if key not in keys:
            raise PointCloudFileError(f"{name}: PCD header has no {key} line")
    if keys["DATA"] != ["binary"]:
        raise PointCloudFileError(
            f"{name}: PCD DATA {short_repr(' '.join(keys['DATA']))}; only 'binary' is read"
        )
    names, sizes, types = keys["FIELDS"], keys["SIZE"], keys["TYPE"]
    counts = keys.get("COUNT", ["1"] * len(names))
    if not len(names) == len(sizes) == len(types) == len(counts):
        raise PointCloudFileError(f"{name}: PCD FIELDS, SIZE, TYPE and COUNT differ in length")
    fields: list[tuple[str, str]] = []
    for field, size, kind, repeat in zip(names, sizes, types, counts, strict=True):
        dtype = _PCD_TYPES.get((kind.upper(), _int(name, size, "SIZE")))
        if dtype is None:
            raise PointCloudFileError(
                f"{name}: unsupported PCD field {short_repr(f'{field} {kind}{size}')}"
            )
        reps = _int(name, repeat, "COUNT")
        if len(fields) + reps > MAX_FIELDS:
            raise PointCloudFileError(f"{name}: more than {MAX_FIELDS} fields per point (COUNT)")
        fields += [(field if reps == 1 else f"{field}_{k}", dtype) for k in range(reps)]
    points = _int(name, keys["POINTS"][0] if keys["POINTS"] else "", "POINTS")
    return _layout(name, handle, offset, fields, points)


def _header(name: str, raw: bytes, end: bytes, kind: str, start: int = 0) -> tuple[list[str], int]:
    """Header lines and the offset of the first byte after the header (which ends with ``end``
    at or after ``start``)."""
    stop = raw.find(end, start)
    if stop < 0 or stop > MAX_HEADER_BYTES:
        raise PointCloudFileError(f"{name}: truncated or not a {kind} file (no end of header)")
    try:
        text = raw[: stop + len(end)].decode("ascii")
    except UnicodeDecodeError:
        raise PointCloudFileError(f"{name}: {kind} header is not ASCII text") from None
    return [line.strip() for line in text.splitlines() if line.strip()], stop + len(end)


def _int(name: str, text: str, what: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise PointCloudFileError(f"{name}: {what} {short_repr(text)} is not an integer") from None
    if value < 0:
        raise PointCloudFileError(f"{name}: {what} {value} is negative")
    if value > 2**48:  # no file holds that many points (nor fields of that size)
        raise PointCloudFileError(f"{name}: {what} {short_repr(value)} is too large")
    return value


def _layout(
    name: str, handle: BinaryIO, offset: int, fields: list[tuple[str, str]], count: int
) -> Layout:
    """Check the fields and that the file holds the ``count`` records the header announces."""
    field_names = [f for f, _ in fields]
    missing = [axis for axis in "xyz" if axis not in field_names]
    if missing:
        raise PointCloudFileError(
            f"{name}: no field {', '.join(missing)} (fields: {short_repr(' '.join(field_names))})"
        )
    if len(fields) > MAX_FIELDS:
        raise PointCloudFileError(f"{name}: more than {MAX_FIELDS} fields per point")
    if len(set(field_names)) != len(field_names):
        raise PointCloudFileError(
            f"{name}: duplicate field names {short_repr(' '.join(field_names))}"
        )
    dtype = np.dtype(fields)
    size = os.fstat(handle.fileno()).st_size - offset
    if size < count * dtype.itemsize:
        raise PointCloudFileError(
            f"{name}: truncated: {count} points need {count * dtype.itemsize} bytes, "
            f"the file has {max(size, 0)}"
        )
    return Layout(name, offset, dtype, count)
