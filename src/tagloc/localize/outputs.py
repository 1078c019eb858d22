"""What the streaming node publishes, and the sink protocol that receives it as it happens.

Every output is one typed record, handed to each :class:`OutputSink` the moment it exists:

- :class:`Estimate`: at every odometry sample, the published correction (``T_map_odom``, frame
  names of the configuration in ``parent``/``child`` of the published edge), the odometry, and
  the covariance of ``T_map_base`` (right tangent ``[x, y, z, rx, ry, rz]``; None before the
  filter is initialized). Sinks thin it to their own rate (``publish`` is True on the samples
  at ``output.publish_rate_hz``).
- :class:`~tagloc.localize.events.FilterEvent`: every decision of the filter;
  :class:`~tagloc.supervise.LadderTransition`: every move of the degradation ladder.
- :class:`~tagloc.supervise.StatusReport`: at ``supervisor.status_rate_hz``.
- :class:`~tagloc.localize.run.FixAttempt` and :class:`~tagloc.localize.run.CameraFrameRecord`:
  each fix and each camera frame with its final decision, a few seconds after the frame (a
  batch decision, start-up or re-acquisition, may still revise a fix within the consistency
  window; past it the record is final and is handed on).
- :class:`~tagloc.messages.GroundTruthMsg`: ground truth, passed through when the stream has it.
- In buildings with elevators (:mod:`tagloc.localize.cab`): :class:`~tagloc.localize.run.
  CabEstimate` at each odometry sample in a cab (the ``<cab_frame> -> odom`` correction),
  :class:`~tagloc.supervise.CabTransition` at each move of the map <-> cab handoff; the floor
  rides on each :class:`Estimate` (``floor``) and a floor change is a ``floor_changed``
  :class:`~tagloc.localize.events.FilterEvent`.

:class:`RunRecorder` is the sink evaluation uses: it keeps everything (spooled to temporary
files, :mod:`tagloc.localize.spool`) and assembles a :class:`~tagloc.localize.run.
LocalizationRun` (a choice of that sink; the node keeps nothing).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeAlias

import numpy as np

from tagloc._types import FloatArray
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize.events import FilterEvent
from tagloc.localize.run import CabEstimate, CameraFrameRecord, FixAttempt, LocalizationRun
from tagloc.localize.spool import RecordSpool, RowSpool
from tagloc.messages import GroundTruthMsg
from tagloc.supervise import CabTransition, LadderTransition, StatusReport

__all__ = ["CabEstimate", "Estimate", "NodeOutput", "OutputSink", "RunRecorder"]

_NAN6 = np.full((6, 6), np.nan)
_NAN6.flags.writeable = False


@dataclass(frozen=True, slots=True)
class Estimate:
    """The node's estimate at one odometry sample (module docstring).

    Attributes
    ----------
    stamp_ns : int
    T_odom_base : SE3
    T_map_odom : SE3
        The published correction (identity before initialization).
    cov_map_base : (6, 6) float or None
    initialized : bool
    publish : bool
        On the configured publication rate.
    parent, child : str
        The published edge's frames (``map``/``odom``, or ``odom``/``map`` for the inverse).
    T_map_odom_estimate : SE3 or None
        The filter's estimate before the cap and the speed limit (None before initialization).
    floor : str or None
        The floor of ``T_map_base`` (None: unknown, riding a cab, or no floors; then, in a
        building of several floors, its z variance is inflated).
    """

    stamp_ns: int
    T_odom_base: SE3
    T_map_odom: SE3
    cov_map_base: FloatArray | None
    initialized: bool
    publish: bool
    parent: str
    child: str
    T_map_odom_estimate: SE3 | None = None
    floor: str | None = None

    @property
    def T_map_base(self) -> SE3:
        return self.T_map_odom @ self.T_odom_base

    def T_parent_child(self, map_frame: str) -> SE3:
        """The published transform: ``T_map_odom``, or its inverse when the parent is not the
        map frame."""
        return self.T_map_odom if self.parent == map_frame else self.T_map_odom.inverse()


NodeOutput: TypeAlias = (
    Estimate | FilterEvent | LadderTransition | StatusReport | FixAttempt | CameraFrameRecord
    | GroundTruthMsg | CabEstimate | CabTransition
)  # fmt: skip


class OutputSink(Protocol):
    """Receives the node's outputs as they happen (files, a bag, dimos, an evaluation)."""

    def write(self, output: NodeOutput) -> None:
        """One output; raise only on a failure that must stop the run (e.g. a full disk)."""


class RunRecorder:
    """A sink for evaluation: :meth:`run` assembles a :class:`LocalizationRun`.

    What it keeps grows with the drive, so it keeps it on disk (:mod:`tagloc.localize.spool`,
    unnamed temporary files): the estimate at each odometry sample and the truth as numeric
    rows, the fix attempts, camera frames, events and cab estimates as records. :attr:`fixes`,
    :attr:`frames`, :attr:`events` and :attr:`cab` read the records written so far (read-only
    sequences), the floor at each sample as a code; the ladder's moves, the status reports and
    the cab's moves stay in lists.
    """

    def __init__(self, name: str = "run") -> None:
        self.name = name
        self._stamps = RowSpool("stamps", 1, np.int64)
        self._series = {k: RowSpool(k, 12) for k in ("odom", "published", "estimate")}
        self._covs = RowSpool("cov_map_base", 36)
        self._init = RowSpool("initialized", 1, np.bool_)
        self._truth_stamps = RowSpool("truth stamps", 1, np.int64)
        self._truth = RowSpool("truth", 12)
        self._records: dict[str, RecordSpool[Any]] = {
            k: RecordSpool(k) for k in ("fixes", "frames", "events", "cab")
        }
        self.ladder: list[LadderTransition] = []
        self.status: list[StatusReport] = []
        self.cab_moves: list[CabTransition] = []
        self._floors = RowSpool("floors", 1, np.int32)  # index into _floor_names; -1: None
        self._floor_names: dict[str, int] = {}

    @property
    def fixes(self) -> Sequence[FixAttempt]:
        """The fix attempts recorded so far."""
        return self._records["fixes"].records()

    @property
    def frames(self) -> Sequence[CameraFrameRecord]:
        return self._records["frames"].records()

    @property
    def events(self) -> Sequence[FilterEvent]:
        return self._records["events"].records()

    @property
    def cab(self) -> Sequence[CabEstimate]:
        return self._records["cab"].records()

    def write(self, output: NodeOutput) -> None:
        if isinstance(output, Estimate):
            self._stamps.append(output.stamp_ns)
            est = output.T_map_odom_estimate
            for key, T in (("odom", output.T_odom_base), ("published", output.T_map_odom),
                           ("estimate", output.T_map_odom if est is None else est)):  # fmt: skip
                self._series[key].append(T.as_rows())
            self._covs.append((_NAN6 if output.cov_map_base is None else output.cov_map_base)
                              .reshape(36))  # fmt: skip
            self._init.append(output.initialized)
            floor = output.floor
            self._floors.append(-1 if floor is None else self._floor_names.setdefault(
                floor, len(self._floor_names)))  # fmt: skip
        elif isinstance(output, FilterEvent):
            self._records["events"].append(output)
        elif isinstance(output, FixAttempt):
            self._records["fixes"].append(output)
        elif isinstance(output, CameraFrameRecord):
            self._records["frames"].append(output)
        elif isinstance(output, LadderTransition):
            self.ladder.append(output)
        elif isinstance(output, StatusReport):
            self.status.append(output)
        elif isinstance(output, GroundTruthMsg):
            self._truth_stamps.append(output.stamp_ns)
            self._truth.append(output.T_frame_child.as_rows())
        elif isinstance(output, CabEstimate):
            self._records["cab"].append(output)
        elif isinstance(output, CabTransition):
            self.cab_moves.append(output)

    def run(self, metadata: dict[str, Any]) -> LocalizationRun:
        """The recorded run (``metadata``: the node's :meth:`~LocalizerNode.metadata`); its
        series are read back into arrays, its records stay on disk, read as they are used.

        Raises
        ------
        SpoolError
            If a spool does not read back (a short write, a damaged temporary file).
        """
        stamps = self._stamps.read().reshape(-1)
        poses = {k: SE3.from_rows(v.read()) for k, v in self._series.items()}
        return LocalizationRun(
            name=self.name, stamps_ns=stamps, T_odom_base=poses["odom"],
            T_map_odom=poses["published"], cov_map_base=self._covs.read().reshape(-1, 6, 6),
            initialized=self._init.read().reshape(-1), T_map_base_truth=self._truth_at(stamps),
            fixes=self.fixes, frames=self.frames, events=self.events,
            metadata=metadata, ladder=list(self.ladder),
            T_map_odom_estimate=poses["estimate"] if len(stamps) else None,
            cab=self.cab, cab_moves=list(self.cab_moves), floors=self._floors_read(),
        )  # fmt: skip

    def _floors_read(self) -> list[str | None]:
        names: list[str | None] = [*self._floor_names, None]  # code -1: the last, None
        return [names[c] for c in self._floors.read().reshape(-1).tolist()]

    def _truth_at(self, stamps: np.ndarray) -> SE3 | None:
        if not len(self._truth):
            return None
        # one truth per stamp, the last written (a stamp sent twice), in stamp order
        written = self._truth_stamps.read().reshape(-1)
        rows = self._truth.read()
        keys, last = np.unique(written[::-1], return_index=True)
        rows = rows[len(written) - 1 - last]
        del written
        at = np.searchsorted(keys, stamps).clip(0, len(keys) - 1)
        if np.array_equal(keys[at], stamps):
            return SE3.from_rows(rows[at])
        buf = TransformBuffer(window_ns=2**62)
        buf.set_transforms("truth", "base", keys, SE3.from_rows(rows))
        inside = (stamps >= keys[0]) & (stamps <= keys[-1])
        if not inside.all():
            return None
        return buf.lookup_many("truth", "base", stamps)

