"""tagSLAM rig files: the tag-id remap relabels detections by stamp; bad entries are one line."""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.camera import PinholeRadtan
from tagloc.geometry import SE3
from tagloc.mapping import MappingError
from tagloc.mapping.stream_survey import TagRemap, parse_tagslam, survey_from_messages
from tagloc.messages import OdometryMsg, TagDetectionsMsg
from tagloc.tags import TagDetection

TAGSLAM = """
tag_id_remap:
  - id: 20
    remaps:
      - {remap_id: 420, start_time: 10.0, end_time: 20.0}
      - {remap_id: 520, start_time: 30.5, end_time: 31.0}
"""
SQUARE = np.array([[100.0, 100.0], [140.0, 100.0], [140.0, 140.0], [100.0, 140.0]])


def test_remaps_are_parsed_in_nanoseconds() -> None:
    rig = parse_tagslam(TAGSLAM, "tagslam.yaml")
    assert rig.tag_remaps == (
        TagRemap(20, 420, 10 * 10**9, 20 * 10**9),
        TagRemap(20, 520, 30_500_000_000, 31 * 10**9),
    )
    assert parse_tagslam("bodies: []", "t.yaml").tag_remaps == ()


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("tag_id_remap: {id: 20}", "tag_id_remap: expected a list"),
        ("tag_id_remap: [{id: 20}]", r"tag_id_remap\[0\]: expected id and remaps"),
        ("tag_id_remap: [{id: 20, remaps: [{remap_id: 4, start_time: 2, end_time: 1}]}]",
         "end_time before start_time"),
    ],
)
def test_bad_remaps_name_the_entry(text: str, words: str) -> None:
    with pytest.raises(MappingError, match=words):
        parse_tagslam(text, "tagslam.yaml")


def test_detections_in_a_window_are_relabelled() -> None:
    rig = parse_tagslam(TAGSLAM, "tagslam.yaml")
    det = TagDetection(tag_id=20, family="tag36h11", corners_px=SQUARE, hamming=0,
                       decision_margin=50.0)  # fmt: skip
    other = TagDetection(tag_id=7, family="tag36h11", corners_px=SQUARE + 200, hamming=0,
                         decision_margin=50.0)  # fmt: skip
    items = [("/odom", OdometryMsg(s * 10**9, "odom", "base", SE3.identity(), np.eye(6)))
             for s in range(0, 40, 5)]  # fmt: skip
    items += [("/tags", TagDetectionsMsg(s * 10**9, "cam", (det, other))) for s in (5, 15, 35)]
    K = [[400, 0, 320], [0, 400, 240], [0, 0, 1]]
    camera = PinholeRadtan.from_opencv(K, [0, 0, 0, 0], (640, 480))
    survey = survey_from_messages(
        items, {"/tags": "cam0"}, "/odom", {"cam0": camera}, {"cam0": SE3.identity()},
        tag_remaps=rig.tag_remaps,
    )  # fmt: skip
    ids = [[d.tag_id for d in f.detections] for f in survey.frames]
    assert ids == [[20, 7], [420, 7], [20, 7]]
