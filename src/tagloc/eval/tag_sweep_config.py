"""The tag-sensor sweep's configuration: :class:`TagSweepConfig` and its pass/fail targets.

A sweep is every combination of ``distances_m x angles_deg x blur_px x noise_dn``, each cell
``trials`` seeded views of one tag (:mod:`tagloc.eval.tag_sweep`). The *reference condition*
is the sharpest, least noisy combination (``min(blur_px)``, ``min(noise_dn)``): the
accuracy targets are stated for it ("no blur").

The file form (``tagloc eval tags --config sweep.yaml``) is the model's fields as a YAML mapping;
unknown keys are errors, and every result directory gets the config it was run with
(``tag_sweep_config.yaml``).
"""

from __future__ import annotations

import math
import os
from typing import Any, Literal

import yaml
from pydantic import Field, ValidationInfo, field_validator

from tagloc.camera import PinholeRadtan
from tagloc.config import StrictModel, parse_yaml_mapping, read_text_file, validate
from tagloc.fileutil import atomic_write_text
from tagloc.sim.render_config import RenderConfig
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.gates import GateConfig

#: Per-coordinate corner noise (px) of each backend on the renderer's images of a 0.16 m tag at
#: 0.5-3 m, sharp, default sensor noise (measured with this sweep's views: AprilTag 3 with
#: ``quad_decimate=2``: 0.06-0.10 px, RMS Euclidean 0.10-0.15 px; ArUco ``subpix``: RMS
#: Euclidean 0.16-0.26 px). It grows with range and blur (the ``corner_rms_px`` column).
DEFAULT_SIGMA_PX = {"apriltag": 0.1, "aruco": 0.2}

#: The grid of ``tagloc eval tags --quick``: 1, 2 and 4 m at 0, 30 and 60 deg, sharp, default
#: sensor noise, and 2 tags face-on at 2 m, 4 views a cell (40 views, a few seconds).
QUICK_GRID: dict[str, Any] = {
    "distances_m": (1.0, 2.0, 4.0),
    "angles_deg": (0.0, 30.0, 60.0),
    "blur_px": (0.0,),
    "noise_dn": (1.5,),
    "joint_tag_counts": (2,),
    "joint_distances_m": (2.0,),
    "trials": 4,
}


class TagSweepTargets(StrictModel):
    """The targets, checked on a sweep result (:func:`tagloc.eval.tag_sweep.run_tag_sweep`).

    Accuracy targets apply to the reference condition; flips and NEES to the whole sweep.
    """

    position_median_2m_m: float = Field(0.01, gt=0, description="median at 2 m, every angle")
    position_median_4m_m: float = Field(0.03, gt=0, description="median at 4 m, every angle")
    rotation_median_2m_deg: float = Field(1.0, gt=0, description="median at 2 m, >= 15 deg")
    rotation_min_angle_deg: float = Field(15.0, ge=0, description="'off face-on' from here")
    max_flips: int = Field(0, ge=0, description="accepted ambiguity flips, whole sweep")
    nees_per_dof_band: tuple[float, float] = Field((0.5, 2.0), description="mean NEES / 6")
    acceptance_min: float = Field(0.9, ge=0, le=1, description="pooled acceptance of ...")
    acceptance_max_distance_m: float = Field(3.0, gt=0, description="... views within this")
    acceptance_angles_deg: tuple[float, float] = Field((15.0, 60.0), description="... and these")
    joint_rotation_median_deg: float = Field(1.0, gt=0, description="joint PnP, face-on ...")
    joint_rotation_distance_m: float = Field(2.0, gt=0, description="... at this distance")


class TagSweepConfig(StrictModel):
    """What a tag-sensor sweep renders, detects and scores.

    Grid
        ``distances_m`` (camera to tag center), ``angles_deg`` (tag normal against the line of
        sight, 0 = face-on), ``blur_px`` (Gaussian defocus sigma of the renderer, pixels) and
        ``noise_dn`` (Gaussian read noise, DN, on top of the renderer's shot noise); every
        combination is a cell of ``trials`` views.
    Views
        Each view is an upright tag on a vertical wall seen by a nearly level camera (the tag up
        to 25 deg off the optical axis, robot roll/pitch ``tilt_deg``): the geometry of the
        corner-level accuracy tests (``tests/tags/test_pnp.py``). The tag id is drawn at random.
        View ``k`` of a cell uses the stream ``SeedSequence([seed, cell..., k])``, so a cell's
        numbers do not depend on which other cells are swept.
    Camera and tag
        An undistorted pinhole ``image_width x image_height`` with horizontal field of view
        ``hfov_deg`` (square pixels, principal point at the center); ``tag_size_m``, ``family``.
        ``sensor_tag_size_m``: the size the sensor is told (default: ``tag_size_m``); another
        value shows what a tag printed at the wrong size, or a wrong size in the map, does.
    Sensor stack
        ``backend`` and ``detector_options`` (:func:`tagloc.tags.make_detector`), ``gates``,
        ``noise`` (None: ``NoiseModel(sigma_px=DEFAULT_SIGMA_PX[backend])``), and the
        orientation prior handed to the ambiguity policy: ``"rotation"`` (default: a predicted
        camera rotation off by ``prior_rotation_error_deg`` per axis with 1-sigma
        ``prior_sigma_deg``, plus gravity off by ``gravity_error_deg``: what the localizer's
        filter gives), ``"gravity"`` (gravity alone) or ``"none"``.
    Joint PnP
        ``joint_tag_counts`` x ``joint_distances_m``: rows of that many tags ``joint_spacing_m``
        apart seen face-on from that far (reference condition, ``trials`` views each;
        empty: none), :mod:`tagloc.eval.tag_sweep_joint`.
    Rendering
        ``render`` is the renderer's config; ``defocus_sigma_px`` and ``read_noise_dn`` are set
        per cell. ``background_albedo`` is the flat backdrop.
    """

    distances_m: tuple[float, ...] = (0.5, 1.0, 2.0, 3.0, 4.0, 6.0)
    angles_deg: tuple[float, ...] = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0)
    blur_px: tuple[float, ...] = (0.0, 1.5)
    noise_dn: tuple[float, ...] = (1.5, 8.0)
    trials: int = Field(12, ge=1, le=10_000)
    seed: int = Field(0, ge=0)
    image_width: int = Field(1280, ge=16)
    image_height: int = Field(720, ge=16)
    hfov_deg: float = Field(90.0, gt=1.0, lt=170.0)
    tag_size_m: float = Field(0.16, gt=0.0)
    sensor_tag_size_m: float | None = Field(None, gt=0.0)
    family: str = "tag36h11"
    backend: str = "apriltag"
    detector_options: dict[str, bool | int | float | str] = Field(default_factory=dict)
    gates: GateConfig = Field(default_factory=GateConfig)
    noise: NoiseModel | None = None
    prior: Literal["none", "gravity", "rotation"] = "rotation"
    prior_rotation_error_deg: float = Field(2.0, ge=0.0)
    prior_sigma_deg: float = Field(3.0, gt=0.0)
    gravity_error_deg: float = Field(1.0, ge=0.0)
    tilt_deg: float = Field(1.0, ge=0.0, le=10.0)
    joint_tag_counts: tuple[int, ...] = (2, 4)
    joint_distances_m: tuple[float, ...] = (1.0, 2.0, 3.0)
    joint_spacing_m: float = Field(0.3, gt=0.0, le=2.0)
    render: RenderConfig = Field(default_factory=RenderConfig)
    background_albedo: float = Field(0.5, ge=0.0, le=1.0)
    targets: TagSweepTargets = Field(default_factory=TagSweepTargets)

    @field_validator("distances_m", "angles_deg", "blur_px", "noise_dn")
    @classmethod
    def _grid_axis(cls, values: tuple[float, ...], info: ValidationInfo) -> tuple[float, ...]:
        limits = {
            "distances_m": (0.05, 100.0),
            "angles_deg": (0.0, 85.0),
            "blur_px": (0.0, 50.0),
            "noise_dn": (0.0, 255.0),
        }
        low, high = limits[str(info.field_name)]
        if not values:
            raise ValueError("needs at least one value")
        for v in values:
            if not (math.isfinite(v) and low <= v <= high):
                raise ValueError(f"value {v:g} outside [{low:g}, {high:g}]")
        if len(set(values)) != len(values):
            raise ValueError("values must be distinct")
        return tuple(sorted(values))

    @field_validator("joint_tag_counts", "joint_distances_m")
    @classmethod
    def _joint_axis(cls, values: tuple[float, ...], info: ValidationInfo) -> tuple[float, ...]:
        low, high = (2, 8) if info.field_name == "joint_tag_counts" else (0.3, 20.0)
        for v in values:
            if not low <= v <= high:
                raise ValueError(f"value {v:g} outside [{low:g}, {high:g}] (or leave it empty)")
        return tuple(sorted(set(values)))

    @property
    def reference_condition(self) -> tuple[float, float]:
        """``(blur_px, noise_dn)`` of the sharpest, least noisy cells."""
        return self.blur_px[0], self.noise_dn[0]

    def camera_model(self) -> PinholeRadtan:
        """The sweep's pinhole: ``fx = fy = (W / 2) / tan(hfov / 2)``, no distortion, principal
        point ``((W - 1) / 2, (H - 1) / 2)``."""
        f = 0.5 * self.image_width / math.tan(math.radians(self.hfov_deg) / 2.0)
        return PinholeRadtan(
            width=self.image_width,
            height=self.image_height,
            fx=f,
            fy=f,
            cx=(self.image_width - 1) / 2.0,
            cy=(self.image_height - 1) / 2.0,
        )

    def noise_model(self) -> NoiseModel:
        """``noise``, or the backend's measured corner noise (:data:`DEFAULT_SIGMA_PX`)."""
        if self.noise is not None:
            return self.noise
        return NoiseModel(sigma_px=DEFAULT_SIGMA_PX.get(self.backend, NoiseModel().sigma_px))


def load_tag_sweep_config(path: str | os.PathLike[str]) -> TagSweepConfig:
    """Read a sweep config YAML file (the model's fields; unknown keys are errors).

    Raises
    ------
    ConfigError
        One line ``file: field.path: problem``, or the file cannot be read.
    """
    source = str(path)
    text = read_text_file(path, "sweep config")
    return validate(TagSweepConfig, parse_yaml_mapping(text, source), source)


def save_tag_sweep_config(config: TagSweepConfig, path: str | os.PathLike[str]) -> None:
    """Write ``config`` as YAML (every field, defaults included), atomically."""
    data = config.model_dump(mode="json")
    atomic_write_text(path, yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
