"""Point-cloud files: PLY and PCD, binary little-endian float32 ``x y z`` (the premap).

Written by :func:`write_ply` / :func:`write_pcd` with a header comment naming the frame
(``frame map``) and atomically (a temporary file renamed over the target). Read back by
:func:`read_ply` / :func:`read_pcd`, which also accept other writers' binary files whose vertex
or point fields include ``x``, ``y``, ``z`` (other fields, any numeric type, are skipped; PLY
``binary_little_endian`` with ``vertex`` as its first element, PCD ``DATA binary``). A truncated
or malformed file fails with one line naming it (:class:`PointCloudFileError`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import numpy.typing as npt

from tagloc.fileutil import atomic_path
from tagloc.io.errors import InputNotFoundError, TaglocIOError

__all__ = ["PointCloudFileError", "read_pcd", "read_ply", "write_pcd", "write_ply"]

PathArg = str | os.PathLike[str]
#: Longest header read, bytes (a header is a few hundred).
MAX_HEADER_BYTES = 64 * 1024
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


def _float32_points(path: PathArg, points: npt.ArrayLike) -> np.ndarray:
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise PointCloudFileError(
            f"{os.fspath(path)}: points must have shape (N, 3), got {array.shape}"
        )
    return np.ascontiguousarray(array, dtype="<f4")


def write_ply(path: PathArg, points: npt.ArrayLike, frame: str = "map") -> None:
    """Write ``points`` (``(N, 3)`` metres in ``frame``) as binary little-endian float32 PLY."""
    data = _float32_points(path, points)
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"comment frame {frame}\ncomment units m\n"
        f"element vertex {len(data)}\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n"
    )
    _write(path, header.encode("ascii"), data)


def write_pcd(path: PathArg, points: npt.ArrayLike, frame: str = "map") -> None:
    """Write ``points`` (``(N, 3)`` metres in ``frame``) as PCD v0.7 ``DATA binary`` float32."""
    data = _float32_points(path, points)
    n = len(data)
    header = (
        f"# .PCD v0.7 - frame {frame}, units m\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\n"
        f"TYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
        f"POINTS {n}\nDATA binary\n"
    )
    _write(path, header.encode("ascii"), data)


def _write(path: PathArg, header: bytes, data: np.ndarray) -> None:
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        handle.write(header)
        handle.write(data.tobytes())


def read_ply(path: PathArg) -> np.ndarray:
    """``(N, 3)`` float64 points of a binary little-endian PLY file's ``vertex`` element.

    Raises
    ------
    InputNotFoundError
        No such file.
    PointCloudFileError
        Not PLY, not ``binary_little_endian``, no ``x``/``y``/``z``, a list property in
        ``vertex``, or fewer bytes than the header announces.
    """
    name, raw = _read(path)
    lines, body = _header(name, raw, b"end_header\n", "PLY")
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
                raise PointCloudFileError(f"{name}: first element is {element!r}, not 'vertex'")
        elif words[0] == "property" and element == "vertex":
            if len(words) != 3 or words[1] not in _PLY_TYPES:
                raise PointCloudFileError(f"{name}: unsupported vertex property {line!r}")
            fields.append((words[2], _PLY_TYPES[words[1]]))
        else:
            raise PointCloudFileError(f"{name}: malformed PLY header line {line!r}")
    if fmt != "binary_little_endian":
        raise PointCloudFileError(
            f"{name}: PLY format {fmt or 'missing'!r}; only binary_little_endian is read"
        )
    if count < 0:
        raise PointCloudFileError(f"{name}: no 'element vertex' in the PLY header")
    return _points(name, body, fields, count)


def read_pcd(path: PathArg) -> np.ndarray:
    """``(N, 3)`` float64 points of a ``DATA binary`` PCD file.

    Raises
    ------
    InputNotFoundError
        No such file.
    PointCloudFileError
        Missing or inconsistent FIELDS / SIZE / TYPE / COUNT / POINTS, ``DATA`` other than
        ``binary``, no ``x``/``y``/``z``, or fewer bytes than the header announces.
    """
    name, raw = _read(path)
    keys: dict[str, list[str]] = {}
    end = raw.find(b"\nDATA ")
    if end < 0 or end > MAX_HEADER_BYTES:
        raise PointCloudFileError(f"{name}: not a PCD file (no DATA line in the header)")
    lines, body = _header(name, raw, b"\n", "PCD", start=end + 1)
    for line in lines:
        words = line.split()
        if words and not words[0].startswith("#"):
            keys[words[0].upper()] = words[1:]
    for key in ("FIELDS", "SIZE", "TYPE", "POINTS", "DATA"):
        if key not in keys:
            raise PointCloudFileError(f"{name}: PCD header has no {key} line")
    if keys["DATA"] != ["binary"]:
        raise PointCloudFileError(
            f"{name}: PCD DATA {' '.join(keys['DATA'])!r}; only 'binary' is read"
        )
    names, sizes, types = keys["FIELDS"], keys["SIZE"], keys["TYPE"]
    counts = keys.get("COUNT", ["1"] * len(names))
    if not len(names) == len(sizes) == len(types) == len(counts):
        raise PointCloudFileError(f"{name}: PCD FIELDS, SIZE, TYPE and COUNT differ in length")
    fields: list[tuple[str, str]] = []
    for field, size, kind, repeat in zip(names, sizes, types, counts, strict=True):
        dtype = _PCD_TYPES.get((kind.upper(), _int(name, size, "SIZE")))
        if dtype is None:
            raise PointCloudFileError(f"{name}: unsupported PCD field {field} {kind}{size}")
        reps = _int(name, repeat, "COUNT")
        fields += [(field if reps == 1 else f"{field}_{k}", dtype) for k in range(reps)]
    return _points(
        name, body, fields, _int(name, keys["POINTS"][0] if keys["POINTS"] else "", "POINTS")
    )


def _read(path: PathArg) -> tuple[str, bytes]:
    name = os.fspath(path)
    if not Path(path).is_file():
        raise InputNotFoundError(f"{name}: no such point-cloud file")
    try:
        return name, Path(path).read_bytes()
    except OSError as exc:
        raise PointCloudFileError(f"{name}: cannot read: {exc.strerror or exc}") from None


def _header(
    name: str, raw: bytes, end: bytes, kind: str, start: int = 0
) -> tuple[list[str], bytes]:
    """Header lines and the bytes after the header (which ends with ``end`` at/after ``start``)."""
    stop = raw.find(end, start)
    if stop < 0 or stop > MAX_HEADER_BYTES:
        raise PointCloudFileError(f"{name}: truncated or not a {kind} file (no end of header)")
    try:
        text = raw[: stop + len(end)].decode("ascii")
    except UnicodeDecodeError:
        raise PointCloudFileError(f"{name}: {kind} header is not ASCII text") from None
    return [line.strip() for line in text.splitlines() if line.strip()], raw[stop + len(end) :]


def _int(name: str, text: str, what: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise PointCloudFileError(f"{name}: {what} {text!r} is not an integer") from None
    if value < 0:
        raise PointCloudFileError(f"{name}: {what} {value} is negative")
    return value


def _points(name: str, body: bytes, fields: list[tuple[str, str]], count: int) -> np.ndarray:
    field_names = [f for f, _ in fields]
    missing = [axis for axis in "xyz" if axis not in field_names]
    if missing:
        raise PointCloudFileError(
            f"{name}: no field {', '.join(missing)} (fields: {' '.join(field_names)})"
        )
    if len(set(field_names)) != len(field_names):
        raise PointCloudFileError(f"{name}: duplicate field names {' '.join(field_names)}")
    dtype = np.dtype(fields)
    if len(body) < count * dtype.itemsize:
        raise PointCloudFileError(
            f"{name}: truncated: {count} points need {count * dtype.itemsize} bytes, "
            f"the file has {len(body)}"
        )
    records = np.frombuffer(body, dtype=dtype, count=count)
    return np.stack([records[axis].astype(np.float64) for axis in "xyz"], axis=1).reshape(-1, 3)
