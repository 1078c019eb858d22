"""``tagloc localize``: a bag or a simulated scenario in; TUM files, events and a bag out.

Outputs in ``--out`` (each written atomically):

- ``fused.tum`` (``T_map_base = T_map_odom @ T_odom_base`` at every odometry stamp, published
  corrections), ``odometry.tum`` and, when known, ``truth.tum``;
- ``events.jsonl``: one filter decision per line; ``fixes.jsonl``: one fix attempt per line;
- ``localizer.yaml``: the configuration used; ``summary.txt``;
- ``localization.mcap`` (unless ``--no-bag``): ``/tf`` ``map -> odom`` and
  ``/localization/pose`` (``PoseWithCovarianceStamped`` of the base in the map) at 10 Hz.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import numpy as np
import typer

if TYPE_CHECKING:
    from tagloc.localize.run import LocalizationRun
    from tagloc.messages import Message

#: Published outputs are written at most at this rate (Hz of the odometry rows kept).
OUTPUT_RATE_HZ = 10.0


@dataclass(frozen=True, slots=True)
class LocalizeSummary:
    """What ``tagloc localize`` reports: files written and headline numbers."""

    files: tuple[Path, ...]
    lines: tuple[str, ...]


def write_stream_bag(
    stream: Iterable[tuple[str, Message]],
    path: Path,
    bag_format: Literal["mcap", "ros2", "ros1"] = "mcap",
) -> int:
    """Record a message stream (e.g. a simulated scenario) to a bag; return the count."""
    from tagloc.io import BagSink

    n = 0
    with BagSink(path, bag_format, overwrite=True) as sink:
        for topic, msg in stream:
            sink.write(topic, msg)
            n += 1
    return n


def summary_lines(run: LocalizationRun) -> list[str]:
    """Headline numbers of a run (ATE against truth when known)."""
    accepted = sum(a.accepted for a in run.fixes)
    offered = sum(not a.decision.startswith("rejected:") for a in run.fixes)
    lines = [
        f"{run.name}: {len(run.stamps_ns)} odometry samples, {len(run.frames)} camera frames",
        f"fixes: {len(run.fixes)} observations, {offered} offered to the filter, "
        f"{accepted} accepted; suspect sources: {run.metadata.get('suspect_sources', [])}",
    ]
    if run.T_map_base_truth is not None:
        truth = np.asarray(run.T_map_base_truth.translation)
        fused = np.linalg.norm(np.asarray(run.T_map_base.translation) - truth, axis=1)
        odom = np.linalg.norm(np.asarray(run.T_odom_base.translation) - truth, axis=1)
        lines.append(
            f"ATE RMSE (unaligned): fused {math.sqrt(float(np.mean(fused**2))):.3f} m, "
            f"odometry only {math.sqrt(float(np.mean(odom**2))):.3f} m"
        )
    return lines


def write_outputs(run: LocalizationRun, out: Path, *, bag: bool = True) -> LocalizeSummary:
    """Write a run's files to ``out`` (module docstring); every file atomically."""
    from tagloc.fileutil import atomic_write_text
    from tagloc.io import write_tum

    out.mkdir(parents=True, exist_ok=True)
    files = [out / "fused.tum", out / "odometry.tum"]
    write_tum(files[0], run.stamps_ns, run.T_map_base)
    write_tum(files[1], run.stamps_ns, run.T_odom_base)
    if run.T_map_base_truth is not None:
        files.append(out / "truth.tum")
        write_tum(files[-1], run.stamps_ns, run.T_map_base_truth)
    events = [
        {"stamp_ns": e.stamp_ns, "kind": str(e.kind), "source": e.source, "d2": e.d2,
         "threshold": e.threshold, "detail": e.detail}
        for e in run.events
    ]  # fmt: skip
    fixes = [
        {"stamp_ns": a.stamp_ns, "source": a.source, "decision": a.decision,
         "range_m": _num(a.range_m), "view_angle_rad": _num(a.view_angle_rad),
         "false_detection": a.false_detection}
        for a in run.fixes
    ]  # fmt: skip
    for name, rows in (("events.jsonl", events), ("fixes.jsonl", fixes)):
        files.append(out / name)
        atomic_write_text(files[-1], "".join(json.dumps(r) + "\n" for r in rows))
    config = run.metadata.get("config")
    if isinstance(config, dict):
        import yaml

        files.append(out / "localizer.yaml")
        atomic_write_text(files[-1], yaml.safe_dump(config, sort_keys=False))
    if bag:
        files.append(out / "localization.mcap")
        _write_output_bag(run, files[-1])
    lines = summary_lines(run)
    files.append(out / "summary.txt")
    atomic_write_text(files[-1], "\n".join(lines) + "\n")
    return LocalizeSummary(tuple(files), tuple(lines))


def _num(value: float) -> float | None:
    return value if math.isfinite(value) else None


def _write_output_bag(run: LocalizationRun, path: Path) -> None:
    from tagloc.io import BagSink, PoseWithCovarianceMsg, TransformMsg

    stamps = run.stamps_ns
    step = max(1, round(len(stamps) / max((stamps[-1] - stamps[0]) / 1e9 * OUTPUT_RATE_HZ, 1)))
    T_map_base = run.T_map_base
    with BagSink(path, "mcap", overwrite=True) as sink:
        for i in range(0, len(stamps), step):
            if not run.initialized[i]:
                continue
            stamp = int(stamps[i])
            sink.write("/tf", TransformMsg(stamp, "map", "odom", run.T_map_odom[i]))
            cov = run.cov_map_base[i]
            if np.isfinite(cov).all():
                sink.write(
                    "/localization/pose", PoseWithCovarianceMsg(stamp, "map", T_map_base[i], cov)
                )


def localize(
    bag: Annotated[Path | None, typer.Argument(help="Input bag / MCAP.")] = None,
    scenario: Annotated[str | None, typer.Option(help="Simulated scenario instead.")] = None,
    tags: Annotated[Path | None, typer.Option(help="Tag map (with a bag).")] = None,
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("out/localize"),
    config: Annotated[Path | None, typer.Option(help="localizer.yaml.")] = None,
    cameras: Annotated[Path | None, typer.Option(help="Kalibr camchain yaml.")] = None,
    odom_topic: Annotated[str, typer.Option(help="Odometry.")] = "/odom",
    detections_topic: Annotated[str, typer.Option(help="Tag corners.")] = "/tag_detections",
    image_topic: Annotated[str, typer.Option(help="Images.")] = "/camera/image",
    camera_info_topic: Annotated[str, typer.Option(help="CameraInfo.")] = "/camera/camera_info",
    truth_topic: Annotated[str, typer.Option(help="Ground truth.")] = "/ground_truth",
    seed: Annotated[int, typer.Option(help="Scenario seed.")] = 0,
    duration: Annotated[float | None, typer.Option(help="Scenario: first N s only.")] = None,
    no_bag: Annotated[bool, typer.Option("--no-bag", help="No localization.mcap.")] = False,
) -> None:  # fmt: skip
    """Localize a bag or a simulated scenario against a tag map; write TUM, events, a bag."""
    from rich.console import Console

    from tagloc.localize import LocalizeError, load_localizer_config

    if (bag is None) == (scenario is None):
        raise LocalizeError("give exactly one input: a bag path or --scenario NAME")
    cfg = None if config is None else load_localizer_config(config)
    if scenario is not None:
        from tagloc.sim.scenarios import run_scenario

        run = run_scenario(scenario, seed=seed, duration_s=duration, config=cfg)
    else:
        assert bag is not None
        run = _localize_bag(
            bag, tags, cfg, cameras,
            (odom_topic, detections_topic, image_topic, camera_info_topic, truth_topic),
        )  # fmt: skip
    result = write_outputs(run, out, bag=not no_bag)
    console = Console()
    for line in result.lines:
        console.print(line)
    console.print(f"wrote {len(result.files)} files to {out}")


def _localize_bag(
    bag: Path, tags: Path | None, cfg: object, cameras: Path | None, topics: tuple[str, ...]
) -> LocalizationRun:
    from tagloc.io import BagSource, load_kalibr_cameras
    from tagloc.localize import LocalizeError
    from tagloc.localize.pipeline import PipelineTopics, localize
    from tagloc.tags import load_tag_map

    if tags is None:
        raise LocalizeError("a bag needs the tag map: --tags tags.yaml")
    tag_map = load_tag_map(tags)
    camera = None if cameras is None else next(iter(load_kalibr_cameras(cameras).values()))
    roles = PipelineTopics(*topics)
    source = BagSource(bag)
    wanted = [t for t in topics if t in source.bag_topics]
    wanted += [t for t in source.bag_topics if t.rstrip("/").endswith("tf_static")]
    source = BagSource(bag, sorted(set(wanted)))
    return localize(source, tag_map, cfg, camera=camera, topics=roles, name=bag.name)  # type: ignore[arg-type]
