"""Occupancy grids as ROS map_server files: ``map.yaml`` + ``map.pgm``.

The format of ROS ``map_server`` / ``nav2_map_server`` (http://wiki.ros.org/map_server):

- ``map.pgm``: binary greyscale PGM (``P5``, maxval 255), row 0 = the TOP of the map.
  :func:`write_map_server` writes the trinary values ``0`` occupied (black), ``254`` free
  (white) and ``205`` unknown (grey), as ``map_saver`` does.
- ``map.yaml``: ``image`` (relative to the YAML's directory, or absolute), ``resolution``
  (m/pixel), ``origin: [x, y, yaw]`` (the map pose of the lower-left pixel), ``negate: 0``,
  ``occupied_thresh``, ``free_thresh``, ``mode: trinary``.

Reading follows map_server: a pixel ``v`` has occupancy probability ``p = (255 - v) / 255``
(``v / 255`` with ``negate: 1``); ``p > occupied_thresh`` is occupied, ``p < free_thresh``
free, anything else unknown (``trinary`` and ``scale`` classify alike; ``raw`` is refused).
The grid read back holds, per class, a log odds well inside its class: occupied
``logit((1 + occupied_thresh) / 2)``, free ``logit(free_thresh / 2)``, unknown 0.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field

from tagloc.config import StrictModel, parse_yaml_mapping, read_text_file, validate
from tagloc.errors import ConfigError
from tagloc.fileutil import atomic_path, atomic_write_text
from tagloc.io.errors import InputNotFoundError, TaglocIOError
from tagloc.lidar import OccupancyGrid

__all__ = ["MapFileError", "MapYaml", "read_map_server", "write_map_server"]

PathArg = str | os.PathLike[str]
OCCUPIED, FREE, UNKNOWN = 0, 254, 205
#: Most cells of a grid read (a 100 m x 100 m floor at 2 cm is 25 M): 200 MB as float32 log odds.
MAX_GRID_CELLS = 50_000_000
#: Largest PGM header (magic, comments, width, height, maxval), bytes.
MAX_PGM_HEADER_BYTES = 64 * 1024
#: Largest ``origin`` x / y accepted, m.
MAX_ORIGIN_M = 1e6


class MapFileError(TaglocIOError, ValueError):
    """A map YAML or PGM that cannot be read or written; the message names the file."""


_OriginXY = Annotated[float, Field(ge=-MAX_ORIGIN_M, le=MAX_ORIGIN_M)]


class MapYaml(StrictModel):
    """The map_server YAML."""

    image: str = Field(min_length=1, max_length=4096)
    resolution: float = Field(ge=1e-4, le=100.0)
    origin: tuple[_OriginXY, _OriginXY, Annotated[float, Field(ge=-1e3, le=1e3)]]
    negate: Literal[0, 1] = 0
    occupied_thresh: float = Field(0.65, gt=0.0, lt=1.0)
    free_thresh: float = Field(0.196, gt=0.0, lt=1.0)
    mode: Literal["trinary", "scale", "raw"] = "trinary"


def write_map_server(yaml_path: PathArg, grid: OccupancyGrid) -> None:
    """Write ``grid`` as ``yaml_path`` and a PGM beside it (same name, ``.pgm``), atomically."""
    yaml_path = Path(yaml_path)
    pgm_path = yaml_path.with_suffix(".pgm")
    if pgm_path == yaml_path:
        raise MapFileError(f"{yaml_path}: the map YAML must not end in .pgm")
    if abs(grid.origin_xyz_yaw[3]) > 0.0 or abs(grid.origin_xyz_yaw[2]) > 0.0:
        raise MapFileError(f"{yaml_path}: only grids with origin z = 0 and yaw = 0 are written")
    pixels = np.full(grid.shape, UNKNOWN, dtype=np.uint8)
    pixels[grid.free()] = FREE
    pixels[grid.occupied()] = OCCUPIED
    height, width = grid.shape
    header = f"P5\n# tagloc occupancy grid, {grid.resolution_m} m/pixel\n{width} {height}\n255\n"
    with atomic_path(pgm_path) as tmp, open(tmp, "wb") as handle:
        handle.write(header.encode("ascii"))
        handle.write(pixels.tobytes())
    x, y = grid.origin_xyz_yaw[:2]
    atomic_write_text(
        yaml_path,
        f"image: {pgm_path.name}\n"
        f"resolution: {grid.resolution_m!r}\n"
        f"origin: [{float(x)!r}, {float(y)!r}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {grid.occupied_thresh!r}\n"
        f"free_thresh: {grid.free_thresh!r}\n"
        "mode: trinary\n",
    )


def read_map_server(yaml_path: PathArg) -> OccupancyGrid:
    """Read a map_server YAML and its image (PGM ``P5``, 8 bit) as an :class:`OccupancyGrid`.

    Raises
    ------
    InputNotFoundError
        No such YAML.
    ConfigError
        A YAML that breaks the format (one line: ``map.yaml: field: problem``).
    MapFileError
        ``mode: raw``, an image that is not a binary 8-bit PGM, or a truncated one.
    """
    name = os.fspath(yaml_path)
    if not Path(yaml_path).is_file():
        raise InputNotFoundError(f"{name}: no such map YAML")
    text = read_text_file(yaml_path, "map YAML")
    meta = validate(MapYaml, parse_yaml_mapping(text, name), name)
    if meta.mode == "raw":
        raise MapFileError(f"{name}: mode 'raw' holds no occupancy; use trinary or scale")
    if not meta.free_thresh < meta.occupied_thresh:
        raise ConfigError(f"{name}: free_thresh: must be below occupied_thresh")
    image = Path(meta.image)
    image = image if image.is_absolute() else Path(yaml_path).parent / image
    pixels = _read_pgm(image)
    value = np.arange(256, dtype=np.float64)  # a log odds per pixel value: one lookup
    p = value / 255.0 if meta.negate else (255.0 - value) / 255.0
    table = np.zeros(256, dtype=np.float32)
    table[p > meta.occupied_thresh] = _logit((1.0 + meta.occupied_thresh) / 2.0)
    table[p < meta.free_thresh] = _logit(meta.free_thresh / 2.0)
    return OccupancyGrid(
        log_odds=table[pixels],
        resolution_m=meta.resolution,
        origin_xyz_yaw=(meta.origin[0], meta.origin[1], 0.0, meta.origin[2]),
        occupied_thresh=meta.occupied_thresh,
        free_thresh=meta.free_thresh,
    )


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


def _read_pgm(path: Path) -> np.ndarray:
    """``(H, W)`` uint8 of a binary PGM (``P5``, maxval <= 255; comments allowed), at most
    :data:`MAX_GRID_CELLS` pixels; the size is checked against the file before the pixels are
    read."""
    if path.exists() and not path.is_file():  # a directory, a FIFO, a device: never opened
        raise MapFileError(f"{path}: the map image is not a regular file")
    try:
        with open(path, "rb") as handle:
            raw = handle.read(MAX_PGM_HEADER_BYTES)
            width, height, pos = _pgm_header(path, raw)
            cells = width * height
            if cells > MAX_GRID_CELLS:
                raise MapFileError(
                    f"{path}: PGM {width}x{height} has more than {MAX_GRID_CELLS} cells"
                )
            available = os.fstat(handle.fileno()).st_size - pos
            if available < cells:
                raise MapFileError(
                    f"{path}: truncated PGM: {width}x{height} needs {cells} bytes, "
                    f"has {max(available, 0)}"
                )
            handle.seek(pos)
            body = handle.read(cells)
    except OSError as exc:
        raise MapFileError(f"{path}: cannot read map image: {exc.strerror or exc}") from None
    if len(body) < cells:  # the file shrank while being read
        raise MapFileError(f"{path}: truncated PGM while reading")
    return np.frombuffer(body, dtype=np.uint8, count=cells).reshape(height, width)


def _pgm_header(path: Path, raw: bytes) -> tuple[int, int, int]:
    """Width, height and the offset of the first pixel."""
    if raw[:2] != b"P5":
        raise MapFileError(f"{path}: not a binary PGM (P5) image")
    tokens: list[int] = []
    pos = 2
    while len(tokens) < 3:
        while pos < len(raw) and raw[pos : pos + 1].isspace():
            pos += 1
        if raw[pos : pos + 1] == b"#":
            end = raw.find(b"\n", pos)
            pos = len(raw) if end < 0 else end + 1
            continue
        start = pos
        while pos < len(raw) and raw[pos : pos + 1].isdigit():
            pos += 1
        if start == pos or pos - start > 9 or pos >= len(raw):
            raise MapFileError(f"{path}: malformed PGM header")
        tokens.append(int(raw[start:pos]))
    width, height, maxval = tokens
    if not 0 < maxval <= 255 or width <= 0 or height <= 0:
        raise MapFileError(f"{path}: PGM {width}x{height} maxval {maxval}: need 8-bit and > 0")
    if not raw[pos : pos + 1].isspace():
        raise MapFileError(f"{path}: malformed PGM header")
    return width, height, pos + 1
