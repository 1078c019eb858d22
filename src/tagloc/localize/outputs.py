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

:class:`RunRecorder` is the sink evaluation uses: it keeps everything in memory and assembles a
:class:`~tagloc.localize.run.LocalizationRun` (a choice of that sink; the node keeps nothing).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, TypeAlias

import numpy as np

from tagloc._types import FloatArray
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize.events import FilterEvent
from tagloc.localize.run import CabEstimate, CameraFrameRecord, FixAttempt, LocalizationRun
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
    """An in-memory sink for evaluation: :meth:`run` assembles a :class:`LocalizationRun`."""

    def __init__(self, name: str = "run") -> None:
        self.name = name
        self._stamps: list[int] = []
        self._odom: list[SE3] = []
        self._published: list[SE3] = []
        self._covs: list[FloatArray] = []
        self._init: list[bool] = []
        self._estimate: list[SE3] = []
        self._truth: dict[int, SE3] = {}
        self.fixes: list[FixAttempt] = []
        self.frames: list[CameraFrameRecord] = []
        self.events: list[FilterEvent] = []
        self.ladder: list[LadderTransition] = []
        self.status: list[StatusReport] = []
        self.cab: list[CabEstimate] = []
        self.cab_moves: list[CabTransition] = []
        self._floors: list[str | None] = []

    def write(self, output: NodeOutput) -> None:
        if isinstance(output, Estimate):
            self._stamps.append(output.stamp_ns)
            self._odom.append(output.T_odom_base)
            self._published.append(output.T_map_odom)
            self._covs.append(_NAN6 if output.cov_map_base is None else output.cov_map_base)
            self._init.append(output.initialized)
            est = output.T_map_odom_estimate
            self._estimate.append(output.T_map_odom if est is None else est)
            self._floors.append(output.floor)
        elif isinstance(output, FilterEvent):
            self.events.append(output)
        elif isinstance(output, FixAttempt):
            self.fixes.append(output)
        elif isinstance(output, CameraFrameRecord):
            self.frames.append(output)
        elif isinstance(output, LadderTransition):
            self.ladder.append(output)
        elif isinstance(output, StatusReport):
            self.status.append(output)
        elif isinstance(output, GroundTruthMsg):
            self._truth[output.stamp_ns] = output.T_frame_child
        elif isinstance(output, CabEstimate):
            self.cab.append(output)
        elif isinstance(output, CabTransition):
            self.cab_moves.append(output)

    def run(self, metadata: dict[str, Any]) -> LocalizationRun:
        """The recorded run (``metadata``: the node's :meth:`~LocalizerNode.metadata`)."""
        stamps = np.array(self._stamps, dtype=np.int64)
        return LocalizationRun(
            name=self.name, stamps_ns=stamps, T_odom_base=SE3.stack(self._odom),
            T_map_odom=SE3.stack(self._published), cov_map_base=np.array(self._covs),
            initialized=np.array(self._init, dtype=bool), T_map_base_truth=self._truth_at(stamps),
            fixes=list(self.fixes), frames=list(self.frames), events=list(self.events),
            metadata=metadata, ladder=list(self.ladder),
            T_map_odom_estimate=SE3.stack(self._estimate) if self._estimate else None,
            cab=list(self.cab), cab_moves=list(self.cab_moves), floors=list(self._floors),
        )  # fmt: skip

    def _truth_at(self, stamps: np.ndarray) -> SE3 | None:
        if not self._truth:
            return None
        if all(int(s) in self._truth for s in stamps):
            return SE3.stack([self._truth[int(s)] for s in stamps])
        buf = TransformBuffer(window_ns=2**62)
        keys = sorted(self._truth)
        buf.set_transforms(
            "truth", "base", np.array(keys), SE3.stack([self._truth[k] for k in keys])
        )
        inside = (stamps >= keys[0]) & (stamps <= keys[-1])
        if not inside.all():
            return None
        return buf.lookup_many("truth", "base", stamps)
