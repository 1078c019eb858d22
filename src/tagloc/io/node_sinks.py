"""The localizer node's outputs streamed to files as they happen (``tagloc localize``).

:class:`RunFilesSink` writes, in ``out_dir`` (each file into a temporary file beside it, renamed
into place by :meth:`RunFilesSink.close`; :meth:`RunFilesSink.abort` leaves what was there):

- ``fused.tum`` (``T_map_base`` at every odometry sample, from the published correction),
  ``odometry.tum`` and, when the stream has ground truth, ``truth.tum``;
- ``events.jsonl``: the filter's own events (initialization, gap, cap, suspect source) and
  every ladder transition (``kind: ladder`` with ``from``, ``to``, ``reason``), one JSON object
  per line; ``fixes.jsonl``: every fix attempt with its final decision (and the tested ``d2``);
  ``status.jsonl``: the status messages;
- ``localization.mcap`` (unless disabled): the published transform on ``/tf`` with the
  configured frame names and ``/localization/pose`` (``PoseWithCovarianceStamped`` of the base
  in the map) at ``output.publish_rate_hz``;
- at :meth:`RunFilesSink.close`: ``summary.json`` (counts, the fix attempts by decision and
  per camera with the hint of a dominant refusal (:mod:`tagloc.eval.refusals`), ladder time
  per level and transitions, ATE against truth when known) and ``summary.txt``.

Memory is constant: running sums only.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from tagloc.eval.refusals import DecisionBook
from tagloc.fileutil import AtomicTextStream, atomic_write_text
from tagloc.geometry import SE3
from tagloc.io.bag_writer import BagSink
from tagloc.io.tum import TUM_HEADER, tum_line
from tagloc.localize.events import FilterEvent
from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.localize.run import CameraFrameRecord, FixAttempt
from tagloc.messages import GroundTruthMsg, PoseWithCovarianceMsg, TransformMsg
from tagloc.supervise import LadderTransition, StatusReport

__all__ = ["RunFilesSink"]


class RunFilesSink:
    """Streams a run's outputs to ``out_dir`` (module docstring).

    Parameters
    ----------
    out_dir : Path
        Created if missing; files of the same names are replaced at :meth:`close`.
    map_frame : str
        The configured map frame (the pose's frame; the transform's parent or child).
    bag : bool
        Write ``localization.mcap``.
    name : str
        The run's name, for the summary.
    """

    def __init__(
        self, out_dir: Path, map_frame: str, *, bag: bool = True, name: str = "run"
    ) -> None:
        self.out_dir, self.map_frame, self.name = Path(out_dir), map_frame, name
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._files: dict[str, AtomicTextStream] = {}
        for fname in ("fused.tum", "odometry.tum"):
            self._open(fname).write(TUM_HEADER)
        for fname in ("events.jsonl", "fixes.jsonl", "status.jsonl"):
            self._open(fname)
        self._bag = (
            BagSink(self.out_dir / "localization.mcap", "mcap", overwrite=True) if bag else None
        )
        self._last: Estimate | None = None
        self.counts: Counter[str] = Counter()
        self._sq = {"fused": 0.0, "odometry": 0.0}
        self._n_truth = 0
        self._ladder_moves = 0
        self.decisions = DecisionBook()

    def _open(self, fname: str) -> AtomicTextStream:
        self._files[fname] = AtomicTextStream(self.out_dir / fname)
        return self._files[fname]

    def write(self, output: NodeOutput) -> None:
        if isinstance(output, Estimate):
            self._estimate(output)
        elif isinstance(output, FilterEvent):
            self.counts[f"event:{output.kind}"] += 1
            self._json("events.jsonl", {
                "stamp_ns": output.stamp_ns, "kind": str(output.kind), "source": output.source,
                "d2": output.d2, "threshold": output.threshold, "detail": output.detail,
            })  # fmt: skip
        elif isinstance(output, LadderTransition):
            self._ladder_moves += 1
            self._json("events.jsonl", output.to_dict())
        elif isinstance(output, StatusReport):
            self._json("status.jsonl", output.to_dict())
        elif isinstance(output, FixAttempt):
            self.counts["fixes"] += 1
            self.counts["offered"] += not output.decision.startswith("rejected:")
            self.counts["accepted"] += output.accepted
            self.decisions.add(output)
            self._json("fixes.jsonl", output.to_row())
        elif isinstance(output, CameraFrameRecord):
            self.counts["frames"] += 1
        elif isinstance(output, GroundTruthMsg):
            self._truth(output)

    def _estimate(self, e: Estimate) -> None:
        self.counts["odometry"] += 1
        self._last = e
        T = e.T_map_base
        self._files["fused.tum"].write(tum_line(e.stamp_ns, _values(T)))
        A = e.T_odom_base
        self._files["odometry.tum"].write(tum_line(e.stamp_ns, _values(A)))
        if self._bag is not None and e.publish and e.initialized:
            T_pc = e.T_parent_child(self.map_frame)
            self._bag.write("/tf", TransformMsg(e.stamp_ns, e.parent, e.child, T_pc))
            if e.cov_map_base is not None and np.isfinite(e.cov_map_base).all():
                self._bag.write("/localization/pose", PoseWithCovarianceMsg(
                    e.stamp_ns, self.map_frame, T, e.cov_map_base))  # fmt: skip

    def _truth(self, msg: GroundTruthMsg) -> None:
        if "truth.tum" not in self._files:
            self._open("truth.tum").write(TUM_HEADER)
        T = msg.T_frame_child
        self._files["truth.tum"].write(tum_line(msg.stamp_ns, _values(T)))
        e = self._last
        if e is not None and e.stamp_ns == msg.stamp_ns:
            t = np.asarray(T.translation)
            self._sq["fused"] += float(np.sum((np.asarray(e.T_map_base.translation) - t) ** 2))
            self._sq["odometry"] += float(np.sum((np.asarray(e.T_odom_base.translation) - t) ** 2))
            self._n_truth += 1

    def _json(self, fname: str, row: dict[str, Any]) -> None:
        self._files[fname].write(json.dumps(row) + "\n")

    # ----- end -------------------------------------------------------------------------------
    def summary(self, metadata: dict[str, Any]) -> dict[str, Any]:
        """The run's headline numbers (``metadata``: the node's)."""
        c = self.counts
        out: dict[str, Any] = {
            "name": self.name, "odometry_samples": c["odometry"], "camera_frames": c["frames"],
            "fix_attempts": c["fixes"], "fixes_offered": c["offered"],
            "fixes_accepted": c["accepted"],
            "events": {k.removeprefix("event:"): v for k, v in c.items() if k.startswith("event:")},
            "ladder": metadata.get("ladder"), "skipped": metadata.get("skipped"),
            "suspect_sources": metadata.get("suspect_sources"),
            "odometry_calibration": metadata.get("odometry_calibration"),
            "fix_decisions": self.decisions.result().to_dict(),
        }  # fmt: skip
        for key in ("realtime", "extrinsic_check", "extrinsic_check_by_camera",
                    "extrinsic_check_rig", "camera_check"):  # fmt: skip
            if key in metadata:
                out[key] = metadata[key]
        if self._n_truth:
            out["ate_unaligned_m"] = {k: math.sqrt(v / self._n_truth) for k, v in self._sq.items()}
        return out

    def summary_lines(self, summary: dict[str, Any]) -> list[str]:
        s = summary
        lines = [
            f"{self.name}: {s['odometry_samples']} odometry samples, {s['camera_frames']} camera "
            "frames",
            f"fixes: {s['fix_attempts']} observations, {s['fixes_offered']} offered to the "
            f"filter, {s['fixes_accepted']} accepted; suspect sources: {s['suspect_sources']}",
        ]
        lines += self.decisions.result().lines()
        ladder = s.get("ladder") or {}
        if ladder:
            at = ", ".join(f"{k} {v:.1f} s" for k, v in ladder["seconds_at_level"].items() if v)
            lines.append(f"ladder: {ladder['transitions']} transitions; time at level: {at}")
        if "ate_unaligned_m" in s:
            ate = s["ate_unaligned_m"]
            lines.append(
                f"ATE RMSE (unaligned): fused {ate['fused']:.3f} m, odometry only "
                f"{ate['odometry']:.3f} m"
            )
        by_camera = s.get("extrinsic_check_by_camera") or {"": s.get("extrinsic_check")}
        for name, ext in by_camera.items():
            if ext:
                lines.append(
                    f"extrinsic check{f' {name}' if name else ''}: camera mounting off by "
                    f"{ext['rotation_deg']:.2f} deg / {ext['translation_m'] * 100:.1f} cm "
                    f"({ext['n_pairs']} fix pairs, {math.sqrt(ext['d2']):.1f} sigma of "
                    f"{math.sqrt(ext['d2_threshold']):.1f}; unobservable: "
                    f"{', '.join(ext['unobservable']) or 'none'})"
                )
        if s.get("extrinsic_check_rig"):
            lines.append(f"extrinsic check (rig): {s['extrinsic_check_rig']}")
        return lines

    def close(self, metadata: dict[str, Any]) -> tuple[list[Path], list[str]]:
        """Finish every file (renamed into place) and write the summaries; return the paths
        written and the summary's lines."""
        written = [f.commit() for f in self._files.values()]
        self._files.clear()
        if self._bag is not None:
            self._bag.close()
            written.append(self._bag.path)
        summary = self.summary(metadata)
        lines = self.summary_lines(summary)
        for fname, text in (("summary.json", json.dumps(summary, indent=2) + "\n"),
                            ("summary.txt", "\n".join(lines) + "\n")):  # fmt: skip
            atomic_write_text(self.out_dir / fname, text)
            written.append(self.out_dir / fname)
        return written, lines

    def abort(self) -> None:
        """Discard every file of this run (the directory keeps what it held before)."""
        for f in self._files.values():
            f.abort()
        self._files.clear()
        if self._bag is not None:
            self._bag.abort()


def _values(T: SE3) -> list[float]:
    return [*np.asarray(T.translation).tolist(), *np.asarray(T.as_quat()).tolist()]
