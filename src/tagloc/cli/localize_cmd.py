"""``tagloc localize``: a bag or a simulated scenario through the streaming node.

The same node a robot runs (:class:`~tagloc.localize.node.LocalizerNode`), fed by a bag reader
or the simulator, its outputs streaming to files in ``--out`` as they happen
(:mod:`tagloc.io.node_sinks`: ``fused.tum``, ``odometry.tum``, ``truth.tum``, ``events.jsonl``
with the ladder's transitions, ``fixes.jsonl``, ``status.jsonl``, ``localization.mcap`` with the
configured frame names, ``summary.json``/``summary.txt``) and the resolved ``localizer.yaml``.
Each file is renamed into place only when the run ends well; on a failure nothing is left.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import typer

from tagloc.cli.bag_camera import (
    CameraInfoTopicOpt,
    CameraPosesOpt,
    CamerasOpt,
    CornerOrderOpt,
    DetectionsTopicOpt,
    ImageTopicOpt,
    OdomTopicOpt,
    TagslamOpt,
    TfTopicOpt,
)
from tagloc.cli.options import SCENARIO_HELP, duration_range, in_range, seed_range
from tagloc.cli.wired import WiredNode
from tagloc.fileutil import check_outputs

if TYPE_CHECKING:
    import numpy as np

    from tagloc.cli.bag_camera import BagCamera
    from tagloc.io import BagTopic
    from tagloc.localize.config import LocalizerConfig
    from tagloc.localize.extrinsic_relative import RigVerdict
    from tagloc.localize.node import LocalizerNode
    from tagloc.localize.outputs import OutputSink
    from tagloc.messages import Message
    from tagloc.tags import TagMap

logger = logging.getLogger(__name__)
#: Files ``tagloc localize`` writes into ``--out``.
OUTPUT_FILES = (
    "fused.tum", "odometry.tum", "truth.tum", "events.jsonl", "fixes.jsonl", "status.jsonl",
    "localization.mcap", "summary.json", "summary.txt", "localizer.yaml", "report.html",
)  # fmt: skip


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


def localize(
    bag: Annotated[Path | None, typer.Argument(help="Input bag / MCAP.")] = None,
    scenario: Annotated[
        str | None, typer.Option(help=SCENARIO_HELP + " Instead of a bag.")
    ] = None,
    tags: Annotated[Path | None, typer.Option(help="Tag map (with a bag).")] = None,
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("out/localize"),
    config: Annotated[Path | None, typer.Option(help="localizer.yaml.")] = None,
    cameras: CamerasOpt = None,
    camera_poses: CameraPosesOpt = None,
    tagslam: TagslamOpt = None,
    corner_order: CornerOrderOpt = "tl_tr_br_bl",
    odom_topic: OdomTopicOpt = "/odom",
    detections_topic: DetectionsTopicOpt = "/tag_detections",
    image_topic: ImageTopicOpt = "/camera/image",
    camera_info_topic: CameraInfoTopicOpt = "/camera/camera_info",
    truth_topic: Annotated[str, typer.Option(help="Ground truth.")] = "/ground_truth",
    seed: Annotated[int, typer.Option(help="Scenario seed.", callback=seed_range)] = 0,
    duration: Annotated[
        float | None,
        typer.Option(help="First N s only (of the scenario, or of the bag).",
                     callback=duration_range),
    ] = None,
    tf_topic: TfTopicOpt = "/tf",
    lidar_topic: Annotated[str, typer.Option(help="Lidar sweeps (PointCloud2).")] = "/lidar/points",
    premap: Annotated[
        Path | None,
        typer.Option(help="Point cloud map (.ply/.pcd/.pc2.lcm, map frame) for the lidar fixes."),
    ] = None,
    no_bag: Annotated[
        bool,
        typer.Option(
            "--no-bag",
            help="Do not write localization.mcap (the outputs as a bag for Foxglove or ros2 bag "
            "play); the text files are written as always. Faster, smaller.",
        ),
    ] = False,
    realtime: Annotated[
        bool, typer.Option("--realtime", help="Pace by the wall clock; detect on a worker.")
    ] = False,
    speed: Annotated[
        float, typer.Option(help="With --realtime: speed factor.", callback=in_range(gt=0, le=1e3))
    ] = 1.0,
    view: Annotated[
        bool, typer.Option("--view", help="Watch it live (rerun; tagloc[view]).")
    ] = False,
    view_save: Annotated[
        Path | None, typer.Option(help="Record the live view to this .rrd file.")
    ] = None,
) -> None:  # fmt: skip
    """Localize a bag or a simulated scenario against a tag map, streaming every output to files."""
    from rich.console import Console

    from tagloc.localize import LocalizeError, load_localizer_config

    if (bag is None) == (scenario is None):
        raise LocalizeError("give exactly one input: a bag path or --scenario NAME")
    from tagloc.cli.bag_camera import BagCamera

    cam = BagCamera(cameras, camera_poses, tagslam, corner_order)
    check_outputs(
        {"--out": out, "--view-save": view_save}, directories={"--out": OUTPUT_FILES},
        inputs={"BAG": bag, "--tags": tags, "--config": config, "--premap": premap,
                **cam.inputs()},
    )  # fmt: skip
    cfg = None if config is None else load_localizer_config(config)
    points = None if premap is None else _read_premap(premap)

    topics = (odom_topic, detections_topic, image_topic, camera_info_topic, truth_topic, tf_topic,
              lidar_topic)  # fmt: skip
    if scenario is not None:
        wired = _scenario_node(scenario, seed, duration, cfg, points, live=realtime)
    else:
        assert bag is not None
        wired = _bag_node(bag, tags, cfg, cam, topics, points, live=realtime, duration=duration)
    from tagloc.cli.live import attach_live

    wired, live = attach_live(wired, view=view, view_save=view_save)
    try:
        written, lines = localize_wired(
            wired, out, bag=not no_bag, realtime=speed if realtime else None, sinks=live.sinks
        )
    except BaseException:
        live.abort()
        raise
    written += live.close(out, lines)
    console = Console()
    for line in lines:
        console.print(line)
    console.print(f"wrote {len(written)} files to {out}")


def live_order(config: LocalizerConfig, live: bool) -> LocalizerConfig:
    """``--realtime``: each odometry sample published before the frames it completes (the live
    order, ``output.publish_first``); else ``config`` unchanged."""
    if not live:
        return config
    output = config.output.model_copy(update={"publish_first": True})
    return config.model_copy(update={"output": output})


def localize_wired(
    wired: WiredNode, out: Path, *, bag: bool = True, realtime: float | None = None,
    sinks: Sequence[OutputSink] = (),
) -> tuple[list[Path], list[str]]:
    """Run the node on the stream (:func:`tagloc.localize.driver.run`) with its outputs
    streaming to files in ``out`` (:class:`~tagloc.io.node_sinks.RunFilesSink`); on any failure
    nothing of this run is left. ``realtime``: the wall clock at this speed, detection on a
    worker thread (else the replay clock); ``sinks``: more outputs beside the files (the status
    line, the report, the view)."""
    from tagloc.fileutil import atomic_write_text
    from tagloc.io.node_sinks import RunFilesSink
    from tagloc.localize.driver import run
    from tagloc.localize.extrinsic_rig import ExtrinsicRecorder

    sink = RunFilesSink(out, wired.config.frames.map_frame, bag=bag, name=wired.name)
    extrinsics = ExtrinsicRecorder()
    extra: dict[str, object] = {}
    if wired.camera_check is not None:
        extra["camera_check"] = wired.camera_check
    try:
        if realtime is not None:
            result = run(wired.node, wired.stream, [sink, extrinsics, *sinks], clock="wall",
                         speed=realtime)  # fmt: skip
            assert result.realtime is not None
            extra["realtime"] = result.realtime.to_dict()
            for line in result.realtime.lines():
                logger.info("%s", line)
        else:
            result = run(wired.node, wired.stream, [sink, extrinsics, *sinks])
        node = result.node
        _check_frames(node, sink.counts["frames"])
        verdicts, rig_line = extrinsics.verdicts(node.T_base_cam_by_camera)
        extra.update(_extrinsic_fields(verdicts, rig_line))
    except BaseException:
        sink.abort()
        raise
    metadata = node.metadata()
    if wired.skipped:  # inputs left out before the node (a lidar topic that is not sweeps)
        counts = Counter(metadata.get("skipped") or {})
        counts.update(wired.skipped)
        metadata["skipped"] = dict(counts)
    written, lines = sink.close({**metadata, **extra})
    lines += [f"WARNING: {v.warning}" for v in verdicts.values() if v.warning]
    atomic_write_text(out / "localizer.yaml", node.config.to_yaml_text())
    return [*written, out / "localizer.yaml"], lines


class _FirstSeconds:
    """The messages of a stream stamped within its first ``seconds`` (``--duration``)."""

    def __init__(self, stream: Iterable[tuple[str, Message]], seconds: float) -> None:
        self.stream, self.span_ns = stream, round(seconds * 1e9)

    def __iter__(self) -> Iterator[tuple[str, Message]]:
        t0 = None
        for topic, msg in self.stream:
            if t0 is None and msg.stamp_ns > 0:  # a static transform may be stamped 0
                t0 = msg.stamp_ns
            if t0 is not None and msg.stamp_ns - t0 > self.span_ns:
                return
            yield topic, msg


def _extrinsic_fields(verdicts: dict[str, RigVerdict], rig_line: str | None) -> dict[str, object]:
    """``summary.json``'s mounting check: ``extrinsic_check`` (the first camera's, or the one
    camera's), and on a rig ``extrinsic_check_by_camera`` and ``extrinsic_check_rig``."""
    first = next(iter(verdicts.values()), None)
    fields: dict[str, object] = {"extrinsic_check": None if first is None else first.to_dict()}
    if len(verdicts) > 1:
        fields["extrinsic_check_by_camera"] = {n: v.to_dict() for n, v in verdicts.items()}
        fields["extrinsic_check_rig"] = rig_line
    return fields


def _check_frames(node: LocalizerNode, n_frames: int) -> None:
    """No camera frame localized from a stream that had frames: one line saying why."""
    from tagloc.localize import LocalizeError

    if n_frames:
        return
    skipped = {k: v for k, v in node.skipped.items() if not k.startswith("odom_")}
    if skipped:
        raise LocalizeError(f"no camera frame could be used (skipped: {skipped})")
    logger.warning("no camera frame reached the node: check the detections/image topic")


def _read_premap(path: Path) -> np.ndarray:
    """The premap's ``(N, 3)`` points from a PLY, PCD or dimos ``.pc2.lcm`` file (one-line
    errors from io; a large PLY or PCD premap is voxel-downsampled on reading,
    :func:`~tagloc.io.pointcloud_files.read_premap`)."""
    from tagloc.io.dimos_premap import PC2_LCM_SUFFIX, read_pc2_lcm
    from tagloc.io.pointcloud_files import read_premap
    from tagloc.localize import LocalizeError

    if path.name.lower().endswith(PC2_LCM_SUFFIX):
        return read_pc2_lcm(path)
    suffix = path.suffix.lower()
    if suffix not in (".ply", ".pcd"):
        raise LocalizeError(f"--premap {path}: expected a .ply, .pcd or .pc2.lcm file")
    return read_premap(path)


def _check_premap(premap: np.ndarray | None, tag_map: TagMap, config: LocalizerConfig) -> None:
    """Refuse a premap the node cannot use before anything is written (one-line error)."""
    if premap is not None and config.lidar.enabled:
        from tagloc.localize.source_lidar import check_premap

        check_premap(premap, tag_map, config.frames.map_frame)


def _scenario_node(
    name: str, seed: int, duration: float | None, cfg: LocalizerConfig | None,
    premap: np.ndarray | None = None, *, live: bool = False,
) -> WiredNode:  # fmt: skip
    """The scenario's node; with the lidar (the world's robot has one, ``lidar.enabled``) the
    premap is ``premap`` or else the scenario's truth premap."""
    from tagloc.eval.scenarios import calibrated_config, scenario_config
    from tagloc.localize.node import LocalizerNode
    from tagloc.sim.scenarios import ScenarioSource, build_scenario, scenario_premap

    scenario = build_scenario(name, seed=seed, duration_s=duration)
    source = ScenarioSource(scenario)
    config = calibrated_config(scenario, cfg if cfg is not None else scenario_config())
    config = live_order(config, live)
    if premap is None and config.lidar.enabled and scenario.world.robot.lidar is not None:
        premap = scenario_premap(scenario)
    _check_premap(premap, scenario.tag_map, config)
    node = partial(
        LocalizerNode, scenario.tag_map, config, frame_truth=source.frame_truth, premap=premap
    )
    return WiredNode(config, node, source, f"scenario:{name}", None, scenario.tag_map, premap)


def _bag_node(
    bag: Path, tags: Path | None, cfg: LocalizerConfig | None, cam: BagCamera,
    topics: tuple[str, ...], premap: np.ndarray | None = None, *, live: bool = False,
    duration: float | None = None,
) -> WiredNode:  # fmt: skip
    from tagloc.cli.bag_camera import bag_camera, bag_cameras, check_cameras
    from tagloc.io import BagSource
    from tagloc.localize import LocalizeError
    from tagloc.localize.config import LocalizerConfig
    from tagloc.localize.node import LocalizerNode
    from tagloc.messages import NodeTopics
    from tagloc.tags import load_tag_map

    if tags is None:
        raise LocalizeError("a bag needs the tag map: --tags tags.yaml")
    tag_map = load_tag_map(tags)
    roles = NodeTopics(*topics)
    config = live_order(cfg or LocalizerConfig(), live)
    family = config.tags.family
    source = BagSource(bag, corner_order=cam.corner_order, default_family=family)
    rig = bag_cameras(cam, source.bag_topics)  # every camera on its tag topic, or none
    camera, T_base_cam = (None, None) if rig else bag_camera(cam)
    if roles.odom not in source.bag_topics and roles.tf not in source.bag_topics:
        raise LocalizeError(
            f"{bag}: no odometry: neither {roles.odom!r} nor {roles.tf!r} is in the bag "
            f"(topics: {', '.join(sorted(source.bag_topics)) or 'none'})"
        )
    present = {roles.detections, roles.image} & set(source.bag_topics)
    if not rig and not present:
        raise LocalizeError(
            f"{bag}: no camera frames: neither {roles.detections!r} nor {roles.image!r} is in "
            f"the bag (topics: {', '.join(sorted(source.bag_topics)) or 'none'})"
        )
    checked = check_cameras(bag, rig, camera, T_base_cam, tag_map, roles, cam.corner_order,
                             family)  # fmt: skip
    wanted = [t for t in topics if t in source.bag_topics]
    wanted += [c.detections_topic for c in rig]
    wanted += [t for t in source.bag_topics if t.rstrip("/").endswith("tf_static")]
    not_clouds = _lidar_not_point_clouds(bag, source.bag_topics.get(roles.lidar), roles.lidar,
                                         premap is not None)  # fmt: skip
    if not_clouds:
        wanted.remove(roles.lidar)
    source = BagSource(bag, sorted(set(wanted)), corner_order=cam.corner_order,
                       default_family=family)  # fmt: skip
    _check_premap(premap, tag_map, config)
    node = partial(LocalizerNode, tag_map, config, camera=camera, T_base_cam=T_base_cam,
                   topics=roles, premap=premap, cameras=rig)  # fmt: skip
    skipped = {"lidar_not_point_cloud": not_clouds} if not_clouds else {}
    stream = source if duration is None else _FirstSeconds(source, duration)
    return WiredNode(config, node, stream, bag.name, checked, tag_map, premap, skipped,
                     tuple(c.name for c in rig))  # fmt: skip


def _lidar_not_point_clouds(bag: Path, info: BagTopic | None, topic: str, premap: bool) -> int:
    """How many messages of the lidar topic are not ``PointCloud2`` sweeps (a ``LaserScan``):
    without a premap the lidar is not used and they are a counted skip; with one, an error."""
    from tagloc.localize import LocalizeError

    if info is None or info.msgtype == "sensor_msgs/msg/PointCloud2":
        return 0
    if premap:
        raise LocalizeError(
            f"{bag}: --lidar-topic {topic} has type {info.msgtype}; the lidar fixes need "
            "sensor_msgs/msg/PointCloud2 sweeps"
        )
    logger.warning("%s: %s has type %s, not PointCloud2: its %d messages are skipped",
                   bag, topic, info.msgtype, info.msgcount)  # fmt: skip
    return max(int(info.msgcount), 1)
