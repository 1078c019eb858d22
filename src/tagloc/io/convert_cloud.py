"""``sensor_msgs/PointCloud2`` to :class:`~tagloc.messages.PointCloudMsg` (see
:mod:`tagloc.io.convert` for the fields read and the time conventions), bounded.

Limits, checked on the message's announced size before any point is copied:

- :data:`MAX_SWEEP_POINTS` (2 M) points at most (a sanity limit: a 128-beam spinning lidar
  makes 260 k per sweep at 2048 columns): more is ``Bad("bad_point_cloud")``.
- A sweep of more than :data:`SWEEP_KEEP_POINTS` (200 k, a performance limit) is thinned on
  reading to the first point (with its intensity and time) in each cube of 5 cm, doubled until at
  most that many are left: registration downsamples to 15-25 cm anyway.
- A point farther than :data:`MAX_POINT_RANGE_M` from the scanner is no return (NaN row, as a
  beam without return); point times must span at most :data:`MAX_SWEEP_SPAN_S`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from tagloc.io.decoded import Bad, Decoded, DecodeOptions, stamp_of
from tagloc.messages import PointCloudMsg

__all__ = [
    "MAX_POINT_RANGE_M",
    "MAX_SWEEP_POINTS",
    "MAX_SWEEP_SPAN_S",
    "SWEEP_KEEP_POINTS",
    "point_cloud",
]

#: Most points of one sweep; a larger cloud is skipped.
MAX_SWEEP_POINTS = 2_000_000
#: A sweep of more points is thinned on reading to at most this many.
SWEEP_KEEP_POINTS = 200_000
#: The finest cube of that thinning, m.
SWEEP_VOXEL_M = 0.05
#: Farther points (m, any coordinate) are taken as no return.
MAX_POINT_RANGE_M = 1e4
#: Longest span of a sweep's point times, s (a spinning lidar's sweep lasts 0.05-0.2 s).
MAX_SWEEP_SPAN_S = 10.0

_POINT_FIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
_TIME_FIELDS = ("t", "time", "offset_time", "timestamp")


def point_cloud(msg: Any, log_ns: int, opts: DecodeOptions, static: bool) -> Decoded:
    """The decoder of ``sensor_msgs/msg/PointCloud2`` (:data:`tagloc.io.convert.DECODERS`)."""
    with np.errstate(invalid="ignore", over="ignore"):  # signalling NaNs, float64 beyond float32
        return _point_cloud(msg, log_ns, opts)


def _point_cloud(msg: Any, log_ns: int, opts: DecodeOptions) -> Decoded:
    h, w, step, row_step = (int(v) for v in (msg.height, msg.width, msg.point_step, msg.row_step))
    data = np.asarray(msg.data, dtype=np.uint8)
    shape = f"{h}x{w} cloud, point_step {step}, row_step {row_step}, {data.size} bytes"
    if h * w > MAX_SWEEP_POINTS:
        return [Bad("bad_point_cloud", f"{shape}: more than {MAX_SWEEP_POINTS} points")]
    if h * w and (row_step < w * step or data.size < h * row_step):
        return [Bad("bad_point_cloud", f"{shape}: data too short")]
    order = ">" if msg.is_bigendian else "<"
    fields: dict[str, tuple[str, int]] = {}
    for field in msg.fields:
        kind = _POINT_FIELD_TYPES.get(int(field.datatype))
        if kind is None or int(field.offset) + int(kind[1]) > step:
            name = str(field.name)[:60]
            return [Bad("bad_point_cloud", f"{shape}: field {name!r} does not fit a point")]
        fields.setdefault(str(field.name), (order + kind, int(field.offset)))
    if missing := [n for n in "xyz" if n not in fields]:
        return [Bad("bad_point_cloud", f"{shape}: no field(s) {missing}")]
    rows = data[: h * row_step].reshape(h, row_step)[:, : w * step] if h * w else data[:0]
    raw = (
        np.ascontiguousarray(rows).reshape(h * w, step) if h * w else np.zeros((0, step), np.uint8)
    )

    def column(name: str) -> Any:
        kind, offset = fields[name]
        return raw[:, offset : offset + int(kind[2])].copy().view(kind)[:, 0]

    points = np.stack([column(n) for n in "xyz"], axis=1).astype(np.float64)
    points[~(np.abs(points) <= MAX_POINT_RANGE_M).all(axis=1)] = np.nan  # no return
    intensity = column("intensity").astype(np.float32) if "intensity" in fields else None
    stamp = stamp_of(msg.header, log_ns, opts)
    offsets = _time_offsets(fields, column, stamp)
    if offsets is not None and len(offsets):
        if not np.isfinite(offsets).all():
            return [Bad("non_finite", f"{shape}: point times hold NaN or inf")]
        earliest, latest = float(offsets.min()), float(offsets.max())
        if not latest - earliest <= MAX_SWEEP_SPAN_S or not abs(earliest) <= 1e9:
            problem = f"point times span more than {MAX_SWEEP_SPAN_S:g} s or lie far from the stamp"
            return [Bad("bad_point_cloud", f"{shape}: {problem}")]
        if earliest < 0.0:
            stamp, offsets = stamp + round(earliest * 1e9), offsets - earliest
            if stamp < 0:
                return [Bad("bad_point_cloud", f"{shape}: points measured before time 0")]
    keep = _thinned(points)
    if keep is not None:
        points, offsets = points[keep], None if offsets is None else offsets[keep]
        intensity = None if intensity is None else intensity[keep]
    offsets32 = None if offsets is None else offsets.astype(np.float32)
    return [PointCloudMsg(stamp, msg.header.frame_id, points.astype(np.float32), intensity,
                          offsets32)]  # fmt: skip


def _thinned(points: np.ndarray) -> np.ndarray | None:
    """Indices of the first point in each cube (5 cm, doubled until at most
    :data:`SWEEP_KEEP_POINTS` are left), in their order; None if the sweep is small enough."""
    if len(points) <= SWEEP_KEEP_POINTS:
        return None
    finite = np.flatnonzero(np.isfinite(points).all(axis=1))
    voxel_m = SWEEP_VOXEL_M
    while True:  # |coordinates| <= MAX_POINT_RANGE_M: keys fit 2^21 per axis from 5 cm up
        keys = np.floor(points[finite] / voxel_m).astype(np.int64) + (2**20)
        flat = (keys[:, 0] << 42) | (keys[:, 1] << 21) | keys[:, 2]
        _, first = np.unique(flat, return_index=True)
        if len(first) <= SWEEP_KEEP_POINTS:
            return np.asarray(finite[np.sort(first)])
        voxel_m *= 2.0


def _time_offsets(fields: Mapping[str, Any], column: Callable[[str], Any], stamp: int) -> Any:
    """Per-point seconds after ``stamp`` (float64), or None (see :mod:`tagloc.io.convert`)."""
    name = next((n for n in _TIME_FIELDS if n in fields), None)
    if name is None:
        return None
    values, integer = column(name), fields[name][0][1] in "iu"
    if name == "offset_time" or (name == "t" and integer):
        return values.astype(np.float64) * 1e-9
    if name in ("t", "time"):
        return values.astype(np.float64)
    values = values.astype(np.float64)
    if len(values) and np.nanmax(np.abs(values)) > 1e12:  # absolute nanoseconds
        return (values - float(stamp)) * 1e-9
    return values - stamp * 1e-9
