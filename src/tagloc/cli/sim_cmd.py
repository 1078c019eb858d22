"""``tagloc sim``: the simulator's drives as bags, so any tool (and ``tagloc localize``) reads them.

``tagloc sim record --scenario NAME --out drive.mcap`` writes the scenario's message stream, the
same one ``tagloc localize --scenario`` consumes: ``/odom`` (``nav_msgs/Odometry``, odom ->
base_link), ``/tag_detections`` (pre-detected corners, ``apriltag_msgs/AprilTagDetectionArray``
layout), ``/camera/camera_info``, ``/tf_static`` (base_link -> camera_optical, base_link -> lidar),
the lidar's raw sweeps ``/lidar/points`` (``sensor_msgs/PointCloud2``, logged when each sweep is
complete) when the world's robot has a lidar, and the ground truth on its own topic
``/ground_truth`` (``geometry_msgs/PoseStamped`` of base_link in map). The tag map
the localizer should use is written beside it (``--tags-out``, default ``tags.yaml`` next to the
bag). ``--format`` picks MCAP, a ROS 2 bag directory or a ROS 1 ``.bag``; it must fit the name
(``.mcap``, a directory, ``.bag``). Both outputs are checked before the drive is simulated; they
are written atomically, and if the tag map cannot be written the new bag is removed again. An
existing directory is never replaced, except a lone ROS 2 bag by a ``ros2`` output.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tagloc.cli.options import duration_range, seed_range

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
    seed: Annotated[int, typer.Option(help="Odometry and detector seed.", callback=seed_range)] = 0,
    duration: Annotated[
        float | None, typer.Option(help="First N s only.", callback=duration_range)
    ] = None,
    tags_out: Annotated[
        Path | None, typer.Option(help="Tag map to write (default: tags.yaml beside the bag).")
    ] = None,
) -> None:
    """Record a simulated scenario (odometry, tag detections, camera, lidar, truth) to a bag."""
    from tagloc.fileutil import atomic_write_text, check_outputs
    from tagloc.io import bag_output_format, check_bag_target, is_ros2_bag_directory

    bag_format = bag_output_format(out, format)
    tags_path = tags_out if tags_out is not None else out.parent / "tags.yaml"
    replaceable = {"--out": is_ros2_bag_directory} if bag_format == "ros2" else {}
    check_outputs({"--out": out, "--tags-out": tags_path}, replaceable=replaceable)
    check_bag_target(out, bag_format)

    from tagloc.cli.localize_cmd import write_stream_bag
    from tagloc.sim.scenarios import ScenarioSource, build_scenario

    built = build_scenario(scenario, seed, duration)
    source = ScenarioSource(built)
    tags_text = built.tag_map.to_yaml_text()
    n = write_stream_bag(source, out, bag_format)
    try:
        atomic_write_text(tags_path, tags_text)
    except BaseException:
        _remove_bag(out)
        raise
    typer.echo(
        f"wrote {out} ({bag_format}, {n} messages, {len(source.frames)} camera frames, "
        f"topics {', '.join(sorted(source.topics))}) and {tags_path}"
    )


def _remove_bag(path: Path) -> None:
    """Remove the bag this command has just written (a file, or a lone ROS 2 bag directory)."""
    import shutil

    from tagloc.io import is_ros2_bag_directory

    if is_ros2_bag_directory(path):
        shutil.rmtree(path, ignore_errors=True)
    elif path.is_file():
        path.unlink(missing_ok=True)
