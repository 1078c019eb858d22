"""``tagloc sim``: the simulator's drives as bags, so any tool (and ``tagloc localize``) reads them.

``tagloc sim record --scenario NAME --out drive.mcap`` writes the scenario's message stream, the
same one ``tagloc localize --scenario`` consumes: ``/odom`` (``nav_msgs/Odometry``, odom ->
base_link), ``/tag_detections`` (pre-detected corners, ``apriltag_msgs/AprilTagDetectionArray``
layout), ``/camera/camera_info``, ``/tf_static`` (base_link -> camera_optical) and the ground truth
on its own topic ``/ground_truth`` (``geometry_msgs/PoseStamped`` of base_link in map). The tag map
the localizer should use is written beside it (``--tags-out``, default ``tags.yaml`` next to the
bag). ``--format`` picks MCAP, a ROS 2 bag directory or a ROS 1 ``.bag``. Outputs are atomic.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

sim_app = typer.Typer(help="Simulated drives: record one as a bag.", no_args_is_help=True)


@sim_app.command("record")
def sim_record(
    out: Annotated[Path, typer.Option(help="Bag to write (.mcap, ROS 2 directory or .bag).")],
    scenario: Annotated[str, typer.Option(help="Scenario (default, kidnap, glint, ...).")] = (
        "default"
    ),
    format: Annotated[
        str, typer.Option("--format", help="mcap | ros2 | ros1 (default: from the suffix).")
    ] = "",
    seed: Annotated[int, typer.Option(help="Odometry and detector seed.")] = 0,
    duration: Annotated[float | None, typer.Option(help="First N s only.")] = None,
    tags_out: Annotated[
        Path | None, typer.Option(help="Tag map to write (default: tags.yaml beside the bag).")
    ] = None,
) -> None:
    """Record a simulated scenario (odometry, tag detections, camera, truth) to a bag."""
    from tagloc.cli.localize_cmd import write_stream_bag
    from tagloc.io import BagWriteError
    from tagloc.sim.scenarios import ScenarioSource, build_scenario
    from tagloc.tags import save_tag_map

    kind = format or {".mcap": "mcap", ".bag": "ros1"}.get(out.suffix, "ros2")
    if kind not in ("mcap", "ros2", "ros1"):
        raise BagWriteError(f"--format {format!r}: expected mcap, ros2 or ros1")
    bag_format: Literal["mcap", "ros2", "ros1"] = kind  # type: ignore[assignment]
    built = build_scenario(scenario, seed, duration)
    source = ScenarioSource(built)
    n = write_stream_bag(source, out, bag_format)
    tags_path = tags_out if tags_out is not None else out.parent / "tags.yaml"
    save_tag_map(built.tag_map, tags_path)
    typer.echo(
        f"wrote {out} ({bag_format}, {n} messages, {len(source.frames)} camera frames, "
        f"topics {', '.join(sorted(source.topics))}) and {tags_path}"
    )
