"""``tagloc map``: check a tag map file, compare two (thin glue over :mod:`tagloc.tags.tagmap`).

- ``tagloc map check tags.yaml`` prints ``tags.yaml: ok: <summary>`` (tags per family, tags per
  frame, anchors), or one error line naming file, entry and field, and exits 1; warnings about
  floors (:mod:`tagloc.tags.tagmap_floors`) go to stderr.
- ``tagloc map build --out tags.yaml ...`` builds a tag map from a survey; with lidar sweeps it
  also writes ``premap.ply`` (or ``.pcd``) and ``map.yaml`` + ``map.pgm`` beside it, all in
  ``map``, all or none (:func:`tagloc.io.survey_files.write_survey_outputs`).
- ``tagloc map diff old.yaml new.yaml`` prints one line per change (see
  :mod:`tagloc.tags.tagmap_diff`), or ``no differences``. It exits 0 either way; with
  ``--exit-code`` it exits 1 when there are differences, like ``git diff --exit-code`` (an
  unreadable or invalid file also exits 1, with a ``tagloc: error:`` line on stderr).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal, cast

import typer

from tagloc.cli.map_inputs import (
    MAX_TAG_EDGE_M,
    bag_survey,
    build_config,
    measured_anchors,
    parse_anchor_sigma,
    parse_exclusion,
    parse_tag_sizes,
    product_paths,
)
from tagloc.cli.options import OptionError, in_range, positive_int, seed_range

if TYPE_CHECKING:
    from collections.abc import Mapping

    from tagloc.geometry import SE3
    from tagloc.mapping.anchors import Anchor

map_app = typer.Typer(
    help="Tag maps (tags.yaml): build one from a survey, check one, compare two.",
    no_args_is_help=True,
)

#: Most odometry self-calibration rounds accepted (each is a full optimization of the survey).
MAX_CALIBRATION_ROUNDS = 10


MapFile = Annotated[Path, typer.Argument(help="Tag map YAML file.", show_default=False)]


@map_app.command("check")
def map_check(path: MapFile) -> None:
    """Validate a tag map; print a one-line summary or one line naming the bad field.

    Warnings about floors (a tag off its floor, a floor without tags) go to stderr, one line
    each; they do not fail the check."""
    from tagloc.tags.tagmap import load_tag_map
    from tagloc.tags.tagmap_floors import floor_warnings

    tag_map = load_tag_map(path)
    for warning in floor_warnings(tag_map):
        typer.echo(f"{path}: warning: {warning}", err=True)
    typer.echo(f"{path}: ok: {tag_map.summary()}")


@map_app.command("diff")
def map_diff(
    old: MapFile,
    new: MapFile,
    min_move_cm: Annotated[
        float, typer.Option(help="Smaller moves are not reported.", callback=in_range(ge=0))
    ] = 0.5,
    min_rot_deg: Annotated[
        float,
        typer.Option(help="Smaller rotations are not reported.", callback=in_range(ge=0, le=180)),
    ] = 0.5,
    exit_code: Annotated[
        bool, typer.Option("--exit-code", help="Exit with 1 if the maps differ (as git diff).")
    ] = False,
) -> None:
    """Print what changed from OLD to NEW: added, removed, moved tags, changed fields."""
    from tagloc.tags.tagmap import load_tag_map
    from tagloc.tags.tagmap_diff import (
        diff_tag_maps,
        format_tag_map_diff,
        summarize_tag_map_diff,
    )

    diff = diff_tag_maps(
        load_tag_map(old),
        load_tag_map(new),
        min_move_m=min_move_cm / 100.0,
        min_rot_deg=min_rot_deg,
    )
    lines = format_tag_map_diff(diff)
    if lines:
        typer.echo("\n".join(lines))
        typer.echo(f"{summarize_tag_map_diff(diff)} ({old} -> {new})")
    else:
        typer.echo(f"no differences: {old} {new}")
    if exit_code and not diff.is_empty:
        raise typer.Exit(code=1)


# ----- tagloc map build ---------------------------------------------------------------------------
@map_app.command("build")
def map_build(
    out: Annotated[Path, typer.Option("--out", help="Tag map to write (tags.yaml).")],
    bag: Annotated[Path | None, typer.Option(help="Bag with odometry and tag detections.")] = None,
    sim: Annotated[bool, typer.Option("--sim", help="Map a simulated survey drive.")] = False,
    world: Annotated[Path | None, typer.Option(help="World for --sim (default office).")] = None,
    seed: Annotated[
        int, typer.Option(help="Odometry and detector seed for --sim.", callback=seed_range)
    ] = 1,
    camera_stride: Annotated[
        int, typer.Option(help="Use every n-th camera frame.", callback=positive_int)
    ] = 1,
    cameras: Annotated[Path | None, typer.Option(help="Kalibr cameras.yaml (with --bag).")] = None,
    camera_poses: Annotated[
        Path | None, typer.Option(help="camera_poses.yaml: T_body_cam of each camera.")
    ] = None,
    tagslam: Annotated[
        Path | None, typer.Option(help="tagslam.yaml: anchors, T_body_odom, ignored ids.")
    ] = None,
    tag_topic: Annotated[
        list[str], typer.Option(help="CAM=TOPIC (repeat); default: cameras.yaml tagtopic.")
    ] = [],  # noqa: B006 - typer needs a literal default
    odom_topic: Annotated[str, typer.Option(help="Odometry topic.")] = "/odom",
    corner_order: Annotated[
        str, typer.Option(help="How the bag lists corners, e.g. bl_br_tr_tl.")
    ] = "tl_tr_br_bl",
    anchor: Annotated[
        list[int], typer.Option(help="Anchor tag id (repeat).", callback=in_range(ge=0))
    ] = [],  # noqa: B006
    anchors: Annotated[
        Path | None, typer.Option(help="tags.yaml whose entries give anchor poses.")
    ] = None,
    tag_size: Annotated[
        float | None,
        typer.Option(help="Default tag edge, m.", callback=in_range(gt=0, le=MAX_TAG_EDGE_M)),
    ] = None,
    size: Annotated[list[str], typer.Option(help="ID=EDGE_M per tag (repeat).")] = [],  # noqa: B006
    report: Annotated[Path | None, typer.Option(help="QA report file (.json or .md).")] = None,
    no_lidar: Annotated[
        bool, typer.Option("--no-lidar", help="Tags and odometry only (no scan matching).")
    ] = False,
    lidar_topic: Annotated[
        str,
        typer.Option(
            help="PointCloud2 topic of the lidar (with --bag; the default only if the bag has it)."
        ),
    ] = "/lidar/points",
    premap_format: Annotated[
        str,
        typer.Option(
            help="Premap file beside --out: ply (premap.ply), pcd (premap.pcd) or pc2.lcm "
            "(premap.pc2.lcm, a dimos premap)."
        ),
    ] = "ply",
    calibrate_odometry: Annotated[
        int | None,
        typer.Option(
            help="Odometry self-calibration rounds (default: with --sim the simulation's "
            "matched configuration, 1 round then joint; else 0).",
            callback=in_range(ge=0, le=MAX_CALIBRATION_ROUNDS),
        ),
    ] = None,
    config_file: Annotated[
        Path | None,
        typer.Option("--config", help="Map build configuration YAML (MapBuildConfig fields)."),
    ] = None,
    gravity: Annotated[
        bool | None,
        typer.Option(
            "--gravity-aligned-odometry/--no-gravity",
            help="The odometry's z is gravity (VIO): roll and pitch priors on every keyframe.",
        ),
    ] = None,
    anchor_sigma: Annotated[
        str | None,
        typer.Option(
            help="POS_M,ROT_DEG: sigma of anchors that give none (tags.yaml anchor_sigma)."
        ),
    ] = None,
    uncertain_cm: Annotated[
        float | None,
        typer.Option(
            help="Flag tags whose position sigma exceeds this (default 5).",
            callback=in_range(gt=0, le=1000),
        ),
    ] = None,
    export_graph: Annotated[
        Path | None,
        typer.Option(help="Write every factor and its residual at the solution (JSON lines)."),
    ] = None,
    exclude: Annotated[
        list[str],
        typer.Option(
            help="Leave out tag:ID, tag:ID@T0-T1 or time:T0-T1 (s from the survey start; repeat)."
        ),
    ] = [],  # noqa: B006
) -> None:
    """Build a tag map from a survey drive (a bag, or --sim) and print its QA report; with lidar
    sweeps (and no --no-lidar) also the premap and the occupancy grid beside --out."""
    from rich.progress import Progress

    from tagloc.fileutil import check_outputs
    from tagloc.io.survey_files import write_survey_outputs
    from tagloc.mapping import MapBuildConfig, MappingError, build_tag_map
    from tagloc.mapping.exclude import exclude_observations
    from tagloc.mapping.products import build_products
    from tagloc.sim.survey import sim_build_config, survey_and_anchors
    from tagloc.tags.tagmap import load_tag_map

    if sim == (bag is not None):
        raise MappingError("give exactly one of --bag PATH or --sim")
    if sim and anchors is not None:
        raise MappingError("--anchors is for --bag (with --sim, give --anchor ID: true poses)")
    if premap_format not in ("ply", "pcd", "pc2.lcm"):
        raise OptionError(f"--premap-format {premap_format!r}: expected ply, pcd or pc2.lcm")
    fmt = cast(Literal["ply", "pcd", "pc2.lcm"], premap_format)
    premap_path, grid_yaml, grid_pgm = product_paths(out, fmt)
    products = {} if no_lidar else {"premap": premap_path, "map.yaml": grid_yaml,
                                    "map.pgm": grid_pgm}  # fmt: skip
    check_outputs(
        {"--out": out, "--report": report, "--export-graph": export_graph, **products},
        inputs={"--bag": bag, "--world": world, "--cameras": cameras,
                "--camera-poses": camera_poses, "--tagslam": tagslam, "--anchors": anchors,
                "--config": config_file},
    )  # fmt: skip
    sizes = parse_tag_sizes(size)
    exclusions = [parse_exclusion(text) for text in exclude]
    known_anchors = {} if anchors is None else measured_anchors(load_tag_map(anchors))
    rounds: dict[str, object] = dict(parse_anchor_sigma(anchor_sigma))
    if calibrate_odometry is not None:
        rounds["calibration_rounds"] = calibrate_odometry
    if gravity is not None:
        rounds["odometry_frame"] = {"gravity_aligned": gravity}
    if uncertain_cm is not None:
        rounds["uncertainty_flag_m"] = uncertain_cm / 100.0
    with Progress(transient=True) as bar:
        task = bar.add_task("mapping", total=1.0)

        def progress(stage: str, done: int, total: int) -> None:
            bar.update(task, description=stage, completed=done / max(total, 1))

        T_map_anchor: Mapping[int, SE3 | Anchor]
        if sim:
            from tagloc.sim import ObservationConfig, load_default_world, load_world, simulate_drive

            sim_world = load_world(world) if world is not None else load_default_world()
            drive = simulate_drive(sim_world, seed=seed)
            observation_config = ObservationConfig(seed=seed)
            config = build_config(config_file, sim_build_config(drive, observation_config), rounds)
            survey, T_map_anchor = survey_and_anchors(
                drive, observation_config, anchor or None, camera_stride, lidar=not no_lidar
            )
        else:
            from tagloc.geometry import SE3

            if cameras is None:
                raise MappingError("--bag needs --cameras cameras.yaml")
            assert bag is not None
            survey, known = bag_survey(
                bag,
                cameras,
                camera_poses,
                tagslam,
                tag_topic,
                odom_topic,
                corner_order,
                tag_size,
                sizes,
                None if no_lidar else lidar_topic,
            )
            known.update(known_anchors)
            chosen = anchor or sorted(known)
            missing = [i for i in chosen if i not in known]
            if missing and len(chosen) > 1:
                raise MappingError(
                    f"--anchor {missing[0]}: no pose known (give --anchors or --tagslam)"
                )
            # one anchor without a known pose defines the map frame (identity pose)
            T_map_anchor = {i: known.get(i, SE3.identity()) for i in chosen}
            config = build_config(config_file, MapBuildConfig(), rounds)
        survey = exclude_observations(survey, exclusions)
        tag_map, qa = build_tag_map(survey, T_map_anchor, config, progress)
        built = None
        if survey.lidar is not None and not no_lidar:
            bar.update(task, description="premap and occupancy grid")
            built = build_products(survey, qa, lidar_config=config.lidar)
    files = {out: tag_map.to_yaml_text()}
    if report is not None:
        files[report] = qa.to_json() if report.suffix == ".json" else qa.to_markdown()
    if export_graph is not None:
        files[export_graph] = qa.graph_jsonl()
    if built is None:
        write_survey_outputs(files)  # all or none
    else:
        write_survey_outputs(files, (premap_path, built.premap_map, fmt), (grid_yaml, built.grid))
    typer.echo("\n".join(qa.summary_lines()))
    typer.echo(f"wrote {out} ({tag_map.summary()})")
    if built is not None:
        height, width = built.grid.shape
        typer.echo(
            f"wrote {premap_path} ({len(built.premap_map)} points from {built.scans} scans), "
            f"{grid_yaml} + {grid_pgm.name} ({width} x {height} cells of "
            f"{built.grid.resolution_m:g} m), in frame map"
        )
