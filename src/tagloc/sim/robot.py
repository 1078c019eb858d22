"""The simulated robot (world-file models): odometry, camera intrinsics, distortion, mounting,
and an optional lidar.

The camera mount gives ``T_base_cam`` of the OpenCV optical frame (x right, y down, z forward);
the lidar mount ``T_base_lidar`` of the scanner frame ``lidar`` (x forward, y left, z up).
"""

from __future__ import annotations

import math
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
    """The world file's ``intrinsics`` section: pinhole intrinsics in pixels (OpenCV: centre of
    the top-left pixel at (0, 0)). Only the file's fields: the camera they describe is
    :meth:`Camera.camera_model`, a :mod:`tagloc.camera` model."""

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


class Mount(StrictModel):
    """A sensor's pose on the robot: ``position`` (m, in ``base``) and either ``quat_xyzw`` or
    ``rpy_deg`` (roll, pitch, yaw in ``base``, ``R = Rz(yaw) Ry(pitch) Rx(roll)``, degrees)."""

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
    def _one_rotation(self) -> Mount:
        if (self.quat_xyzw is None) == (self.rpy_deg is None):
            raise ValueError("give exactly one of 'quat_xyzw' or 'rpy_deg'")
        return self

    def _pose(self, R_body_frame: np.ndarray) -> SE3:
        """The mounted frame in ``base``: ``quat_xyzw`` as given, or the ``rpy_deg`` body
        rotation followed by ``R_body_frame`` (the sensor's own axis convention)."""
        if self.quat_xyzw is not None:
            return SE3.from_quat(self.quat_xyzw, self.position)
        assert self.rpy_deg is not None
        R_base_body = SO3.from_euler("xyz", self.rpy_deg, degrees=True).as_matrix()
        return SE3(
            rotation=SO3.from_matrix(R_base_body @ R_body_frame),
            translation=np.array(self.position),
        )


class CameraMount(Mount):
    """``T_base_cam``: ``position`` (m, in ``base``) and either ``quat_xyzw`` of the optical frame
    or ``rpy_deg``: roll, pitch, yaw of the camera *body* frame (x forward, y left, z up) in
    ``base``, ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (positive pitch looks down, REP-103), after which
    the optical frame is ``R @ R_BODY_OPTICAL``; ``[0, 0, 0]`` is level and forward-looking."""

    def T_base_cam(self) -> SE3:
        """Pose of the optical frame ``cam`` in ``base``."""
        return self._pose(R_BODY_OPTICAL)


class Camera(StrictModel):
    """The world file's camera on the robot: intrinsics, distortion, frame rate and mounting.

    The camera itself (camera matrix, projection, undistortion) is the :mod:`tagloc.camera`
    model :meth:`camera_model` builds from the file's sections.
    """

    intrinsics: Intrinsics
    distortion: Distortion = Distortion()
    rate_hz: float = Field(gt=0.0, le=1000.0)
    T_base_cam: CameraMount

    def camera_model(self) -> CameraModel:
        """This camera as a :mod:`tagloc.camera` model (``K``, project, undistort, rays)."""
        pinhole = self.intrinsics.model_dump()  # width, height, fx, fy, cx, cy
        coeffs = self.distortion.coefficients
        if self.distortion.model == "equidistant":
            k1, k2, k3, k4 = coeffs
            return PinholeEquidistant(**pinhole, k1=k1, k2=k2, k3=k3, k4=k4)
        k1, k2, p1, p2, k3 = (*coeffs, 0.0)[:5] if coeffs else (0.0,) * 5
        return PinholeRadtan(**pinhole, k1=k1, k2=k2, p1=p1, p2=p2, k3=k3)


class LidarMount(Mount):
    """``T_base_lidar``: ``position`` (m, in ``base``) and either ``quat_xyzw`` or ``rpy_deg``
    (roll, pitch, yaw of the scanner frame in ``base``, ``R = Rz(yaw) Ry(pitch) Rx(roll)``) of
    the scanner frame ``lidar`` (x forward, y left, z up; no optical convention)."""

    def T_base_lidar(self) -> SE3:
        """Pose of the scanner frame ``lidar`` in ``base``."""
        return self._pose(np.eye(3))


class LidarConfig(StrictModel):
    """A spinning multi-ring 3D scanner (the simulator's lidar; :mod:`tagloc.sim.lidar`).

    ``rings`` beams at elevations evenly spread over ``vertical_fov_deg = [low, high]`` (degrees
    above the scanner's xy plane; one ring needs ``low == high``: ``rings: 1`` with ``[0, 0]`` is a
    2D scanner), fired at ``columns`` azimuths evenly spread over ``horizontal_fov_deg`` centred
    on the scanner's x axis, column by column, counter-clockwise (from the right to the left)
    once per sweep at ``rate_hz``. A return between ``min_range_m`` and ``max_range_m`` gets
    Gaussian range noise ``range_sigma_m``. Glass lets beams through; with
    ``glass_return_probability`` > 0 a beam reaching glass returns from it with that probability
    (a weak return). Mirrors reflect beams specularly up to ``max_bounces`` times (a beam
    reflected more often is lost). ``seed`` seeds the noise (sweep ``k`` draws from
    ``(seed, k)``).

    The defaults are a Livox Mid-360's geometry (-7 to 52 degrees, 360 degrees, 10 Hz,
    0.1-40 m, 2 cm) with far fewer points: 16 rings x 360 columns = 5 760 beams per sweep
    (the Mid-360 measures 20 000), so a 10-minute drive simulates in well under a minute.
    """

    T_base_lidar: LidarMount
    rings: int = Field(default=16, ge=1, le=256)
    vertical_fov_deg: tuple[
        Annotated[float, Field(ge=-89.0, le=89.0)], Annotated[float, Field(ge=-89.0, le=89.0)]
    ] = (-7.0, 52.0)
    horizontal_fov_deg: float = Field(default=360.0, gt=0.0, le=360.0)
    columns: int = Field(default=360, ge=1, le=20000)
    rate_hz: float = Field(default=10.0, gt=0.0, le=100.0)
    min_range_m: float = Field(default=0.1, ge=0.0)
    max_range_m: float = Field(default=40.0, gt=0.0, le=1000.0)
    range_sigma_m: float = Field(default=0.02, ge=0.0, le=1.0)
    glass_return_probability: float = Field(default=0.0, ge=0.0, le=1.0)
    max_bounces: int = Field(default=1, ge=0, le=2)
    seed: int = Field(default=0, ge=0)

    @model_validator(mode="after")
    def _check(self) -> LidarConfig:
        low, high = self.vertical_fov_deg
        if low > high:
            raise FieldPathError(("vertical_fov_deg",), f"low {low} is above high {high}")
        if self.rings == 1 and low != high:
            raise FieldPathError(
                ("vertical_fov_deg",),
                f"one ring needs low == high (e.g. [0, 0]), got {low}, {high}",
            )
        if self.rings > 1 and low == high:
            raise FieldPathError(("vertical_fov_deg",), f"{self.rings} rings need low < high")
        if self.min_range_m >= self.max_range_m:
            raise FieldPathError(("min_range_m",), "must be below max_range_m")
        if self.rings * self.columns > 2_000_000:
            raise FieldPathError(("columns",), "rings x columns exceeds 2 000 000 beams per sweep")
        return self

    def elevations_rad(self) -> np.ndarray:
        """``(rings,)`` beam elevations above the scanner's xy plane, radians, low to high."""
        low, high = np.radians(self.vertical_fov_deg)
        return np.linspace(low, high, self.rings)

    def azimuths_rad(self) -> np.ndarray:
        """``(columns,)`` azimuths about the scanner's z axis (0 = x, counter-clockwise), in
        firing order; a full circle does not repeat its first azimuth."""
        fov = math.radians(self.horizontal_fov_deg)
        if self.horizontal_fov_deg >= 360.0:
            return -math.pi + fov * np.arange(self.columns) / self.columns
        if self.columns == 1:
            return np.zeros(1)
        return np.linspace(-fov / 2, fov / 2, self.columns)

    def period_s(self) -> float:
        """One sweep (one turn of the scanner), seconds."""
        return 1.0 / self.rate_hz

    def column_offsets_s(self) -> np.ndarray:
        """``(columns,)`` firing time of each column after the sweep start, seconds: the scanner
        turns at a constant rate, so a column fires when the turn reaches its azimuth."""
        turn = (self.azimuths_rad() - self.azimuths_rad()[0]) / (2 * math.pi)
        return np.asarray(turn * self.period_s(), dtype=np.float64)


class Robot(StrictModel):
    """The robot: odometry drift model, camera, odometry rate (Hz), body height (m) and an
    optional lidar (None: the robot has none).

    ``base`` stays on the floor (z = 0 in ``map``); ``base_height`` is the height of the body above
    the floor, for renderers and sensors that need it.
    """

    odometry: OdometryConfig
    camera: Camera
    odom_rate_hz: float = Field(gt=0.0, le=2000.0)
    base_height: float = Field(default=0.3, ge=0.0, le=5.0)
    lidar: LidarConfig | None = None
