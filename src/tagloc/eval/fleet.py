"""Many recorded drives evaluated together: one pass per log and per held-out tag, on an engine.

Each log (a :class:`LogSpec`: a picklable stream factory, its tag map and configuration) is
localized once against its whole map (:func:`log_pass`: reliability when the stream has ground
truth, fix decisions by reason, time at each ladder level, suspect tags, skipped input) and once
per held-out tag (:func:`~tagloc.eval.onsite.held_out_pass`). All passes of all logs are one
list mapped by an :class:`~tagloc.eval.engine.Engine`, so the logs and their held-out passes
fill the pool together; the results are merged per log in the logs' order, so the numbers do not
depend on the engine or the number of jobs (:func:`evaluate_logs`). :func:`pooled` adds the
logs up (counts summed, reliability as successes over opportunities of all logs).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass, field
from functools import partial
from typing import Any

from tagloc.camera import CameraModel
from tagloc.eval.engine import Engine, Progress
from tagloc.eval.onsite import (
    HeldOutObservation,
    HeldOutResult,
    HeldOutTask,
    StreamFactory,
    held_out_pass,
    merge_held_out,
)
from tagloc.eval.protocol import EvalConfig
from tagloc.eval.summary import evaluate
from tagloc.geometry import SE3
from tagloc.localize import driver
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.node import LocalizerNode, NodeTopics
from tagloc.localize.outputs import RunRecorder
from tagloc.tags import TagMap

__all__ = ["LogResult", "LogRun", "LogSpec", "evaluate_logs", "log_pass", "pooled"]


@dataclass(frozen=True, slots=True)
class LogSpec:
    """One recorded drive to evaluate (picklable when ``stream`` is).

    Attributes
    ----------
    name : str
    stream : callable
        Returns the log's message stream afresh (replayed once per pass).
    tag_map : TagMap
    config : LocalizerConfig
    topics : NodeTopics
    camera, T_base_cam : optional
        As for the node (default: the stream's CameraInfo and static transform).
    hold_out : tuple of int
        Tags to hold out, one pass each (empty: none).
    family : str
    max_range_m : float
        Held-out views up to this PnP range, m.
    eval_config : EvalConfig
        The reliability protocol's thresholds (with ground truth).
    """

    name: str
    stream: StreamFactory
    tag_map: TagMap
    config: LocalizerConfig = field(default_factory=LocalizerConfig)
    topics: NodeTopics = field(default_factory=NodeTopics)
    camera: CameraModel | None = None
    T_base_cam: SE3 | None = None
    hold_out: tuple[int, ...] = ()
    family: str = "tag36h11"
    max_range_m: float = 4.0
    eval_config: EvalConfig = field(default_factory=EvalConfig)

    def held_out_tasks(self) -> list[HeldOutTask]:
        return [
            HeldOutTask(self.stream, self.tag_map, tag_id, self.config, self.camera,
                        self.T_base_cam, self.topics, self.family, None, self.max_range_m)
            for tag_id in self.hold_out
        ]  # fmt: skip


@dataclass(frozen=True, slots=True)
class LogRun:
    """What the whole-map pass of one log measured (JSON-ready with :meth:`to_dict`).

    Attributes
    ----------
    name : str
    duration_s : float
    odometry_samples, camera_frames, fix_attempts, fixes_accepted : int
    decisions : dict of str -> int
        Fix attempts by decision (``accepted``, ``gated_chi2``, ``rejected:<reason>``, ...).
    ladder_s : dict of str -> float
        Seconds at each ladder level.
    ladder_transitions : int
    suspect_sources : list of str
        Sources (``tag:<id>``) the filter flagged as moved.
    skipped : dict of str -> int
        Input the node dropped, by reason.
    opportunities, successes : int or None
        The reliability protocol's counts (None without ground truth).
    ate_fused_m : float or None
        Fused ATE RMSE (unaligned) against ground truth (None without).
    wall_s : float
        Wall time of the pass (not part of the results' equality).
    """

    name: str
    duration_s: float
    odometry_samples: int
    camera_frames: int
    fix_attempts: int
    fixes_accepted: int
    decisions: dict[str, int]
    ladder_s: dict[str, float]
    ladder_transitions: int
    suspect_sources: list[str]
    skipped: dict[str, int]
    opportunities: int | None
    successes: int | None
    ate_fused_m: float | None
    wall_s: float = field(default=0.0, compare=False)

    @property
    def reliability(self) -> float | None:
        if not self.opportunities or self.successes is None:
            return None
        return self.successes / self.opportunities

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name, "duration_s": self.duration_s,
            "odometry_samples": self.odometry_samples, "camera_frames": self.camera_frames,
            "fix_attempts": self.fix_attempts, "fixes_accepted": self.fixes_accepted,
            "decisions": dict(self.decisions), "ladder_s": dict(self.ladder_s),
            "ladder_transitions": self.ladder_transitions,
            "suspect_sources": list(self.suspect_sources), "skipped": dict(self.skipped),
            "reliability": {"opportunities": self.opportunities, "successes": self.successes,
                            "fraction": self.reliability},
            "ate_fused_m": self.ate_fused_m, "wall_s": self.wall_s,
        }  # fmt: skip


@dataclass(frozen=True, slots=True)
class LogResult:
    """One log's whole-map pass and its held-out tags."""

    run: LogRun
    held_out: HeldOutResult | None

    def to_dict(self) -> dict[str, Any]:
        return {**self.run.to_dict(),
                "held_out_tags": None if self.held_out is None else self.held_out.to_dict()}


def log_pass(spec: LogSpec) -> LogRun:
    """Localize one log against its whole map and measure it (:class:`LogRun`)."""
    t0 = time.perf_counter()
    node = partial(
        LocalizerNode, spec.tag_map, spec.config, camera=spec.camera,
        T_base_cam=spec.T_base_cam, topics=spec.topics,
    )  # fmt: skip
    recorder = RunRecorder(spec.name)
    done = driver.run(node, spec.stream(), [recorder])
    run = recorder.run(done.node.metadata())
    skipped = done.node.skipped
    ladder = run.metadata.get("ladder")
    ladder = ladder if isinstance(ladder, dict) else {}
    opportunities = successes = None
    ate = None
    if run.T_map_base_truth is not None and len(run.stamps_ns) >= 2:
        summary = evaluate(run, spec.eval_config).summary
        fused = summary.estimators["fused"]
        if fused.reliability is not None:
            opportunities = fused.reliability.n_opportunities
            successes = fused.reliability.n_success
        ate = fused.ate_rmse_m if math.isfinite(fused.ate_rmse_m) else None
    stamps = run.stamps_ns
    suspects = run.metadata.get("suspect_sources")
    return LogRun(
        name=spec.name,
        duration_s=float(stamps[-1] - stamps[0]) * 1e-9 if len(stamps) else 0.0,
        odometry_samples=len(stamps), camera_frames=len(run.frames),
        fix_attempts=len(run.fixes), fixes_accepted=sum(f.accepted for f in run.fixes),
        decisions=dict(sorted(Counter(f.decision for f in run.fixes).items())),
        ladder_s={str(k): float(v) for k, v in ladder.get("seconds_at_level", {}).items()},
        ladder_transitions=int(ladder.get("transitions", 0)),
        suspect_sources=[str(s) for s in suspects] if isinstance(suspects, list) else [],
        skipped=dict(sorted(skipped.items())), opportunities=opportunities,
        successes=successes, ate_fused_m=ate, wall_s=time.perf_counter() - t0,
    )  # fmt: skip


def _one_pass(item: tuple[LogSpec, HeldOutTask | None]) -> object:
    """One item of the engine's list: a log's whole-map pass or one of its held-out passes."""
    spec, task = item
    return log_pass(spec) if task is None else held_out_pass(task)


def evaluate_logs(
    specs: list[LogSpec], engine: Engine, progress: Progress | None = None
) -> list[LogResult]:
    """Every pass of every log on ``engine``; one :class:`LogResult` per log, in order.

    Raises
    ------
    TaglocError
        The first failure of any pass (a bad bag, a stream without odometry), after the passes
        running beside it have ended; nothing is returned then.
    """
    items: list[tuple[LogSpec, HeldOutTask | None]] = []
    for spec in specs:
        items.append((spec, None))
        items += [(spec, task) for task in spec.held_out_tasks()]
    results = iter(engine.map(_one_pass, items, progress))
    out = []
    for spec in specs:
        run = next(results)
        assert isinstance(run, LogRun)
        views: list[list[HeldOutObservation] | None] = [
            next(results) for _ in spec.hold_out  # type: ignore[misc]
        ]
        held = merge_held_out(spec.hold_out, views) if spec.hold_out else None
        out.append(LogResult(run, held))
    return out


def pooled(results: list[LogResult]) -> dict[str, Any]:
    """The logs added up (module docstring), JSON-ready."""
    runs = [r.run for r in results]
    decisions: Counter[str] = Counter()
    ladder: Counter[str] = Counter()
    skipped: Counter[str] = Counter()
    for r in runs:
        decisions.update(r.decisions)
        ladder.update(r.ladder_s)
        skipped.update(r.skipped)
    with_truth = [r for r in runs if r.opportunities is not None]
    opp = sum(r.opportunities or 0 for r in with_truth)
    succ = sum(r.successes or 0 for r in with_truth)
    held = HeldOutResult()
    for log in results:
        if log.held_out is not None:
            held.observations.extend(log.held_out.observations)
    suspects = sorted({f"{r.name}:{s}" for r in runs for s in r.suspect_sources})
    return {
        "logs": len(runs), "duration_s": sum(r.duration_s for r in runs),
        "fix_attempts": sum(r.fix_attempts for r in runs),
        "fixes_accepted": sum(r.fixes_accepted for r in runs),
        "decisions": dict(sorted(decisions.items())), "ladder_s": dict(ladder),
        "skipped": dict(sorted(skipped.items())), "suspect_sources": suspects,
        "reliability": {"logs_with_truth": len(with_truth), "opportunities": opp,
                        "successes": succ, "fraction": succ / opp if opp else None},
        "held_out_tags": held.to_dict()["overall"] if held.observations else None,
    }  # fmt: skip
