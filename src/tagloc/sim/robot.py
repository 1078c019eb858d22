"""The simulated robot (world-file models): odometry, camera intrinsics, distortion, mounting.

The camera mount gives ``T_base_cam`` of the OpenCV optical frame (x right, y down, z forward).
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from tagloc.camera import CameraModel, PinholeEquidistant, PinholeRadtan
from tagloc.config import FieldPathError, StrictModel, check_unit_quat
from tagloc.geometry import SE3, SO3
from tagloc.sim.odometry import OdometryConfig

#: A mounting offset on the robot, metres.
Offset = Annotated[float, Field(ge=-10.0, le=10.0)]
Vec3 = tuple[Offset, Offset, Offset]
Angle3 = tuple[
    Annotated[float, Field(ge=-360.0, le=360.0)],
    Annotated[float, Field(ge=-360.0, le=360.0)],
    Annotated[float, Field(ge=-360.0, le=360.0)],
]
#: Camera body (x forward, y left, z up) to OpenCV optical frame (x right, y down, z forward).
R_BODY_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


class Intrinsics(StrictModel):
    """Pinhole intrinsics in pixels (OpenCV: centre of the top-left pixel at (0, 0))."""

    fx: float = Field(ge=1.0, le=1e5)
    fy: float = Field(ge=1.0, le=1e5)
    cx: float
    cy: float
    width: int = Field(gt=0, le=20000)
    height: int = Field(gt=0, le=20000)

    @model_validator(mode="after")
    def _centre_inside(self) -> Intrinsics:
        if not (0 <= self.cx <= self.width and 0 <= self.cy <= self.height):
            raise FieldPathError(
                ("cx",),
                f"principal point ({self.cx}, {self.cy}) lies outside "
                f"the {self.width}x{self.height} image",
            )
        return self


class Distortion(StrictModel):
    """Lens distortion: ``none``; ``radtan`` (OpenCV k1 k2 p1 p2 [k3]); ``equidistant``
    (OpenCV fisheye k1..k4)."""

    model: Literal["none", "radtan", "equidistant"] = "none"
    coefficients: tuple[Annotated[float, Field(ge=-1e3, le=1e3)], ...] = Field(
        default=(), max_length=5
    )

    @model_validator(mode="after")
    def _count(self) -> Distortion:
        allowed = {"none": (0,), "radtan": (4, 5), "equidistant": (4,)}[self.model]
        if len(self.coefficients) not in allowed:
            raise FieldPathError(
                ("coefficients",),
                f"model {self.model} takes "
                f"{' or '.join(map(str, allowed))} coefficients, "
                f"got {len(self.coefficients)}",
            )
        return self


class CameraMount(StrictModel):
    """``T_base_cam``: ``position`` (m, in ``base``) and either ``quat_xyzw`` of the optical frame
    or ``rpy_deg``: roll, pitch, yaw of the camera *body* frame (x forward, y left, z up) in
    ``base``, ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (positive pitch looks down, REP-103), after which
    the optical frame is ``R @ R_BODY_OPTICAL``; ``[0, 0, 0]`` is level and forward-looking."""

    position: Vec3
    quat_xyzw: tuple[float, float, float, float] | None = None
    rpy_deg: Angle3 | None = None

    @field_validator("quat_xyzw")
    @classmethod
    def _check_quat(
        cls, value: tuple[float, float, float, float] | None
    ) -> tuple[float, float, float, float] | None:
        return value if value is None else check_unit_quat(value)

    @model_validator(mode="after")
    def _one_rotation(self) -> CameraMount:
        if (self.quat_xyzw is None) == (self.rpy_deg is None):
            raise ValueError("give exactly one of 'quat_xyzw' or 'rpy_deg'")
        return self

    def T_base_cam(self) -> SE3:
        """Pose of the optical frame ``cam`` in ``base``."""
        if self.quat_xyzw is not None:
            return SE3.from_quat(self.quat_xyzw, self.position)
        assert self.rpy_deg is not None
        R_base_body = SO3.from_euler("xyz", self.rpy_deg, degrees=True).as_matrix()
        return SE3(
            rotation=SO3.from_matrix(R_base_body @ R_BODY_OPTICAL),
            translation=np.array(self.position),
        )


class Camera(StrictModel):
    """A camera on the robot: intrinsics, distortion, frame rate and mounting."""

    intrinsics: Intrinsics
    distortion: Distortion = Distortion()
    rate_hz: float = Field(gt=0.0, le=1000.0)
    T_base_cam: CameraMount

    def camera_model(self) -> CameraModel:
        """This camera as a :mod:`tagloc.camera` model (project, undistort, rays)."""
        i, coeffs = self.intrinsics, self.distortion.coefficients
        if self.distortion.model == "equidistant":
            k1, k2, k3, k4 = coeffs
            return PinholeEquidistant(
                width=i.width,
                height=i.height,
                fx=i.fx,
                fy=i.fy,
                cx=i.cx,
                cy=i.cy,
                k1=k1,
                k2=k2,
                k3=k3,
                k4=k4,
            )
        k1, k2, p1, p2, k3 = (*coeffs, 0.0)[:5] if coeffs else (0.0,) * 5
        return PinholeRadtan(
            width=i.width,
            height=i.height,
            fx=i.fx,
            fy=i.fy,
            cx=i.cx,
            cy=i.cy,
            k1=k1,
            k2=k2,
            p1=p1,
            p2=p2,
            k3=k3,
        )

    def K(self) -> np.ndarray:
        """The 3x3 camera matrix."""
        i = self.intrinsics
        return np.array([[i.fx, 0.0, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]])


class Robot(StrictModel):
    """The robot: odometry drift model, camera, odometry rate (Hz) and body height (m).

    ``base`` stays on the floor (z = 0 in ``map``); ``base_height`` is the height of the body above
    the floor, for renderers and sensors that need it.
    """

    odometry: OdometryConfig
    camera: Camera
    odom_rate_hz: float = Field(gt=0.0, le=2000.0)
    base_height: float = Field(default=0.3, ge=0.0, le=5.0)
