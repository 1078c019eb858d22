"""``tagloc eval bag``: evaluate localization on site, from a bag without ground truth.

``tagloc eval bag BAG --tags tags.yaml [camera and topic options of tagloc localize]
[--checkpoints checkpoints.yaml] [--hold-out ID ...] --out DIR`` localizes the bag once
(acceptance by conditions, checkpoint repeatability, the extrinsic check), then once per
held-out tag (:mod:`tagloc.eval.onsite`), and writes ``summary.json``, ``summary.txt`` and
``report.html`` into ``--out`` (all or none, outputs checked before any work).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from tagloc.cli.bag_options import (
    DEFAULT_BAG_INPUTS,
    BagInputs,
    bag_topics_to_read,
    with_bag_inputs,
)
from tagloc.cli.engine_opts import JobsOpt, RayOpt
from tagloc.cli.eval_cmd import eval_app
from tagloc.cli.options import in_range

if TYPE_CHECKING:
    from tagloc.eval.onsite_conditions import ImageMeasure
    from tagloc.messages import Message
    from tagloc.tags import TagDetector


class _ImageTap:
    """Passes the stream through; measures blur and brightness of each image's tags."""

    def __init__(self, topic: str, detector: TagDetector | None) -> None:
        self.topic, self.detector = topic, detector
        self.measures: dict[tuple[int, int], ImageMeasure] = {}
        self.images = 0

    def __call__(self, stream: Iterable[tuple[str, Message]]) -> Iterator[tuple[str, Message]]:
        from tagloc.eval.onsite_conditions import image_measures
        from tagloc.messages import ImageMsg

        for topic, msg in stream:
            if topic == self.topic and isinstance(msg, ImageMsg) and self.detector is not None:
                self.images += 1
                dets = self.detector.detect(msg.image)
                for tag_id, m in image_measures(msg.image, dets).items():
                    self.measures[msg.stamp_ns, tag_id] = m
            yield topic, msg


@eval_app.command("bag")
@with_bag_inputs
def eval_bag(
    bag: Annotated[Path, typer.Argument(help="Input bag / MCAP.")],
    tags: Annotated[Path, typer.Option(help="Surveyed tag map.")],
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("out/eval_bag"),
    config: Annotated[Path | None, typer.Option(help="localizer.yaml.")] = None,
    bag_inputs: BagInputs = DEFAULT_BAG_INPUTS,  # the bag's camera and topic options
    checkpoints: Annotated[
        Path | None, typer.Option(help="checkpoints.yaml (name, x, y, radius); default: stops.")
    ] = None,
    hold_out: Annotated[
        list[int], typer.Option(help="Tag id to hold out (repeat; default: every tag).",
                                callback=in_range(ge=0))
    ] = [],  # noqa: B006
    no_hold_out: Annotated[
        bool, typer.Option("--no-hold-out", help="Skip the held-out-tag runs.")
    ] = False,
    max_range: Annotated[
        float, typer.Option(help="Held-out views up to this range, m.", callback=in_range(gt=0))
    ] = 4.0,
    min_stop: Annotated[
        float, typer.Option(help="A stop: still for this long, s.", callback=in_range(gt=0))
    ] = 2.0,
    jobs: JobsOpt = 1,
    ray: RayOpt = None,
) -> None:  # fmt: skip
    """Evaluate localization on a bag without ground truth: held-out tags, checkpoint
    repeatability, fix acceptance by conditions, the camera's extrinsics."""
    from rich.progress import Progress

    from tagloc.cli.bag_camera import bag_camera, bag_cameras, check_cameras
    from tagloc.cli.engine_opts import make_engine
    from tagloc.config import read_text_file
    from tagloc.eval.onsite import held_out_tags
    from tagloc.eval.onsite_checkpoints import checkpoint_spreads, detect_stops, parse_checkpoints
    from tagloc.eval.onsite_conditions import acceptance_by_conditions
    from tagloc.eval.onsite_report import ONSITE_FILES, onsite_summary, write_onsite_report
    from tagloc.eval.refusals import fix_decisions
    from tagloc.fileutil import check_outputs
    from tagloc.io import BagSource
    from tagloc.io.bag_stream import BagStream
    from tagloc.localize import LocalizeError, driver, load_localizer_config
    from tagloc.localize.config import LocalizerConfig
    from tagloc.localize.extrinsic_rig import ExtrinsicRecorder
    from tagloc.localize.node import LocalizerNode
    from tagloc.localize.outputs import RunRecorder
    from tagloc.tags import load_tag_map, make_detector

    cam = bag_inputs.camera
    check_outputs(
        {"--out": out}, directories={"--out": ONSITE_FILES},
        inputs={"BAG": bag, "--tags": tags, "--config": config, "--checkpoints": checkpoints,
                **cam.inputs()},
    )  # fmt: skip
    cfg = load_localizer_config(config) if config is not None else LocalizerConfig()
    tag_map = load_tag_map(tags)
    spots = None
    if checkpoints is not None:
        spots = parse_checkpoints(read_text_file(checkpoints, "checkpoints"), str(checkpoints))
    family = cfg.tags.family
    unknown = [i for i in hold_out if tag_map.get(i, family) is None]
    if unknown:
        raise LocalizeError(f"--hold-out {unknown[0]}: no tag {family}:{unknown[0]} in {tags}")
    topics = bag_inputs.topics()
    present = BagSource(bag, corner_order=cam.corner_order, default_family=family).bag_topics
    rig = bag_cameras(cam, present)  # every camera on its tag topic, or none
    camera, T_base_cam = (None, None) if rig else bag_camera(cam)
    wanted = bag_topics_to_read(bag, topics, cam.corner_order, family, truth=False,
                                rig_topics=[c.detections_topic for c in rig])  # fmt: skip
    camera_check = check_cameras(bag, rig, camera, T_base_cam, tag_map, topics,
                                 cam.corner_order, family)  # fmt: skip
    stream = BagStream(bag, tuple(wanted), cam.corner_order, family)

    engine = None if no_hold_out else make_engine(jobs, ray)  # a bad --ray before any work
    has_images = topics.image in wanted
    tap = _ImageTap(topics.image, make_detector(cfg.tags.backend, family) if has_images else None)
    recorder, extrinsics = RunRecorder(bag.name), ExtrinsicRecorder()
    node = partial(LocalizerNode, tag_map, cfg, camera=camera, T_base_cam=T_base_cam,
                   topics=topics, cameras=rig)  # fmt: skip
    result = driver.run(node, tap(stream()), [recorder, extrinsics])
    run = recorder.run(result.node.metadata())
    verdicts, rig_line = extrinsics.verdicts(result.node.T_base_cam_by_camera)
    ext = next(iter(verdicts.values()), None)
    stops = detect_stops(run, min_stop_s=min_stop)
    spreads = checkpoint_spreads(stops, spots)
    acceptance = acceptance_by_conditions(run.fixes, tap.measures if tap.images else None)
    held = None
    if engine is not None:
        ids = hold_out or list(tag_map.ids(family))
        try:
            with Progress(transient=True) as bar:
                task = bar.add_task(f"held-out tags ({engine.jobs} at once)", total=len(ids))
                held = held_out_tags(
                    stream, tag_map, cfg, tag_ids=ids, camera=camera, T_base_cam=T_base_cam,
                    topics=topics, family=family, max_range_m=max_range, engine=engine,
                    progress=lambda done, n: bar.update(task, completed=done), cameras=rig,
                )  # fmt: skip
        finally:
            engine.close()
    decisions = fix_decisions(run.fixes)
    facts = {
        "odometry_samples": len(run.stamps_ns), "camera_frames": len(run.frames),
        "fixes_accepted": sum(f.accepted for f in run.fixes), "fix_attempts": len(run.fixes),
        "images_measured": tap.images,
        "fix_decisions": decisions.to_dict(),
    }  # fmt: skip
    summary = onsite_summary(
        bag.name, held, stops, spreads, acceptance,
        checkpoints_from=str(checkpoints) if checkpoints else f"stops >= {min_stop:g} s",
        extrinsic_check=None if ext is None else ext.to_dict(), camera_check=camera_check,
        run_facts=facts, extrinsic_rig=rig_line,
        extrinsic_by_camera={n: v.to_dict() for n, v in verdicts.items()} if rig else None,
    )  # fmt: skip
    write_onsite_report(summary, held, stops, out, run)
    from tagloc.eval.onsite_report import summary_lines

    for line in [*summary_lines(summary), *decisions.lines()]:
        typer.echo(line)
    typer.echo(f"wrote {', '.join(ONSITE_FILES)} to {out}")
