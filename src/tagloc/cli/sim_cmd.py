"""``tagloc sim``: the simulator's drives as bags, so any tool (and ``tagloc localize``) reads them.

``tagloc sim record --scenario NAME --out drive.mcap`` writes the scenario's message stream, the
same one ``tagloc localize --scenario`` consumes: ``/odom`` (``nav_msgs/Odometry``, odom ->
base_link), ``/tag_detections`` (pre-detected corners, ``apriltag_msgs/AprilTagDetectionArray``
layout), ``/camera/camera_info``, ``/tf_static`` (base_link -> camera_optical, base_link -> lidar),
the lidar's raw sweeps ``/lidar/points`` (``sensor_msgs/PointCloud2``, logged when each sweep is
complete) when the world's robot has a lidar, and the ground truth on its own topic
``/ground_truth`` (``geometry_msgs/PoseStamped`` of base_link in map).

The tag map the localizer should use is written beside it (``--tags-out``, default ``tags.yaml``
next to the bag); a tag map already there that differs from the scenario's (edited by hand,
another scenario's) is not replaced unless ``--force`` (the same map is rewritten). ``--format``
picks MCAP, a ROS 2 bag directory or a ROS 1 ``.bag``; it must fit the name (``.mcap``, a
directory, ``.bag``); a name with another suffix (``x.txt``) is refused unless ``--format ros2``
says it is meant as a directory. Both outputs are checked before the drive is simulated; they
are written atomically, and if the tag map cannot be written the new bag is removed again. An
existing directory is never replaced, except a lone ROS 2 bag by a ``ros2`` output.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tagloc.cli.options import SCENARIO_HELP, duration_range, seed_range

sim_app = typer.Typer(help="Simulated drives: record one as a bag.", no_args_is_help=True)


@sim_app.command("record")
def sim_record(
    out: Annotated[Path, typer.Option(help="Bag to write (.mcap, ROS 2 directory or .bag).")],
    scenario: Annotated[str, typer.Option(help=SCENARIO_HELP)] = "default",
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
    force: Annotated[
        bool,
        typer.Option(
            "--force", help="Replace a tag map at --tags-out that differs from the scenario's."
        ),
    ] = False,
) -> None:
    """Record a simulated scenario (odometry, tag detections, camera, lidar, truth) to a bag."""
    from tagloc.fileutil import atomic_write_text, check_outputs
    from tagloc.io import BagWriteError, bag_output_format, check_bag_target, is_ros2_bag_directory

    if not format and out.suffix and out.suffix.lower() not in (".mcap", ".bag"):
        raise BagWriteError(
            f"--out {out}: a bag is a .mcap file, a .bag file or a ROS 2 directory without a "
            f"suffix; for a ROS 2 directory named {out.name!r} add --format ros2"
        )
    bag_format = bag_output_format(out, format)
    tags_path = tags_out if tags_out is not None else out.parent / "tags.yaml"
    replaceable = {"--out": is_ros2_bag_directory} if bag_format == "ros2" else {}
    check_outputs({"--out": out, "--tags-out": tags_path}, replaceable=replaceable)
    check_bag_target(out, bag_format)

    from tagloc.cli.localize_cmd import write_stream_bag
    from tagloc.sim.scenario_source import ScenarioSource
    from tagloc.sim.scenarios import build_scenario

    built = build_scenario(scenario, seed, duration)
    source = ScenarioSource(built)
    tags_text = built.tag_map.to_yaml_text()
    _check_tags_target(tags_path, tags_text, force)
    from tagloc.messages import ElevatorStateMsg

    # bags have no message type for a building's elevator state yet: it stays out of the bag
    recorded = ((t, m) for t, m in source if not isinstance(m, ElevatorStateMsg))
    n = write_stream_bag(recorded, out, bag_format)
    try:
        atomic_write_text(tags_path, tags_text)
    except BaseException:
        _remove_bag(out)
        raise
    typer.echo(
        f"wrote {out} ({bag_format}, {n} messages, {source.n_frames} camera frames, "
        f"topics {', '.join(sorted(set(source.topics) - {source.t.elevator}))}) and {tags_path}"
    )


def _check_tags_target(path: Path, text: str, force: bool) -> None:
    """Refuse to replace a tag map that differs from the one about to be written (one edited by
    hand, or another scenario's) unless ``--force``; the same map is rewritten silently."""
    from tagloc.errors import SimulationError

    if force or not path.is_file():
        return
    try:
        same = path.read_text(encoding="utf-8") == text
    except (OSError, UnicodeDecodeError):
        same = False
    if not same:
        raise SimulationError(
            f"--tags-out {path}: exists and differs from this scenario's tag map (edited, or "
            "from another scenario); pass --force to replace it, or --tags-out another path"
        )


def _remove_bag(path: Path) -> None:
    """Remove the bag this command has just written (a file, or a lone ROS 2 bag directory)."""
    import shutil

    from tagloc.io import is_ros2_bag_directory

    if is_ros2_bag_directory(path):
        shutil.rmtree(path, ignore_errors=True)
    elif path.is_file():
        path.unlink(missing_ok=True)
