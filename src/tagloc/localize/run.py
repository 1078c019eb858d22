"""The record of one localization run: what the pipeline produced, what evaluation reads.

A :class:`LocalizationRun` is the interface between :mod:`tagloc.localize` (which fills it while
replaying a message stream: simulator or bag) and :mod:`tagloc.eval` (which scores it). Everything
is stamped in integer nanoseconds, with frame names in the field names; the per-sample series are
arrays in memory, the records (``fixes``, ``frames``, ``events``, ``cab``) any read-only sequence
(a recorded run's are read from its spool as they are used: :mod:`tagloc.localize.spool`).

- ``stamps_ns`` / ``T_odom_base`` / ``T_map_odom`` / ``cov_map_base``: one row per odometry
  sample, the filter's published ``map -> odom`` correction at that stamp (identity before the
  filter is initialized, ``initialized[i]`` False) and the covariance of ``T_map_base`` (right
  tangent ``[x, y, z, rx, ry, rz]``, NaN before initialization).
- ``T_map_base_truth``: ground truth at the same stamps when known (simulator), else None.
- ``fixes``: one :class:`FixAttempt` per candidate fix offered to the filter, with the filter's
  decision, so acceptance can be tabulated against range and angle and false fixes counted.
- ``frames``: one :class:`CameraFrameRecord` per camera frame, for the per-opportunity
  reliability protocol (what was truly visible, what was detected, what was accepted).
- ``events``: the filter's :class:`~tagloc.localize.events.FilterEvent` log.
- ``kidnaps_ns``: stamps at which the scenario teleported the robot (empty if none).
- ``ladder``: the supervisor's ladder transitions; ``T_map_odom_estimate``: the filter's own
  estimate at each row before the cap and the speed limit (None where not recorded).
- ``cab``: the node's :class:`CabEstimate` s (the pose relative to an elevator cab, while in
  one), ``cab_moves``: the map <-> cab handoff's transitions, ``floors``: the floor published
  with each row (None: unknown, or a building without floors); ``T_cab_base_truth``: the truth
  of each ``cab`` estimate when known (simulator).
"""

from __future__ import annotations

import math
from collections.abc import Container, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.localize.events import APPLIED, FilterEvent
from tagloc.supervise import CabState, CabTransition, LadderTransition

__all__ = ["CabEstimate", "CameraFrameRecord", "FixAttempt", "LocalizationRun"]


@dataclass(frozen=True, slots=True, eq=False)
class CabEstimate:
    """The node's estimate relative to an elevator cab at one odometry sample (published while
    the handoff is not ``in_map`` and the cab's estimate exists).

    Attributes
    ----------
    stamp_ns : int
    cab_frame : str
    T_cab_odom : SE3
        The published ``<cab_frame> -> odom`` correction (capped, as ``map -> odom`` is).
    T_odom_base : SE3
    cov_cab_base : (6, 6) float
        Right-tangent covariance of ``T_cab_base``, ``[x, y, z, rx, ry, rz]``.
    state : CabState
    """

    stamp_ns: int
    cab_frame: str
    T_cab_odom: SE3
    T_odom_base: SE3
    cov_cab_base: FloatArray
    state: CabState

    @property
    def T_cab_base(self) -> SE3:
        return self.T_cab_odom @ self.T_odom_base



@dataclass(frozen=True, slots=True, eq=False)
class FixAttempt:
    """One candidate fix and what became of it.

    Attributes
    ----------
    stamp_ns : int
        Camera exposure stamp of the observation.
    source : str
        ``"tag:17"`` (single tag) or ``"tags:3,17"`` (joint PnP).
    tag_ids : tuple of int
    T_map_base : SE3
        The fix's pose of the base in the map.
    cov : (6, 6) float
        Its covariance, ``[x, y, z, rx, ry, rz]`` right tangent.
    decision : str
        The filter's :class:`~tagloc.localize.events.EventKind` value (``"accepted"``,
        ``"gated_chi2"``, ...) or the per-observation gate's reason (``"rejected:<reason>"``)
        when the fix never reached the filter.
    range_m : float
        Camera to the nearest tag in the fix, m.
    view_angle_rad : float
        Viewing angle of that tag (0 = head-on).
    false_detection : bool or None
        True if built from an injected false detection (simulator), None if unknown (bag).
    d2 : float or None
        The squared Mahalanobis distance the filter tested the fix with, when it did (not for
        a fix decided in a batch: start-up, re-acquisition, kidnap).
    camera : str
        The camera whose frame the fix came from (``""``: the node's only camera, or not a
        camera's fix).
    frame : str
        The tag-map frame the fix's tags are posed in: ``""`` for the map (its ``T_map_base``
        is the base in ``map``), an elevator cab's frame for a fix of the cab's tags (its
        ``T_map_base`` is then the base in that cab, decided by the cab's estimator). A record
        written before the field existed is a map fix.
    """

    stamp_ns: int
    source: str
    tag_ids: tuple[int, ...]
    T_map_base: SE3
    cov: FloatArray
    decision: str
    range_m: float
    view_angle_rad: float
    false_detection: bool | None = None
    d2: float | None = None
    camera: str = ""
    frame: str = ""

    @property
    def accepted(self) -> bool:
        """Whether the filter accepted (or initialized from) the fix."""
        return self.decision in APPLIED

    @property
    def in_map(self) -> bool:
        """Whether the fix is of the map (not of a cab's tags): what ``map -> odom`` used."""
        return not self.frame

    @property
    def of_tags(self) -> bool:
        """Whether the fix came from tags in a camera's frame (not from the lidar)."""
        return self.source.startswith("tag")

    def to_row(self) -> dict[str, object]:
        """The ``fixes.jsonl`` row (no pose: the fused trajectory carries the poses; NaN as
        None); :meth:`from_row` reads it back."""
        return {
            "stamp_ns": self.stamp_ns, "source": self.source, "decision": self.decision,
            "range_m": _num(self.range_m), "view_angle_rad": _num(self.view_angle_rad),
            "false_detection": self.false_detection,
            "d2": None if self.d2 is None else _num(self.d2), "camera": self.camera,
            "frame": self.frame,
        }  # fmt: skip

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> FixAttempt:
        """The attempt of a ``fixes.jsonl`` row (pose unknown: identity, covariance NaN).
        Rows of older files lack ``camera``, ``d2`` or ``frame``: their defaults (a map fix).

        Raises
        ------
        KeyError, ValueError
            A row without ``stamp_ns``, ``source`` or ``decision``, or with a malformed
            ``source``.
        """
        source = str(row["source"])
        kind, _, ids = source.partition(":")
        tag_ids = tuple(int(i) for i in ids.split(",")) if kind in ("tag", "tags") else ()
        d2 = row.get("d2")
        return cls(
            int(row["stamp_ns"]), source, tag_ids, SE3.identity(), np.full((6, 6), np.nan),
            str(row["decision"]), _float(row.get("range_m")), _float(row.get("view_angle_rad")),
            row.get("false_detection"), None if d2 is None else float(d2),
            str(row.get("camera", "")), str(row.get("frame") or ""),
        )  # fmt: skip


@dataclass(frozen=True, slots=True)
class CameraFrameRecord:
    """One camera frame: the truth in view (simulator) and what the pipeline made of it.

    Attributes
    ----------
    stamp_ns : int
    nearest_visible_tag_m : float
        Camera to the nearest tag truly in view, m (simulator truth; for a bag, the nearest
        detected tag); ``inf`` when none.
    n_detections : int
        Detections the detector reported (true and false).
    n_fixes_accepted : int
        Fixes from this frame the ``map -> odom`` filter accepted (a cab's fixes are counted
        by their :class:`FixAttempt` s, :attr:`FixAttempt.frame`).
    nearest_by_frame : tuple of (str, float)
        Per tag-map frame with a tag truly in view (``"map"``, a cab's frame), camera to its
        nearest tag, m (simulator truth; empty when unknown: a bag).
    """

    stamp_ns: int
    nearest_visible_tag_m: float
    n_detections: int
    n_fixes_accepted: int
    nearest_by_frame: tuple[tuple[str, float], ...] = ()

    def nearest_in(self, frames: Container[str], inside: bool = True) -> float:
        """Camera to the nearest tag truly in view posed in one of ``frames`` (``inside``
        False: in none of them), m (``inf``: none, or no per-frame truth)."""
        return min(
            (m for f, m in self.nearest_by_frame if (f in frames) == inside), default=math.inf
        )


@dataclass(slots=True, eq=False)
class LocalizationRun:
    """Everything one run produced (see the module docstring).

    Attributes
    ----------
    name : str
        Scenario or bag name, for reports.
    stamps_ns : (N,) int64
    T_odom_base : SE3 batch of N
    T_map_odom : SE3 batch of N
        Published correction at each stamp.
    cov_map_base : (N, 6, 6) float
        NaN where not initialized.
    initialized : (N,) bool
    T_map_base_truth : SE3 batch of N or None
    fixes : sequence of FixAttempt
    frames : sequence of CameraFrameRecord
    events : sequence of FilterEvent
    kidnaps_ns : list of int
    metadata : dict
        Free-form facts for the report (world, seed, config values, wall time).
    ladder : list of LadderTransition
    T_map_odom_estimate : SE3 batch of N or None
        The filter's estimate (unclipped) at each stamp; identity where not initialized.
    cab, cab_moves, floors :
        See the module docstring.
    T_cab_base_truth : SE3 batch of len(cab) or None
        The true base in the cab of each ``cab`` estimate, at its stamp (simulator), else None.
    """

    name: str
    stamps_ns: npt.NDArray[np.int64]
    T_odom_base: SE3
    T_map_odom: SE3
    cov_map_base: FloatArray
    initialized: npt.NDArray[np.bool_]
    T_map_base_truth: SE3 | None = None
    fixes: Sequence[FixAttempt] = field(default_factory=list)
    frames: Sequence[CameraFrameRecord] = field(default_factory=list)
    events: Sequence[FilterEvent] = field(default_factory=list)
    kidnaps_ns: list[int] = field(default_factory=list)
    metadata: dict[str, object] = field(default_factory=dict)
    ladder: list[LadderTransition] = field(default_factory=list)
    T_map_odom_estimate: SE3 | None = None
    cab: Sequence[CabEstimate] = field(default_factory=list)
    cab_moves: list[CabTransition] = field(default_factory=list)
    floors: list[str | None] = field(default_factory=list)
    T_cab_base_truth: SE3 | None = None

    @property
    def T_map_base(self) -> SE3:
        """The fused estimate of the base in the map, ``T_map_odom @ T_odom_base`` (batch)."""
        return self.T_map_odom @ self.T_odom_base


def _num(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _float(value: object) -> float:
    return math.nan if value is None else float(value)  # type: ignore[arg-type]
