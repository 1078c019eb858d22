"""How a bag's camera is described on the command line, and its check before any fix.

Shared by ``tagloc localize`` and ``tagloc eval bag``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

if TYPE_CHECKING:
    from tagloc.camera import CameraModel
    from tagloc.geometry import SE3
    from tagloc.localize.node import NodeTopics
    from tagloc.tags import TagMap

__all__ = ["BagCamera", "bag_camera", "check_bag_camera"]

# The options both commands take, one definition each (parameter names give the option names).
CamerasOpt = Annotated[Path | None, typer.Option(help="Kalibr camchain yaml.")]
CameraPosesOpt = Annotated[
    Path | None, typer.Option(help="camera_poses.yaml: T_body_cam (with --cameras).")
]
TagslamOpt = Annotated[
    Path | None, typer.Option(help="tagslam.yaml: T_body_odom (odometry child in body).")
]
CornerOrderOpt = Annotated[str, typer.Option(help="How the bag lists corners, e.g. bl_br_tr_tl.")]
OdomTopicOpt = Annotated[str, typer.Option(help="Odometry.")]
DetectionsTopicOpt = Annotated[str, typer.Option(help="Tag corners.")]
ImageTopicOpt = Annotated[str, typer.Option(help="Images.")]
CameraInfoTopicOpt = Annotated[str, typer.Option(help="CameraInfo.")]
TfTopicOpt = Annotated[str, typer.Option(help="Odometry as /tf (odom -> base).")]


@dataclass(frozen=True, slots=True)
class BagCamera:
    """How a bag's camera is described: ``--cameras`` (Kalibr; its first camera),
    ``--camera-poses`` (``T_body_cam``), ``--tagslam`` (``T_body_odom``: the odometry's child
    frame in the body) and how the bag lists a tag's corners."""

    cameras: Path | None = None
    camera_poses: Path | None = None
    tagslam: Path | None = None
    corner_order: str = "tl_tr_br_bl"

    def inputs(self) -> dict[str, Path | None]:
        return {"--cameras": self.cameras, "--camera-poses": self.camera_poses,
                "--tagslam": self.tagslam}  # fmt: skip


def bag_camera(cam: BagCamera) -> tuple[CameraModel | None, SE3 | None]:
    """The camera model and ``T_base_cam`` the options give (None: from the bag)."""
    from tagloc.config import read_text_file
    from tagloc.io import load_kalibr_cameras
    from tagloc.localize import LocalizeError
    from tagloc.mapping.stream_survey import parse_camera_poses, parse_tagslam

    if cam.cameras is None:
        if cam.camera_poses is not None:
            raise LocalizeError("--camera-poses needs --cameras (which camera it names)")
        return None, None
    name, camera = next(iter(load_kalibr_cameras(cam.cameras).items()))
    if cam.camera_poses is None:
        return camera, None
    poses = parse_camera_poses(
        read_text_file(cam.camera_poses, "camera poses"), str(cam.camera_poses)
    )
    if name not in poses:
        raise LocalizeError(f"{cam.camera_poses}: no pose of camera {name!r} (--cameras's first)")
    T_base_cam = poses[name]
    if cam.tagslam is not None:
        rig = parse_tagslam(read_text_file(cam.tagslam, "tagslam configuration"), str(cam.tagslam))
        if rig.T_body_odom is not None:  # the odometry's child frame is the node's base
            T_base_cam = rig.T_body_odom.inverse() @ T_base_cam
    return camera, T_base_cam


def check_bag_camera(
    bag: Path, camera: CameraModel, T_base_cam: SE3 | None, tag_map: TagMap,
    topics: NodeTopics, corner_order: str, family: str,
) -> dict[str, object]:  # fmt: skip
    """Check the camera model against the bag's first frames (before any fix); refuse with one
    line naming what disagrees."""
    from tagloc.io import BagSource
    from tagloc.localize import LocalizeError
    from tagloc.localize.intrinsic_check import check_camera

    wanted = [topics.odom, topics.detections, topics.camera_info, topics.image]
    source = BagSource(bag, corner_order=corner_order, default_family=family)
    wanted += [t for t in source.bag_topics if t.rstrip("/").endswith("tf_static")]
    source = BagSource(bag, sorted({t for t in wanted if t in source.bag_topics}),
                       corner_order=corner_order, default_family=family)  # fmt: skip
    found = check_camera(
        source, camera, tag_map, detections_topic=topics.detections, odom_topic=topics.odom,
        T_base_cam=T_base_cam, camera_info_topic=topics.camera_info, image_topic=topics.image,
        family=family,
    )  # fmt: skip
    if found.problems:
        raise LocalizeError(
            f"--cameras: the camera model does not fit {bag.name}: {found.problems[0]}; "
            "refusing before any fix"
        )
    return found.to_dict()
