"""A fix attempt's frame (the map, or an elevator cab) in ``fixes.jsonl`` and in the held
records: rows written before the field existed still read as the map's fixes, a cab's fix is
written and read back with its cab, and a frame's record counts the map's accepted fixes only."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from tagloc.geometry import SE3
from tagloc.io.node_sinks import RunFilesSink
from tagloc.localize.held import HeldRecords, Record
from tagloc.localize.run import CameraFrameRecord, FixAttempt

#: Rows as ``fixes.jsonl`` held them before the ``frame`` field (and before ``camera``/``d2``).
OLD_ROWS = (
    '{"stamp_ns": 1500000000, "source": "tag:17", "decision": "accepted", "range_m": 2.5, '
    '"view_angle_rad": 0.2, "false_detection": false, "d2": 3.1, "camera": "front"}',
    '{"stamp_ns": 1600000000, "source": "tags:3,17", "decision": "gated_chi2", '
    '"range_m": null, "view_angle_rad": null, "false_detection": null}',
)


def _attempt(stamp_ns: int, decision: str, frame: str = "", tag: int = 40) -> FixAttempt:
    return FixAttempt(stamp_ns, f"tag:{tag}", (tag,), SE3.identity(), np.eye(6) * 1e-4,
                      decision, 1.2, 0.1, None, 2.0, frame=frame)  # fmt: skip


def test_old_rows_without_the_frame_read_as_map_fixes() -> None:
    first, second = (FixAttempt.from_row(json.loads(line)) for line in OLD_ROWS)
    assert first.in_map and first.frame == "" and first.camera == "front"
    assert (first.stamp_ns, first.tag_ids, first.decision, first.d2) == (
        1_500_000_000, (17,), "accepted", 3.1)  # fmt: skip
    assert first.accepted and first.range_m == 2.5 and first.false_detection is False
    assert second.in_map and second.tag_ids == (3, 17) and not second.accepted
    assert math.isnan(second.range_m) and second.d2 is None and second.camera == ""


def test_a_cab_fix_is_written_and_read_back_with_its_cab(tmp_path: Path) -> None:
    sink = RunFilesSink(tmp_path, "map", bag=False)
    written = [_attempt(10, "accepted", "elevator_cab"), _attempt(20, "gated_chi2", tag=12)]
    for attempt in written:
        sink.write(attempt)
    sink.close({})
    rows = [json.loads(line) for line in (tmp_path / "fixes.jsonl").read_text().splitlines()]
    read = [FixAttempt.from_row(row) for row in rows]
    assert [(a.frame, a.in_map) for a in read] == [("elevator_cab", False), ("", True)]
    for a, b in zip(read, written, strict=True):
        assert (a.stamp_ns, a.source, a.tag_ids, a.decision, a.range_m, a.d2) == (
            b.stamp_ns, b.source, b.tag_ids, b.decision, b.range_m, b.d2)  # fmt: skip


def test_a_frame_counts_its_accepted_fixes_of_the_map_only() -> None:
    out: list[Record] = []
    held = HeldRecords(out.append)
    held.hold(_attempt(100, "accepted", tag=12))  # the map's tag source: before the record
    held.hold(CameraFrameRecord(100, 1.0, 2, 0))
    held.hold(_attempt(100, "accepted", "elevator_cab"))  # the cab's: after the record
    held.hold(_attempt(200, "accepted", "elevator_cab"))  # held before it: not counted either
    held.hold(CameraFrameRecord(200, 1.0, 1, 0))
    held.release(None)
    frames = [r for r in out if isinstance(r, CameraFrameRecord)]
    assert [f.n_fixes_accepted for f in frames] == [1, 0]
    assert sum(isinstance(r, FixAttempt) for r in out) == 3  # every attempt left once
