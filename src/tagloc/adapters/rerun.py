"""The live view: the node's outputs streamed to rerun (``pip install 'tagloc[view]'``).

:class:`RerunSink` is an :class:`~tagloc.localize.outputs.OutputSink` (the node writes to it as
it writes to its files) and a tap on the input stream (:meth:`RerunSink.tap`: the lidar sweeps
and the odometry's covariance, which are inputs, not outputs). Entities, all in the map frame on
the timeline ``stream`` (the stamps, as a duration):

- ``map/tags`` (static): every tag of the map frame as a thin box with its id;
  ``map/premap`` (static): the point-cloud premap, thinned to :data:`MAX_PREMAP_POINTS`;
- ``map/fused``, ``map/odometry``, ``map/truth``: the base's pose (``Transform3D``) at up to
  :data:`POSE_RATE_HZ` (the fused one on the node's publications), each with ``.../cov``: the
  1-sigma position ellipsoid of its covariance in the base frame (the fused estimate's
  ``cov_map_base``, the odometry message's covariance), and ``map/path/<name>/<k>``: the path
  as lines of :data:`PATH_POINTS` positions;
- ``map/fixes``: each fix attempt's base position, green when the filter accepted it, red
  otherwise, labelled with its decision, and ``map/rays``: lines from it to the tags it saw;
- ``map/lidar``: each sweep's points in the map through the latest fused pose and the static
  ``base -> lidar`` transform (thinned to :data:`MAX_SWEEP_POINTS`), against the premap;
- ``status/ladder_level`` (1 lidar nominal .. 4 odometry only), ``status/fixes_accepted`` and
  ``status/events`` (every ladder move with its reason, as a text log).

Outputs go to a viewer (``spawn``: start one; ``connect``: a running one's gRPC URL) and/or an
``.rrd`` file (``save``), which rerun's own readers load (``rerun.chunk.RrdReader``). The sink's
memory is bounded (one path segment per pose; the viewer keeps what it is sent).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from tagloc.adapters import AdapterError, missing_extra
from tagloc.geometry import SE3
from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.localize.run import FixAttempt
from tagloc.messages import GroundTruthMsg, Message, OdometryMsg, PointCloudMsg, TransformMsg
from tagloc.supervise import LadderTransition, StatusReport
from tagloc.tags import TagMap

__all__ = ["MAX_PREMAP_POINTS", "MAX_SWEEP_POINTS", "PATH_POINTS", "POSE_RATE_HZ", "RerunSink"]

logger = logging.getLogger(__name__)
MAX_PREMAP_POINTS = 200_000
MAX_SWEEP_POINTS = 5_000
PATH_POINTS = 100
#: Each pose (fused, odometry, truth) is drawn at most this often, per stream second.
POSE_RATE_HZ = 10.0
_COLORS = {"fused": (31, 119, 180), "odometry": (214, 39, 40), "truth": (44, 160, 44)}
_ACCEPTED, _REFUSED = (40, 200, 40), (220, 40, 40)


class RerunSink:
    """Streams a run to rerun (module docstring).

    Parameters
    ----------
    tag_map : TagMap or None
        Its tags in ``map_frame`` are drawn.
    map_frame : str
        The configured map frame (its tags are drawn).
    base_frame : str
        The configured base frame (the lidar's static transform hangs from it).
    spawn : bool
        Start a viewer and stream to it.
    connect : str, optional
        Stream to a running viewer at this gRPC URL (``rerun+http://host:9876/proxy``).
    save : Path, optional
        Record everything to this ``.rrd`` file (written beside it as ``.NAME.partial`` and
        renamed into place by :meth:`close`; :meth:`abort` removes it).
    premap : (N, 3) float, optional
        The lidar premap, in the map frame.
    name : str
        The recording's name.

    Raises
    ------
    AdapterError
        If rerun-sdk is not installed, or no output is asked for.
    """

    def __init__(
        self, tag_map: TagMap | None, *, map_frame: str = "map", base_frame: str = "base_link",
        spawn: bool = False, connect: str | None = None, save: Path | None = None,
        premap: np.ndarray | None = None, name: str = "run",
    ) -> None:  # fmt: skip
        try:
            import rerun as rr
        except ImportError:
            raise missing_extra("rerun-sdk", "view") from None
        if not (spawn or connect or save):
            raise AdapterError("the view needs a viewer (spawn, connect) or a file (save)")
        self._rr: Any = rr
        self.rec: Any = rr.RecordingStream("tagloc", recording_id=name)
        sinks: list[Any] = []
        self.save = save
        self._partial = None if save is None else save.with_name(f".{save.name}.partial")
        if self._partial is not None:
            sinks.append(rr.FileSink(str(self._partial)))
        if spawn:
            self.rec.spawn(connect=False)
        if spawn or connect:
            sinks.append(rr.GrpcSink(connect) if connect else rr.GrpcSink())
        self.rec.set_sinks(*sinks)
        self.map_frame, self.base_frame = map_frame, base_frame
        self._paths: dict[str, tuple[int, list[tuple[float, float, float]]]] = {}
        self._step_ns, self._stamp_ns = round(1e9 / POSE_RATE_HZ), 0
        self._next_ns: dict[str, int] = {}
        self._T_map_base: SE3 | None = None
        self._T_base_frame: dict[str, SE3] = {}
        self._accepted = 0
        self._tag_centres = {
            e.id: np.asarray(e.T_frame_tag().translation) for e in tag_map or ()
            if e.frame == map_frame
        }  # fmt: skip
        self._static(tag_map, premap)

    # ----- static scene ----------------------------------------------------------------------
    def _static(self, tag_map: TagMap | None, premap: np.ndarray | None) -> None:
        rr = self._rr
        entries = [e for e in tag_map or () if e.frame == self.map_frame]
        if entries:
            poses = [e.T_frame_tag() for e in entries]
            self.rec.log("map/tags", rr.Boxes3D(
                centers=[np.asarray(T.translation) for T in poses],
                half_sizes=[(e.size / 2, e.size / 2, 0.002) for e in entries],
                quaternions=[rr.Quaternion(xyzw=T.as_quat()) for T in poses],
                labels=[str(e.id) for e in entries], colors=(30, 30, 30),
            ), static=True)  # fmt: skip
        if premap is not None and len(premap):
            step = max(1, len(premap) // MAX_PREMAP_POINTS)
            points = rr.Points3D(np.asarray(premap)[::step], radii=0.01, colors=(150, 150, 150))
            self.rec.log("map/premap", points, static=True)

    # ----- the input stream ------------------------------------------------------------------
    def tap(self, stream: Iterable[tuple[str, Message]]) -> Iterator[tuple[str, Message]]:
        """Pass ``stream`` through, drawing its lidar sweeps and the odometry's covariance."""
        for topic, msg in stream:
            if isinstance(msg, PointCloudMsg):
                self._sweep(msg)
            elif isinstance(msg, OdometryMsg):
                self._time(msg.stamp_ns)
                self._pose("odometry", msg.T_parent_child, msg.cov)
            elif isinstance(msg, TransformMsg) and msg.static and msg.parent == self.base_frame:
                self._T_base_frame[msg.child] = msg.T_parent_child
            yield topic, msg

    def _sweep(self, msg: PointCloudMsg) -> None:
        T_base_lidar = self._T_base_frame.get(msg.frame_id)
        if self._T_map_base is None or T_base_lidar is None or not len(msg.points):
            return
        points = np.asarray(msg.points, dtype=np.float64)
        points = points[np.isfinite(points).all(axis=1)]
        points = points[:: max(1, len(points) // MAX_SWEEP_POINTS)]
        self._time(msg.stamp_ns)
        points_map = (self._T_map_base @ T_base_lidar).act(points)
        self.rec.log("map/lidar", self._rr.Points3D(points_map, radii=0.02, colors=(255, 140, 0)))

    # ----- the node's outputs ----------------------------------------------------------------
    def write(self, output: NodeOutput) -> None:
        if isinstance(output, Estimate):
            if output.initialized:
                self._T_map_base = output.T_map_base
            if output.publish and output.initialized:
                self._time(output.stamp_ns)
                self._pose("fused", output.T_map_base, output.cov_map_base)
        elif isinstance(output, GroundTruthMsg):
            self._time(output.stamp_ns)
            self._pose("truth", output.T_frame_child, None)
        elif isinstance(output, FixAttempt):
            self._fix(output)
        elif isinstance(output, StatusReport):
            self._time(output.stamp_ns)
            self.rec.log("status/ladder_level", self._rr.Scalars([float(int(output.level))]))
        elif isinstance(output, LadderTransition):
            self._time(output.stamp_ns)
            self.rec.log("status/ladder_level", self._rr.Scalars([float(int(output.to_level))]))
            self.rec.log("status/events", self._rr.TextLog(
                f"ladder {int(output.from_level)} -> {int(output.to_level)}: {output.reason}"))

    def _fix(self, fix: FixAttempt) -> None:
        if not fix.in_map:  # a fix of a cab's tags is a pose in the cab, not in the map
            return
        rr = self._rr
        self._time(fix.stamp_ns)
        self._accepted += fix.accepted
        p = np.asarray(fix.T_map_base.translation)
        color = _ACCEPTED if fix.accepted else _REFUSED
        self.rec.log("map/fixes", rr.Points3D([p], radii=0.04, colors=color,
                                              labels=[f"{fix.source}: {fix.decision}"]))
        ends = [self._tag_centres.get(i) for i in fix.tag_ids]
        strips = [[p, c] for c in ends if c is not None]
        if strips and np.isfinite(p).all():
            self.rec.log("map/rays", rr.LineStrips3D(strips, radii=0.005, colors=color))
        self.rec.log("status/fixes_accepted", rr.Scalars([float(self._accepted)]))

    def _pose(self, name: str, T_map_base: SE3, cov: np.ndarray | None) -> None:
        rr = self._rr
        t = np.asarray(T_map_base.translation, dtype=np.float64)
        if not np.isfinite(t).all() or self._stamp_ns < self._next_ns.get(name, -(2**62)):
            return
        self._next_ns[name] = self._stamp_ns + self._step_ns
        self.rec.log(f"map/{name}", rr.Transform3D(
            translation=t, quaternion=rr.Quaternion(xyzw=T_map_base.as_quat())))  # fmt: skip
        if cov is not None and np.isfinite(cov[:3, :3]).all():
            w, V = np.linalg.eigh(0.5 * (cov[:3, :3] + cov[:3, :3].T))
            if np.linalg.det(V) < 0:
                V[:, 0] = -V[:, 0]
            R = SE3.from_matrix(np.block([[V, np.zeros((3, 1))], [np.zeros((1, 3)), 1.0]]))
            self.rec.log(f"map/{name}/cov", rr.Ellipsoids3D(
                half_sizes=[np.sqrt(np.clip(w, 1e-12, None))], centers=[(0.0, 0.0, 0.0)],
                quaternions=[rr.Quaternion(xyzw=R.as_quat())], colors=_COLORS[name],
            ))  # fmt: skip
        # the path in segments of PATH_POINTS, each its own entity (so all stay in view while
        # each log carries one short segment); a new segment starts at the last one's end
        k, path = self._paths.get(name, (0, []))
        path.append((float(t[0]), float(t[1]), float(t[2])))
        self.rec.log(f"map/path/{name}/{k}", rr.LineStrips3D([path], radii=0.01,
                                                             colors=_COLORS[name]))
        self._paths[name] = (k + 1, [path[-1]]) if len(path) >= PATH_POINTS else (k, path)

    def _time(self, stamp_ns: int) -> None:
        self._stamp_ns = stamp_ns
        self.rec.set_time("stream", duration=np.timedelta64(int(stamp_ns), "ns"))

    def close(self) -> Path | None:
        """Flush everything to the viewer and the file (renamed into place); return the file."""
        self.rec.flush()
        self.rec.disconnect()
        if self._partial is None or self.save is None:
            return None
        self._partial.replace(self.save)
        return self.save

    def abort(self) -> None:
        """Stop streaming and remove the unfinished file (an existing one is left as it was)."""
        self.rec.disconnect()
        if self._partial is not None:
            self._partial.unlink(missing_ok=True)
