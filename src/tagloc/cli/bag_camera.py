"""How a bag's camera is described on the command line, and its check before any fix.

Shared by ``tagloc localize`` and ``tagloc eval bag``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

if TYPE_CHECKING:
    from collections.abc import Collection

    from tagloc.camera import CameraModel
    from tagloc.geometry import SE3
    from tagloc.localize.node import NodeCamera, NodeTopics
    from tagloc.tags import TagMap

__all__ = ["BagCamera", "bag_camera", "bag_cameras", "check_bag_camera", "check_cameras"]

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
DetectionsTopicOpt = Annotated[
    str, typer.Option(help="Tag corners (localize: unless --cameras names tag topics).")
]
ImageTopicOpt = Annotated[str, typer.Option(help="Images.")]
CameraInfoTopicOpt = Annotated[str, typer.Option(help="CameraInfo.")]
TfTopicOpt = Annotated[str, typer.Option(help="Odometry as /tf (odom -> base).")]


@dataclass(frozen=True, slots=True)
class BagCamera:
    """How a bag's cameras are described: ``--cameras`` (Kalibr; ``localize`` takes every camera
    whose ``tagtopic`` is in the bag, else its first on ``--detections-topic``),
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
    """The first camera's model and ``T_base_cam`` the options give (None: from the bag)."""
    from tagloc.io import load_kalibr_cameras
    from tagloc.localize import LocalizeError

    if cam.cameras is None:
        if cam.camera_poses is not None:
            raise LocalizeError("--camera-poses needs --cameras (which camera it names)")
        return None, None
    name, camera = next(iter(load_kalibr_cameras(cam.cameras).items()))
    if cam.camera_poses is None:
        return camera, None
    return camera, _extrinsics(cam, [name])[name]


def bag_cameras(cam: BagCamera, bag_topics: Collection[str]) -> tuple[NodeCamera, ...]:
    """Every camera of ``--cameras`` whose ``tagtopic`` is in the bag, with its model and
    extrinsics (as ``map build`` reads them); empty when none is (then the first camera on
    ``--detections-topic``, :func:`bag_camera`).

    Raises
    ------
    LocalizeError
        Several cameras without ``--camera-poses``, or a camera without a pose in it.
    """
    from tagloc.cli.map_inputs import camera_tag_topics
    from tagloc.io import load_kalibr_cameras
    from tagloc.localize import LocalizeError
    from tagloc.localize.node import NodeCamera

    if cam.cameras is None:
        return ()
    models = load_kalibr_cameras(cam.cameras)
    topics = {c: t for t, c in camera_tag_topics(cam.cameras, []).items() if t in bag_topics}
    names = [n for n in models if n in topics]
    if not names:
        return ()
    if cam.camera_poses is None:
        if len(names) > 1:
            raise LocalizeError(f"{cam.cameras}: {len(names)} cameras with tag topics in the "
                                "bag: give --camera-poses (their extrinsics)")  # fmt: skip
        return (NodeCamera(names[0], topics[names[0]], models[names[0]]),)
    poses = _extrinsics(cam, names)
    return tuple(NodeCamera(n, topics[n], models[n], poses[n]) for n in names)


def _extrinsics(cam: BagCamera, names: list[str]) -> dict[str, SE3]:
    """``T_base_cam`` of each named camera: ``--camera-poses``'s ``T_body_cam``, moved into the
    odometry's child frame with ``--tagslam``'s ``T_body_odom``."""
    from tagloc.config import read_text_file
    from tagloc.localize import LocalizeError
    from tagloc.mapping.stream_survey import parse_camera_poses, parse_tagslam

    assert cam.camera_poses is not None
    poses = parse_camera_poses(
        read_text_file(cam.camera_poses, "camera poses"), str(cam.camera_poses)
    )
    missing = [n for n in names if n not in poses]
    if missing:
        raise LocalizeError(f"{cam.camera_poses}: no pose of camera {missing[0]!r}")
    T_body_odom = None
    if cam.tagslam is not None:
        rig = parse_tagslam(read_text_file(cam.tagslam, "tagslam configuration"), str(cam.tagslam))
        T_body_odom = rig.T_body_odom
    # the odometry's child frame is the node's base
    return {n: poses[n] if T_body_odom is None else T_body_odom.inverse() @ poses[n]
            for n in names}  # fmt: skip


def check_bag_camera(
    bag: Path, camera: CameraModel, T_base_cam: SE3 | None, tag_map: TagMap,
    topics: NodeTopics, corner_order: str, family: str, *, name: str = "",
) -> dict[str, object]:  # fmt: skip
    """Check the camera model against the bag's first frames (before any fix); refuse with one
    line naming what disagrees (and the camera, ``name``, of a rig)."""
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
            f"--cameras: the camera model{f' {name}' if name else ''} does not fit {bag.name}: "
            f"{found.problems[0]}; "
            "refusing before any fix"
        )
    return found.to_dict()


def check_cameras(
    bag: Path, rig: tuple[NodeCamera, ...], camera: CameraModel | None, T_base_cam: SE3 | None,
    tag_map: TagMap, roles: NodeTopics, corner_order: str, family: str,
) -> dict[str, object] | None:  # fmt: skip
    """Each camera's model against the bag's first frames (one line naming the camera that does
    not fit, before any fix): the one camera's result, or ``{camera: result}`` of a rig."""
    import dataclasses

    if not rig:
        return None if camera is None else check_bag_camera(
            bag, camera, T_base_cam, tag_map, roles, corner_order, family)  # fmt: skip
    out: dict[str, object] = {}
    for c in rig:
        assert c.camera is not None
        own = dataclasses.replace(roles, detections=c.detections_topic)
        out[c.name] = check_bag_camera(bag, c.camera, c.T_base_cam, tag_map, own, corner_order,
                                       family, name=c.name)  # fmt: skip
    return out
