"""Stream faults on a small hand-made stream: what each delivers, message by message.

(The faults through the node, with ladder walks and ground truth: tests/localize/test_faults.py.)
"""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.geometry import SE3
from tagloc.messages import Message, OdometryMsg, TagDetectionsMsg
from tagloc.sim.faults import ClockJump, DropMessages, DuplicateMessages, apply_faults

S = 1_000_000_000
T0 = 5 * S  # a stream that does not start at 0: fault times are relative to it


def stream() -> list[tuple[str, Message]]:
    """Odometry every 0.5 s and a frame every 1 s (before the odometry of its stamp), 0-4 s."""
    out: list[tuple[str, Message]] = []
    for k in range(9):
        stamp = T0 + k * S // 2
        if k % 2 == 0:
            out.append(("/tag_detections", TagDetectionsMsg(stamp, "camera", ())))
        T = SE3.from_quat(np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.1 * k, 0.0, 0.0]))
        out.append(("/odom", OdometryMsg(stamp, "odom", "base_link", T, np.eye(6))))
    return out


def summary(items: list[tuple[str, Message]]) -> list[tuple[str, float]]:
    """(topic, seconds after T0) per item."""
    return [(topic, (msg.stamp_ns - T0) / S) for topic, msg in items]


def test_drop_removes_its_kind_over_a_half_open_window() -> None:
    out = list(apply_faults(stream(), [DropMessages(1.0, 2.5, (TagDetectionsMsg,))], T0))
    frames = [t for topic, t in summary(out) if topic == "/tag_detections"]
    assert frames == [0.0, 3.0, 4.0]  # 1.0 and 2.0 dropped, 2.5 is past the window
    assert [t for topic, t in summary(out) if topic == "/odom"] == [k / 2 for k in range(9)]
    everything = list(apply_faults(stream(), [DropMessages(1.0, 2.0)], T0))
    kept = [0.0, 0.0, 0.5, 2.0, 2.0, 2.5, 3.0, 3.0, 3.5, 4.0, 4.0]
    assert [t for _, t in summary(everything)] == kept


def test_duplicate_repeats_each_message_in_place() -> None:
    original = stream()
    out = list(apply_faults(original, [DuplicateMessages(0.5, 1.5)], T0))
    assert summary(out)[:7] == [
        ("/tag_detections", 0.0), ("/odom", 0.0), ("/odom", 0.5), ("/odom", 0.5),
        ("/tag_detections", 1.0), ("/tag_detections", 1.0), ("/odom", 1.0),
    ]  # fmt: skip
    assert out[2][1] is out[3][1]  # the same record, sent twice
    assert len(out) == len(original) + 3  # odometry at 0.5 and 1.0, the frame at 1.0


def test_clock_jump_shifts_its_kind_from_the_jump_on_and_keeps_the_order() -> None:
    out = list(apply_faults(stream(), [ClockJump(2.0, 1.5, (OdometryMsg,))], T0))
    odom = [t for topic, t in summary(out) if topic == "/odom"]
    assert odom == [0.0, 0.5, 1.0, 1.5, 0.5, 1.0, 1.5, 2.0, 2.5]
    frames = [t for topic, t in summary(out) if topic == "/tag_detections"]
    assert frames == [0.0, 1.0, 2.0, 3.0, 4.0]  # the camera's clock did not jump
    moved = [m for _, m in out if isinstance(m, OdometryMsg)]
    assert moved[4].T_parent_child.translation[0] == pytest.approx(0.4)  # data unchanged
    with pytest.raises(ValueError, match="back_s"):
        ClockJump(2.0, 0.0)


def test_faults_chain_in_order_and_describe_themselves() -> None:
    twice = DuplicateMessages(0.0, 1.0, (OdometryMsg,))
    out = list(apply_faults(stream(), [twice, DropMessages(0.0, 0.6, (OdometryMsg,))], T0))
    assert [t for topic, t in summary(out) if topic == "/odom"][:3] == [1.0, 1.5, 2.0]
    assert twice.describe() == "OdometryMsg sent twice from 0 s to 1 s"
    assert ClockJump(45.0, 5.0).describe() == "every message clock jumps 5 s back at 45 s"
