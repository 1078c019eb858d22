"""The pose records of the stream: odometry, transform-tree edges, pose estimates and ground
truth (conventions in :mod:`tagloc.messages`)."""

from __future__ import annotations

from dataclasses import dataclass

from tagloc._types import FloatArray
from tagloc.errors import RecordError
from tagloc.geometry import SE3
from tagloc.messages._checks import _array, _check_stamp_frame, _frame, _pose, _set, _stamp

__all__ = ["GroundTruthMsg", "OdometryMsg", "PoseWithCovarianceMsg", "TransformMsg"]


@dataclass(frozen=True, slots=True, eq=False)
class OdometryMsg:
    """Odometry of ``child_frame_id`` in ``frame_id`` (ROS ``nav_msgs/Odometry``).

    Attributes
    ----------
    frame_id : str
        The odometry origin (REP-105 ``odom``).
    child_frame_id : str
        The moving body (``base_link``).
    T_parent_child : SE3
        Pose of the child in the parent frame (``T_odom_base``).
    cov : (6, 6) float64, read-only
        Covariance of ``T_parent_child`` in its body tangent, ``[x, y, z, rx, ry, rz]``.
    twist : (6,) float64, read-only, or None
        ``[vx, vy, vz, wx, wy, wz]`` in ``child_frame_id`` (as ROS), m/s and rad/s; None when
        the source has none (written as zeros).
    """

    stamp_ns: int
    frame_id: str
    child_frame_id: str
    T_parent_child: SE3
    cov: FloatArray
    twist: FloatArray | None = None

    def __post_init__(self) -> None:
        _check_stamp_frame(self)
        _set(self, "child_frame_id", _frame(self, "child_frame_id"))
        _set(self, "T_parent_child", _pose(self, "T_parent_child"))
        _set(self, "cov", _array(self, "cov", (6, 6)))
        if self.twist is not None:
            _set(self, "twist", _array(self, "twist", (6,)))


@dataclass(frozen=True, slots=True, eq=False)
class TransformMsg:
    """One edge of the transform tree (one ``TransformStamped`` of a ``/tf`` message).

    Attributes
    ----------
    parent, child : str
        Non-empty frame names.
    T_parent_child : SE3
    static : bool
        True for ``/tf_static`` edges (valid at every time).
    """

    stamp_ns: int
    parent: str
    child: str
    T_parent_child: SE3
    static: bool = False

    def __post_init__(self) -> None:
        _set(self, "stamp_ns", _stamp(self))
        for name in ("parent", "child"):
            if not _frame(self, name):
                raise RecordError(f"TransformMsg.{name}: must be a non-empty frame name")
        _set(self, "T_parent_child", _pose(self, "T_parent_child"))
        _set(self, "static", bool(self.static))


@dataclass(frozen=True, slots=True, eq=False)
class PoseWithCovarianceMsg:
    """A pose estimate with covariance (ROS ``geometry_msgs/PoseWithCovarianceStamped``).

    Attributes
    ----------
    frame_id : str
        The frame the pose is expressed in (``map``).
    T_frame_child : SE3
        The pose of the estimated body (``T_map_base``).
    cov : (6, 6) float64, read-only
        Body-tangent covariance, ``[x, y, z, rx, ry, rz]``.
    """

    stamp_ns: int
    frame_id: str
    T_frame_child: SE3
    cov: FloatArray

    def __post_init__(self) -> None:
        _check_stamp_frame(self)
        _set(self, "T_frame_child", _pose(self, "T_frame_child"))
        _set(self, "cov", _array(self, "cov", (6, 6)))


@dataclass(frozen=True, slots=True, eq=False)
class GroundTruthMsg:
    """The true pose of the robot (simulator truth; ROS ``geometry_msgs/PoseStamped``).

    Attributes
    ----------
    frame_id : str
        The frame the truth is expressed in (``map``).
    T_frame_child : SE3
        True pose of the body (``T_map_base``).
    """

    stamp_ns: int
    frame_id: str
    T_frame_child: SE3

    def __post_init__(self) -> None:
        _check_stamp_frame(self)
        _set(self, "T_frame_child", _pose(self, "T_frame_child"))
