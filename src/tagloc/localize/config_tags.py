"""``localizer.yaml``: the tag sensor's sections (``tags``, ``gates``) and the frames.

One set of gates serves the whole fix path: the per-observation limits (reprojection error,
range, viewing angle, decoder margin and Hamming distance, IPPE ambiguity, the prior's
chi-square) are applied by :func:`~tagloc.tags.observe_tags` before a fix exists, and the same
reprojection and range limits are checked again by the filter on each fix's quality (a fix from
another source, e.g. a joint solve or a future lidar source, meets the same bar). The filter's
own gates (chi-square quantile, k consistent fixes, gaps) sit beside them.

Units: pixels, metres, degrees where the name says so, seconds.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from tagloc.config import StrictModel, short_repr
from tagloc.localize.config_roi import RegionConfig
from tagloc.tags import GateConfig, NoiseModel
from tagloc.tags.families import known_families

__all__ = ["FramesConfig", "GatesConfig", "TagSensorConfig"]

#: Frame names of each naming convention: (map, odometry origin, base).
CONVENTIONS = {"ros": ("map", "odom", "base_link"), "dimos": ("map", "world", "base_link")}


class FramesConfig(StrictModel):
    """Frame names (configuration, never literals in the algorithm) and the published edge.

    ``convention: ros`` (default) publishes ``map -> odom`` (REP-105). ``convention: dimos``
    names the odometry origin ``world`` and publishes ``world -> map`` (the inverse edge, as
    dimos's relocalization does). A name given explicitly overrides the convention's.
    """

    convention: Literal["ros", "dimos"] = "ros"
    map_frame: str = Field("", max_length=200, description="default: the convention's (map)")
    odom_frame: str = Field("", max_length=200, description="default: the convention's (odom)")
    base_frame: str = Field("", max_length=200, description="default: the convention's")
    #: The published edge: ``map_to_odom`` (parent map, child odom) or ``odom_to_map``
    #: (parent odom, child map: the inverse transform). Default: the convention's.
    publish: Literal["map_to_odom", "odom_to_map", ""] = ""

    @model_validator(mode="after")
    def _fill(self) -> FramesConfig:
        names = CONVENTIONS[self.convention]
        for field, default in zip(("map_frame", "odom_frame", "base_frame"), names, strict=True):
            if not getattr(self, field):
                object.__setattr__(self, field, default)
        if not self.publish:
            edge = "odom_to_map" if self.convention == "dimos" else "map_to_odom"
            object.__setattr__(self, "publish", edge)
        return self

    @property
    def published_edge(self) -> tuple[str, str]:
        """``(parent, child)`` of the published transform."""
        if self.publish == "odom_to_map":
            return self.odom_frame, self.map_frame
        return self.map_frame, self.odom_frame


class GatesConfig(StrictModel, GateConfig):
    """One set of gates for observations and fixes (module docstring).

    The per-observation fields are the tag layer's :class:`~tagloc.tags.GateConfig` (inherited:
    one definition, one default each): ``max_reproj_err_px`` (2.0 px; checked again on every
    fix), ``max_range_m`` (8.0 m; also on fixes), ``max_view_angle_deg`` (75),
    ``min_decision_margin`` (20), ``max_hamming`` (1), ``ambiguity_log_odds`` (18.4),
    ``prior_gate_chi2`` (16.3).
    """

    #: IPPE ambiguity ratio above which a fix is refused (None: no limit; the chi-square gate
    #: already refuses a flipped branch once the state is known).
    max_ambiguity_ratio: float | None = Field(None, gt=0, le=1e6)
    #: Chi-square quantile of the filter's Mahalanobis gate (dof 6, or 3 in planar mode): a
    #: consistent fix is wrongly gated once in 1 / (1 - q) fixes.
    chi2_quantile: float = Field(0.999, gt=0, lt=1)
    #: Mutually consistent fixes required at start-up and after a gap before any is applied.
    k_consistent: int = Field(3, ge=1, le=100_000)
    #: The k fixes must lie within this window, s.
    consistency_window_s: float = Field(3.0, gt=0, le=1e6)
    #: A gap (re-acquisition needs k consistent fixes again): no accepted fix for this long, s,
    gap_s: float = Field(10.0, gt=0, le=1e6)
    #: ... or over this much travel, m.
    gap_m: float = Field(5.0, gt=0, le=1e6)

    def observation_gates(self) -> GateConfig:
        """The per-observation part, as the tag layer takes it."""
        return GateConfig(**self.model_dump(include=set(GateConfig.model_fields)))


class TagSensorConfig(StrictModel):
    """The tag sensor: detector, PnP mode, pixel noise and how fixes are formed.

    ``noise`` is the corner noise model (:class:`~tagloc.tags.NoiseModel`; ``sigma_px`` is
    the one number to calibrate on your detector). The rest are the fix source's tunables
    (:class:`~tagloc.localize.fiducial.FiducialConfig` documents each and how it was set).
    """

    #: Detector backend for images (``apriltag``: the AprilTag 3 library; ``aruco``: OpenCV).
    backend: Literal["apriltag", "aruco"] = "apriltag"
    family: str = Field("tag36h11", min_length=1, max_length=64)

    @field_validator("family")
    @classmethod
    def _known_family(cls, family: str) -> str:
        if family not in known_families():
            raise ValueError(f"unknown tag family {short_repr(family)}; known: {known_families()}")
        return family

    #: One fix per tag (``single``) or one joint PnP fix per frame over >= 2 tags (``joint``).
    mode: Literal["single", "joint"] = "single"
    noise: NoiseModel = NoiseModel()
    #: Every fix covariance is multiplied by this.
    cov_scale: float = Field(1.0, gt=0, le=1e6)
    #: Floor on each translation (m) and rotation (rad) standard deviation of a fix.
    min_cov_translation_m: float = Field(0.005, ge=0, le=1e3)
    min_cov_rotation_rad: float = Field(0.002, ge=0, le=4)
    #: 1-sigma of the filter's orientation handed to the ambiguity policy, rad.
    prior_rotation_sigma_rad: float = Field(0.05, gt=0, le=4)
    #: The ambiguity evidence threshold while the filter has an estimate (None: the gates').
    ambiguity_log_odds_with_prior: float | None = Field(9.2, ge=0, le=1e6)
    #: Two detections whose corners all lie within this distance (px) are one quad.
    shared_quad_px: float = Field(3.0, ge=0, le=1e4)
    #: Detection in the regions where mapped tags are predicted (``docs/detection.md``).
    roi: RegionConfig = RegionConfig()
