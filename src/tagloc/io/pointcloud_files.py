"""Point-cloud files: PLY and PCD, binary little-endian float32 ``x y z`` (the premap).

Written by :func:`write_ply` / :func:`write_pcd` with a header comment naming the frame
(``frame map``) and atomically (a temporary file renamed over the target). Read back by
:func:`read_ply` / :func:`read_pcd`, which also accept other writers' binary files whose vertex
or point fields include ``x``, ``y``, ``z`` (other fields, any numeric type, are skipped; PLY
``binary_little_endian`` with ``vertex`` as its first element, PCD ``DATA binary``). A truncated
or malformed file fails with one line naming it (:class:`PointCloudFileError`).

Bounds, checked against the header and the file's size before any point is read: a header of at
most 64 KiB and 256 fields (:mod:`tagloc.io._cloud_headers`); the points the header announces
present in the file; at most ``max_points`` of them (:data:`MAX_POINTS`, 5 M, by default: 120 MB
as float64); every coordinate finite and within :data:`MAX_COORDINATE_M` (NaN rows of organized
clouds are refused too: a premap is a map, not a sweep). The body is read in blocks of
:data:`BLOCK_POINTS`, so a read needs the output and one block. :func:`read_premap` reads up to
:data:`MAX_PREMAP_POINTS` (20 M, a sanity limit) and voxel-downsamples a premap of more than
:data:`PREMAP_KEEP_POINTS` (1 M, a performance limit: registration downsamples the premap to its
own voxel anyway) block by block, at the finest of 5, 10, 20, ... cm that keeps at most that many
(a voxel that straddles blocks gets the mean of the blocks' centroids).
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np
import numpy.typing as npt

from tagloc.fileutil import atomic_path
from tagloc.io._cloud_headers import (
    Layout,
    PointCloudFileError,
    pcd_layout,
    ply_layout,
)
from tagloc.io.errors import InputNotFoundError

__all__ = [
    "MAX_POINTS",
    "MAX_PREMAP_POINTS",
    "PREMAP_KEEP_POINTS",
    "PointCloudFileError",
    "read_pcd",
    "read_ply",
    "read_premap",
    "write_pcd",
    "write_ply",
]

logger = logging.getLogger(__name__)

PathArg = str | os.PathLike[str]
#: Most points :func:`read_ply` / :func:`read_pcd` return by default (120 MB as float64).
MAX_POINTS = 5_000_000
#: Most points a premap file may hold (240 MB of float32 x y z): more is refused.
MAX_PREMAP_POINTS = 20_000_000
#: A premap of more points is voxel-downsampled on reading to at most this many.
PREMAP_KEEP_POINTS = 1_000_000
#: The finest voxel of that downsampling, m (doubled until the premap fits).
PREMAP_VOXEL_M = 0.05
#: Largest accepted coordinate magnitude, m (float32 resolves 1 cm up to 1e5 m).
MAX_COORDINATE_M = 1e5
#: Points converted per block.
BLOCK_POINTS = 500_000


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


def read_ply(path: PathArg, *, max_points: int = MAX_POINTS) -> np.ndarray:
    """``(N, 3)`` float64 points of a binary little-endian PLY file's ``vertex`` element.

    Raises
    ------
    InputNotFoundError
        No such file.
    PointCloudFileError
        Not PLY, not ``binary_little_endian``, no ``x``/``y``/``z``, a list property in
        ``vertex``, fewer bytes than the header announces, more than ``max_points`` points, or a
        coordinate that is not finite or beyond :data:`MAX_COORDINATE_M`.
    """
    with _open(path) as (name, handle):
        return _read_all(ply_layout(name, handle), handle, max_points)


def read_pcd(path: PathArg, *, max_points: int = MAX_POINTS) -> np.ndarray:
    """``(N, 3)`` float64 points of a ``DATA binary`` PCD file.

    Raises
    ------
    InputNotFoundError
        No such file.
    PointCloudFileError
        Missing or inconsistent FIELDS / SIZE / TYPE / COUNT / POINTS, ``DATA`` other than
        ``binary``, no ``x``/``y``/``z``, fewer bytes than the header announces, more than
        ``max_points`` points, or a coordinate that is not finite or beyond
        :data:`MAX_COORDINATE_M`.
    """
    with _open(path) as (name, handle):
        return _read_all(pcd_layout(name, handle), handle, max_points)


def read_premap(path: PathArg) -> np.ndarray:
    """``(N, 3)`` float64 premap points of a ``.ply`` or ``.pcd`` file, at most
    :data:`PREMAP_KEEP_POINTS` (voxel-downsampled on reading beyond that; module docstring).

    Raises
    ------
    InputNotFoundError, PointCloudFileError
        As :func:`read_ply` / :func:`read_pcd`; a file of more than :data:`MAX_PREMAP_POINTS`
        points, or a suffix other than ``.ply`` / ``.pcd``.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in (".ply", ".pcd"):
        raise PointCloudFileError(f"{os.fspath(path)}: expected a .ply or .pcd premap file")
    with _open(path) as (name, handle):
        layout = (ply_layout if suffix == ".ply" else pcd_layout)(name, handle)
        _check_count(layout, MAX_PREMAP_POINTS)
        if layout.count <= PREMAP_KEEP_POINTS:
            return _read_all(layout, handle, PREMAP_KEEP_POINTS)
        from tagloc.lidar.cloud import voxel_downsample

        voxel_m, kept = PREMAP_VOXEL_M, np.zeros((0, 3))
        for block in _blocks(layout, handle):  # memory: the points kept and one block
            kept = voxel_downsample(np.concatenate([kept, block]), voxel_m)
            while len(kept) > PREMAP_KEEP_POINTS:
                voxel_m *= 2.0
                kept = voxel_downsample(kept, voxel_m)
    logger.info(
        "%s: %d points downsampled on reading to %d (%g m voxels; at most %d are kept)",
        name, layout.count, len(kept), voxel_m, PREMAP_KEEP_POINTS,
    )  # fmt: skip
    return kept


@contextlib.contextmanager
def _open(path: PathArg) -> Iterator[tuple[str, BinaryIO]]:
    name = os.fspath(path)
    if not Path(path).is_file():
        raise InputNotFoundError(f"{name}: no such point-cloud file")
    try:
        handle = open(path, "rb")  # noqa: SIM115 (closed below)
    except OSError as exc:
        raise PointCloudFileError(f"{name}: cannot read: {exc.strerror or exc}") from None
    with handle:
        yield name, handle


def _check_count(layout: Layout, max_points: int) -> None:
    if layout.count > max_points:
        raise PointCloudFileError(
            f"{layout.name}: {layout.count} points, more than the {max_points} read at most"
        )


def _read_all(layout: Layout, handle: BinaryIO, max_points: int) -> np.ndarray:
    _check_count(layout, max_points)
    out = np.empty((layout.count, 3), dtype=np.float64)
    done = 0
    for block in _blocks(layout, handle):
        out[done : done + len(block)] = block
        done += len(block)
    return out


def _blocks(layout: Layout, handle: BinaryIO) -> Iterator[np.ndarray]:
    """The points as ``(k, 3)`` float64 blocks of at most :data:`BLOCK_POINTS`, each checked."""
    handle.seek(layout.offset)
    for start in range(0, layout.count, BLOCK_POINTS):
        n = min(BLOCK_POINTS, layout.count - start)
        data = handle.read(n * layout.dtype.itemsize)
        if len(data) < n * layout.dtype.itemsize:  # the file shrank while being read
            raise PointCloudFileError(f"{layout.name}: truncated while reading")
        records = np.frombuffer(data, dtype=layout.dtype, count=n)
        with np.errstate(invalid="ignore"):  # signalling NaNs in the file: refused below
            block = np.stack([records[axis].astype(np.float64) for axis in "xyz"], axis=1)
        bad = ~(np.abs(block) <= MAX_COORDINATE_M).all(axis=1)  # NaN compares False
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise PointCloudFileError(
                f"{layout.name}: point {start + k} {block[k].tolist()}: coordinates must be "
                f"finite and within {MAX_COORDINATE_M:g} m ({int(bad.sum())} of points "
                f"{start}..{start + n - 1} are not)"
            )
        yield block.reshape(-1, 3)
