"""Views of the tag-sensor sweep: one tag on a wall, a face-on row of tags, the camera's prior.

Both kinds of view put a nearly level camera (roll and pitch ``N(0, tilt_deg)``) in a z-up map
and return exact poses; the sweep renders them (:mod:`tagloc.eval.tag_sweep`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tagloc.camera import CameraModel
from tagloc.eval.tag_sweep_config import TagSweepConfig
from tagloc.geometry import SE3, SO3
from tagloc.tags import NoiseModel, PosePrior, TagDetector, family_spec, make_detector

#: Map up in a level camera's optical frame; optical axes of a level camera in a z-up map
#: (x right = map x, y down = -map z, z forward = map y).
_UP_LEVEL_CAM = np.array([0.0, -1.0, 0.0])
_R_MAP_LEVEL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_E_Z = np.array([0.0, 0.0, 1.0])


def rotation_error_deg(T_true: SE3, T_est: SE3) -> float:
    """Angle of ``R_true^T R_est``, degrees."""
    return float(np.rad2deg(np.linalg.norm((T_true.inverse() @ T_est).rotation.log())))


def _tilt(rng: np.random.Generator, tilt_deg: float) -> SO3:
    """``R_cam_level``: roll and pitch ``N(0, tilt_deg)`` (no yaw)."""
    return SO3.from_rotvec(np.deg2rad(tilt_deg) * rng.normal(size=3) * np.array([1.0, 0.0, 1.0]))


def sample_wall_view(
    distance_m: float, angle_rad: float, rng: np.random.Generator, tilt_deg: float = 1.0
) -> tuple[SE3, SE3]:
    """An upright tag on a vertical wall seen by a nearly level camera at the map origin.

    The tag center is ``distance_m`` away along a ray up to 25 deg off-axis horizontally and up
    to ``min(15 deg, angle)`` vertically; the tag normal is horizontal and makes ``angle_rad``
    with the ray to the camera (to either side); the camera is rolled and pitched by
    ``N(0, tilt_deg)`` each. The same draws, in the same order, as the corner-level tests'
    ``wall_view`` (``tests/tags/test_pnp.py``), so both see the same views for the same seed.

    Parameters
    ----------
    distance_m : float
    angle_rad : float
        Viewing angle, ``[0, pi/2)``.
    rng : numpy.random.Generator
    tilt_deg : float

    Returns
    -------
    T_cam_tag, T_map_cam : SE3
        The map has z up; ``T_map_tag = T_map_cam @ T_cam_tag`` has its y axis up.
    """
    el = np.deg2rad(rng.uniform(-1.0, 1.0) * min(15.0, np.rad2deg(angle_rad)))
    az = np.deg2rad(rng.uniform(-25.0, 25.0))
    ray = np.array([np.sin(az) * np.cos(el), -np.sin(el), np.cos(az) * np.cos(el)])
    psi = np.arccos(np.clip(np.cos(angle_rad) / np.cos(el), -1.0, 1.0)) * rng.choice([-1, 1])
    h = -np.array([ray[0], 0.0, ray[2]]) / np.hypot(ray[0], ray[2])
    c, s = np.cos(psi), np.sin(psi)
    normal = np.array([c * h[0] + s * h[2], 0.0, -s * h[0] + c * h[2]])
    R_level_tag = np.stack([np.cross(_UP_LEVEL_CAM, normal), _UP_LEVEL_CAM, normal], axis=1)
    R_cam_level = _tilt(rng, tilt_deg).matrix
    T_cam_tag = SE3(
        rotation=SO3.from_matrix(R_cam_level @ R_level_tag),
        translation=R_cam_level @ (distance_m * ray),
    )
    T_map_cam = SE3(rotation=SO3.from_matrix(_R_MAP_LEVEL @ R_cam_level.T), translation=np.zeros(3))
    return T_cam_tag, T_map_cam


def sample_board_view(
    distance_m: float,
    n_tags: int,
    spacing_m: float,
    rng: np.random.Generator,
    tilt_deg: float = 1.0,
) -> tuple[list[SE3], SE3]:
    """``n_tags`` upright tags in a row on the wall ``y = distance_m``, seen face-on.

    Tag ``i`` is at ``x = (i - (n - 1) / 2) spacing``, alternately at the camera's height and
    ``spacing`` above it (not collinear), facing ``-y``; the camera is at ``x ~ U(-0.1, 0.1)``
    m, level up to ``N(0, tilt_deg)`` roll and pitch, and turned ``U(-3, 3)`` deg about the
    vertical: every tag is within a few degrees of face-on, where single tags are ambiguous.

    Returns
    -------
    T_map_tags : list of SE3
    T_map_cam : SE3
    """
    R_map_tag = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # z = -y, y = z
    T_map_tags = [
        SE3(
            rotation=SO3.from_matrix(R_map_tag),
            translation=np.array([x, distance_m, spacing_m * (i % 2)]),
        )
        for i, x in enumerate((np.arange(n_tags) - (n_tags - 1) / 2) * spacing_m)
    ]
    yaw = SO3.from_rotvec([0.0, 0.0, np.deg2rad(rng.uniform(-3.0, 3.0))])
    R_map_cam = yaw.matrix @ _R_MAP_LEVEL @ _tilt(rng, tilt_deg).matrix.T
    T_map_cam = SE3(
        rotation=SO3.from_matrix(R_map_cam), translation=np.array([rng.uniform(-0.1, 0.1), 0, 0])
    )
    return T_map_tags, T_map_cam


def pose_prior(config: TagSweepConfig, T_map_cam: SE3, rng: np.random.Generator) -> PosePrior:
    """The orientation prior of ``config.prior`` for a camera truly at ``T_map_cam``.

    Gravity (the map's up in the camera) is measured through a rotation off by
    ``gravity_error_deg`` per axis; ``"rotation"`` adds a predicted ``T_map_cam`` off by
    ``prior_rotation_error_deg`` per axis; both with 1-sigma ``prior_sigma_deg``.
    """
    measured = T_map_cam.rotation @ SO3.from_rotvec(
        np.deg2rad(config.gravity_error_deg) * rng.normal(size=3)
    )
    up_cam = measured.inverse().act(_E_Z)
    predicted = None
    if config.prior == "rotation":
        turn = np.deg2rad(config.prior_rotation_error_deg) * rng.normal(size=3)
        predicted = T_map_cam.plus(np.r_[0.0, 0.0, 0.0, turn])
    sigma = np.deg2rad(config.prior_sigma_deg)
    return PosePrior(predicted, sigma, up_cam, sigma)


@dataclass(frozen=True, slots=True)
class SweepStack:
    """What every view of a sweep shares: camera, detector, noise model, id count."""

    config: TagSweepConfig
    camera: CameraModel
    detector: TagDetector
    noise: NoiseModel
    num_ids: int

    @classmethod
    def from_config(cls, config: TagSweepConfig) -> SweepStack:
        """Build it; raises ``TagBackendError`` for an unknown backend, family or option."""
        return cls(
            config,
            config.camera_model(),
            make_detector(config.backend, config.family, **config.detector_options),
            config.noise_model(),
            family_spec(config.family).num_ids,
        )
