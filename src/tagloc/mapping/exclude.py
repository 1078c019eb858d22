"""Leave observations out of a survey: a tag during a time window, a whole tag, a time range.

After reviewing a build (the QA report, the exported graph: :mod:`tagloc.mapping.graph_export`),
a person removes what is wrong (a tag that was moved halfway through the survey, a stretch where
a duplicate id was seen) and builds again. :func:`exclude_observations` is a pure filter on the
:class:`~tagloc.mapping.survey.Survey`: detections go; camera frames, odometry and lidar sweeps
stay (the odometry still links the keyframes on either side, the scans still match).

Times are seconds from the survey start, :func:`survey_start_ns` (the first camera frame), the
same origin as the exported graph's ``t_s``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from tagloc.mapping.survey import CameraFrame, MappingError, Survey


@dataclass(frozen=True, slots=True)
class Exclusion:
    """Detections to leave out: of ``tag_id`` (None: every tag) stamped in ``[t0_s, t1_s]``
    seconds from the survey start (None: the whole survey). ``text`` is how the user wrote it."""

    tag_id: int | None = None
    t0_s: float | None = None
    t1_s: float | None = None
    text: str = ""

    def __post_init__(self) -> None:
        if self.tag_id is None and self.t0_s is None:
            raise MappingError(f"exclusion {self.text!r}: names neither a tag nor a time range")
        if (self.t0_s is None) != (self.t1_s is None):
            raise MappingError(f"exclusion {self.text!r}: a time range needs both ends")
        if self.t0_s is not None and self.t1_s is not None and not self.t0_s <= self.t1_s:
            raise MappingError(f"exclusion {self.text!r}: the range ends before it starts")

    def matches(self, tag_id: int, t_s: float) -> bool:
        """Whether a detection of ``tag_id`` at ``t_s`` (s from the survey start) is left out."""
        if self.tag_id is not None and tag_id != self.tag_id:
            return False
        return self.t0_s is None or self.t0_s <= t_s <= (self.t1_s or 0.0)


def survey_start_ns(survey: Survey) -> int:
    """The survey's time origin: the first camera frame's stamp (the first odometry stamp if it
    has no frames), ns."""
    if not survey.frames:
        return int(survey.odom_stamps_ns[0])
    return min(frame.stamp_ns for frame in survey.frames)


def exclude_observations(survey: Survey, exclusions: Sequence[Exclusion]) -> Survey:
    """``survey`` without the detections any of ``exclusions`` matches (same frames, odometry).

    Raises
    ------
    MappingError
        An exclusion names a tag the survey never detects (a typo would silently do nothing).
    """
    if not exclusions:
        return survey
    seen = {det.tag_id for frame in survey.frames for det in frame.detections}
    for exclusion in exclusions:
        if exclusion.tag_id is not None and exclusion.tag_id not in seen:
            raise MappingError(
                f"exclusion {exclusion.text!r}: tag {exclusion.tag_id} is never detected in "
                f"{survey.source}"
            )
    t0 = survey_start_ns(survey)
    frames = []
    for frame in survey.frames:
        t_s = (frame.stamp_ns - t0) * 1e-9
        kept = tuple(
            det
            for det in frame.detections
            if not any(e.matches(det.tag_id, t_s) for e in exclusions)
        )
        frames.append(frame if len(kept) == len(frame.detections) else
                      CameraFrame(frame.stamp_ns, frame.camera, kept))  # fmt: skip
    return replace(survey, frames=tuple(frames))  # the lidar sweeps and every other field stay
