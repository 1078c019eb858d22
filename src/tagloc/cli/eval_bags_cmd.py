"""``tagloc eval bags``: many recorded drives evaluated in parallel into one report.

``tagloc eval bags LOG... [--tags tags.yaml] [--hold-out ID ...] [--jobs N | --ray ADDRESS]
--out DIR``: each log is localized against its map (``--tags``, else the ``tags.yaml`` beside
the log) and once per held-out tag; every pass of every log runs on one engine (a local process
pool, or a Ray cluster) and the results are merged per log (:mod:`tagloc.eval.fleet`). Writes
``summary.json``, ``summary.txt`` and ``report.html`` into ``--out`` when all passes have ended
(all or none; inputs, outputs and the cluster are checked before any work).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

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


@eval_app.command("bags")
@with_bag_inputs
def eval_bags(
    logs: Annotated[list[Path], typer.Argument(help="Recorded drives (bags / MCAP).")],
    out: Annotated[Path, typer.Option(help="Output directory.")] = Path("out/eval_bags"),
    tags: Annotated[
        Path | None, typer.Option(help="Tag map of every log (default: tags.yaml beside each).")
    ] = None,
    config: Annotated[Path | None, typer.Option(help="localizer.yaml.")] = None,
    bag_inputs: BagInputs = DEFAULT_BAG_INPUTS,  # the bag's camera and topic options
    truth_topic: Annotated[str, typer.Option(help="Ground truth, when a log has it.")] = (
        "/ground_truth"
    ),
    hold_out: Annotated[
        list[int], typer.Option(help="Tag id to hold out in every log (repeat; default: none).",
                                callback=in_range(ge=0))
    ] = [],  # noqa: B006
    max_range: Annotated[
        float, typer.Option(help="Held-out views up to this range, m.", callback=in_range(gt=0))
    ] = 4.0,
    jobs: JobsOpt = 1,
    ray: RayOpt = None,
) -> None:  # fmt: skip
    """Evaluate many recorded drives in parallel: per log and pooled reliability, fix decisions
    by reason, ladder time, suspect tags and held-out-tag errors."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    from tagloc.cli.bag_camera import bag_camera
    from tagloc.cli.engine_opts import engine_facts, make_engine
    from tagloc.eval.fleet import LogSpec, evaluate_logs
    from tagloc.eval.fleet_report import (
        FLEET_FILES,
        fleet_summary,
        summary_lines,
        write_fleet_report,
    )
    from tagloc.eval.protocol import EvalConfig
    from tagloc.fileutil import check_outputs
    from tagloc.io.bag_stream import BagStream
    from tagloc.localize import LocalizeError, load_localizer_config
    from tagloc.localize.config import LocalizerConfig
    from tagloc.tags import load_tag_map

    # 1. every input and output checked before any work
    cam = bag_inputs.camera
    maps = {log: tags if tags is not None else log.parent / "tags.yaml" for log in logs}
    check_outputs(
        {"--out": out}, directories={"--out": FLEET_FILES},
        inputs={**{f"LOG {log}": log for log in logs},
                **{f"tag map {m}": m for m in set(maps.values())}, "--config": config,
                **cam.inputs()},
    )  # fmt: skip
    cfg = load_localizer_config(config) if config is not None else LocalizerConfig()
    family = cfg.tags.family
    camera, T_base_cam = bag_camera(cam)
    topics = bag_inputs.topics(truth_topic)
    loaded = {m: load_tag_map(m) for m in set(maps.values())}
    names = [log.name for log in logs]
    common = os.path.commonpath([log.resolve().parent for log in logs])  # for names seen twice
    specs = []
    for log, name in zip(logs, names, strict=True):
        tag_map = loaded[maps[log]]
        unknown = [i for i in hold_out if tag_map.get(i, family) is None]
        if unknown:
            raise LocalizeError(f"--hold-out {unknown[0]}: no tag {family}:{unknown[0]} in "
                                f"{maps[log]}")  # fmt: skip
        wanted = bag_topics_to_read(log, topics, cam.corner_order, family)
        label = name if names.count(name) == 1 else os.path.relpath(log.resolve(), common)
        specs.append(LogSpec(
            label, BagStream(log, tuple(wanted), cam.corner_order, family), tag_map, cfg, topics,
            camera, T_base_cam, tuple(hold_out), family, max_range, EvalConfig(),
        ))  # fmt: skip
    engine = make_engine(jobs, ray)
    # 2. every pass on the engine, then the report
    passes = len(specs) * (1 + len(hold_out))
    try:
        columns = ("{task.description}", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
        with Progress(*columns, transient=True) as bar:
            task = bar.add_task(f"localizer passes ({engine.jobs} at once)", total=passes)
            results = evaluate_logs(specs, engine,
                                    lambda done, n: bar.update(task, completed=done))
    finally:
        engine.close()
    summary = fleet_summary(results, EvalConfig(), engine_facts(engine, ray, passes))
    write_fleet_report(summary, out)
    for line in summary_lines(summary):
        typer.echo(line)
    typer.echo(f"wrote {', '.join(FLEET_FILES)} to {out}")
