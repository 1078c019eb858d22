"""``localizer.yaml``: ``lidar``: the lidar (scan to premap) fix source of the node.

Each sweep on the lidar topic (``NodeTopics.lidar``) is de-skewed with the odometry, registered
against the premap (the point cloud map the node is started with, ``tagloc localize --premap``)
from the estimate's prediction, and applied to the filter as a fix that measures only the
directions the scan constrains (:mod:`tagloc.localize.projected_update`). Without a premap the
lidar topic is ignored. Units: metres, seconds, hertz.
"""

from __future__ import annotations

from pydantic import Field

from tagloc.config import StrictModel
from tagloc.lidar.fix import LidarFixConfig

__all__ = ["LidarConfig"]


class LidarConfig(StrictModel):
    """The lidar fix source (module docstring)."""

    #: Use the lidar when a premap is given (``false``: scans are ignored, as without a premap).
    enabled: bool = True
    #: The scanner's frame: a cloud in another frame is skipped (``lidar_wrong_frame``); its
    #: mount is the static ``base -> frame_id`` transform of the stream (``/tf_static``).
    frame_id: str = Field("lidar", min_length=1, max_length=200)
    #: Sweeps registered per second at most (stream time); the others are thinned out (a
    #: registration costs tens of milliseconds; the liveness check still sees every sweep).
    max_rate_hz: float = Field(5.0, gt=0, le=1000)
    #: A sweep whose start is older than this when the odometry covers its end is skipped
    #: (``lidar_stale``): its fix would come too late to help.
    max_scan_age_s: float = Field(1.0, gt=0, le=3600)
    #: Inside the elevator cab the walls move with the robot: after a camera frame whose
    #: newest known tag belongs to ``cab_frame``, sweeps are skipped (``in_cab``) until a frame
    #: sees a tag of the map frame again.
    ignore_in_cab: bool = True
    cab_frame: str = Field("elevator_cab", min_length=1, max_length=200)
    #: Floor of a fix's covariance along its measured directions (1-sigma, m and rad): the
    #: registration's covariance (Hessian from thousands of points) shrinks below the
    #: errors that do not average out over points (the premap's surfaces, de-skew, the
    #: mount); the isotropic floor ``diag(min_sigma_m^2 I3, min_sigma_rad^2 I3)`` projected
    #: on the measured directions is added to it. Calibrated with the NEES of the fixes
    #: against the simulator's truth (README, the node section).
    min_sigma_m: float = Field(0.004, ge=0, le=10)
    min_sigma_rad: float = Field(0.002, ge=0, le=1)
    #: Registration, acceptance and degeneracy of one fix (:mod:`tagloc.lidar.fix`).
    fix: LidarFixConfig = LidarFixConfig()
