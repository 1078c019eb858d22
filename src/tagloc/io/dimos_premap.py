"""dimos premaps: a ``sensor_msgs/PointCloud2`` LCM message in a file (``premap.pc2.lcm``).

dimos's relocalization loads its premap as ``PointCloud2.lcm_decode(path.read_bytes())``: the
file is one LCM-encoded message, no header of its own. LCM encoding (big-endian): the type's
64-bit fingerprint, then the fields in declaration order::

    int32 fields_length, int32 data_length,
    Header header {int32 seq, Time stamp {int32 sec, int32 nsec}, string frame_id},
    int32 height, int32 width,
    PointField fields[fields_length] {string name, int32 offset, uint8 datatype, int32 count},
    boolean is_bigendian, int32 point_step, int32 row_step,
    byte data[data_length], boolean is_dense

(an LCM string is an int32 length including a trailing NUL, the UTF-8 bytes and the NUL). The
point data itself is little-endian unless ``is_bigendian``.

:func:`write_pc2_lcm` writes what dimos writes (``PointCloud2.lcm_encode``): float32 ``x y z
intensity`` at offsets 0, 4, 8, 12 (intensity 0), ``height`` 1, ``is_dense``, the frame in the
header (dimos overrides it with its ``map_frame`` on load), atomically. :func:`read_pc2_lcm`
reads any such message whose ``x``, ``y``, ``z`` fields are FLOAT32 or FLOAT64, and drops rows
with a NaN; a file that is not one fails with one line naming it.
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
import numpy.typing as npt

from tagloc.fileutil import atomic_path
from tagloc.io.errors import InputNotFoundError
from tagloc.io.pointcloud_files import PointCloudFileError

__all__ = ["PC2_LCM_SUFFIX", "read_pc2_lcm", "write_pc2_lcm"]

PathArg = str | os.PathLike[str]
#: The premap file suffix dimos uses (``dimos.mapping.relocalization.module.MAP_SUFFIX``).
PC2_LCM_SUFFIX = ".pc2.lcm"
#: LCM fingerprint of ``sensor_msgs.PointCloud2`` (with its nested Header, Time, PointField).
FINGERPRINT = bytes.fromhex("f5eb3da1c2853175")
_FLOAT32, _FLOAT64 = 7, 8
_POINT_DTYPES = {(_FLOAT32, False): "<f4", (_FLOAT32, True): ">f4",
                 (_FLOAT64, False): "<f8", (_FLOAT64, True): ">f8"}  # fmt: skip


def _lcm_string(text: str) -> bytes:
    raw = text.encode("utf-8")
    return struct.pack(">I", len(raw) + 1) + raw + b"\0"


def write_pc2_lcm(path: PathArg, points: npt.ArrayLike, frame: str = "map") -> None:
    """Write ``points`` (``(N, 3)`` metres in ``frame``) as a dimos ``.pc2.lcm`` premap."""
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise PointCloudFileError(f"{os.fspath(path)}: points must have shape (N, 3), got "
                                  f"{array.shape}")  # fmt: skip
    n = len(array)
    data = np.zeros((n, 4), dtype="<f4")
    data[:, :3] = array
    payload = data.tobytes()
    out = [FINGERPRINT, struct.pack(">ii", 4, len(payload))]
    out.append(struct.pack(">iii", 0, 0, 0) + _lcm_string(frame))  # seq, sec, nsec, frame_id
    out.append(struct.pack(">ii", 1 if n else 0, n))
    for i, name in enumerate(("x", "y", "z", "intensity")):
        out.append(_lcm_string(name) + struct.pack(">iBi", 4 * i, _FLOAT32, 1))
    out.append(struct.pack(">bii", 0, 16, 16 * n))
    out.append(payload)
    out.append(struct.pack(">b", 1))
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(b"".join(out))


class _Reader:
    """Big-endian LCM fields off a byte string; a short read names the file."""

    def __init__(self, data: bytes, where: str) -> None:
        self.data, self.pos, self.where = data, 0, where

    def take(self, n: int) -> bytes:
        if n < 0 or self.pos + n > len(self.data):
            raise PointCloudFileError(f"{self.where}: truncated PointCloud2 message")
        chunk = self.data[self.pos : self.pos + n]
        self.pos += n
        return chunk

    def unpack(self, fmt: str) -> tuple[int, ...]:
        return struct.unpack(fmt, self.take(struct.calcsize(fmt)))

    def string(self) -> str:
        (size,) = self.unpack(">I")
        raw = self.take(size)
        if not raw.endswith(b"\0"):
            raise PointCloudFileError(f"{self.where}: malformed string in PointCloud2 message")
        return raw[:-1].decode("utf-8", errors="replace")


def read_pc2_lcm(path: PathArg) -> np.ndarray:
    """The ``(N, 3)`` float64 points of a ``.pc2.lcm`` premap (rows with a NaN dropped).

    Raises
    ------
    InputNotFoundError
        If the file does not exist.
    PointCloudFileError
        If it is not an LCM ``PointCloud2`` message with float ``x``, ``y``, ``z`` fields.
    """
    where = os.fspath(path)
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise InputNotFoundError(f"{where}: no such file") from None
    r = _Reader(data, where)
    if r.take(8) != FINGERPRINT:
        raise PointCloudFileError(f"{where}: not an LCM sensor_msgs/PointCloud2 message "
                                  "(fingerprint differs)")  # fmt: skip
    n_fields, data_length = r.unpack(">ii")
    r.unpack(">iii")  # seq, stamp
    r.string()  # frame_id
    height, width = r.unpack(">ii")
    fields: dict[str, tuple[int, int]] = {}
    for _ in range(max(n_fields, 0)):
        name = r.string()
        offset, datatype, _count = r.unpack(">iBi")
        fields[name] = (offset, datatype)
    (big,), (step, _row) = r.unpack(">b"), r.unpack(">ii")
    payload = r.take(data_length)
    n = height * width
    if n == 0:
        return np.zeros((0, 3))
    if any(axis not in fields for axis in "xyz"):
        raise PointCloudFileError(f"{where}: PointCloud2 has no x, y, z fields "
                                  f"(fields: {', '.join(fields) or 'none'})")  # fmt: skip
    if step <= 0 or n * step > len(payload):
        raise PointCloudFileError(f"{where}: {n} points of {step} bytes do not fit "
                                  f"{len(payload)} data bytes")  # fmt: skip
    rows = np.frombuffer(payload, dtype=np.uint8, count=n * step).reshape(n, step)
    points = np.empty((n, 3))
    for i, axis in enumerate("xyz"):
        offset, datatype = fields[axis]
        dtype = _POINT_DTYPES.get((datatype, bool(big)))
        if dtype is None or offset < 0 or offset + np.dtype(dtype).itemsize > step:
            raise PointCloudFileError(f"{where}: field {axis} (datatype {datatype}, offset "
                                      f"{offset}) is not a float inside the point")  # fmt: skip
        size = np.dtype(dtype).itemsize
        points[:, i] = np.ascontiguousarray(rows[:, offset : offset + size]).view(dtype)[:, 0]
    return points[np.isfinite(points).all(axis=1)]
