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

__all__ = ["FiducialConfig", "FramesConfig", "GatesConfig", "TagSensorConfig"]

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


class FiducialConfig(StrictModel):
    """How the fiducial fix source forms fixes from accepted tags (``localizer.yaml``: the
    ``tags`` section's fix fields; :class:`TagSensorConfig` adds the detector and noise).

    Attributes
    ----------
    mode : {"single", "joint"}
        One fix per tag, or one joint PnP fix per frame over >= 2 map tags
        (:mod:`tagloc.localize.fiducial`).
    cov_scale : float
        Every fix covariance is multiplied by this (default 1: no inflation). Measured on the
        corner-level simulator with the noise model's ``sigma_px`` equal to the simulated pixel
        noise (0.3 px), the tag sensor's covariance is *conservative*: the normalized
        estimation error squared (NEES, 6 dof, expected 6) of the base pose averages 2.4-3 at
        every range from 1 to 8 m, mostly because the ambiguity mixture folds the other IPPE
        branch in. Shrinking it (0.5) let correlated errors of consecutive far frames pull the
        estimate, inflating it (2-5) changed the ATE by < 1 cm: left at 1.
    min_cov_translation_m, min_cov_rotation_rad : float
        Floor on each translation (m) / rotation (rad) standard deviation of a fix (extrinsics
        and map survey error that the per-frame covariance does not know of).
    prior_rotation_sigma_rad : float
        1-sigma of the filter's orientation handed to the ambiguity policy, rad.
    ambiguity_log_odds_with_prior : float or None
        The ambiguity policy's evidence threshold while the filter has an estimate (None: the
        gates' own, 18.4). The filter's chi-square gate refuses a flipped branch (its base pose
        is off by about range x twice the viewing angle), and the accepted covariance already
        carries the other branch's weight, so a 100:1 posterior (9.2) suffices; it keeps far,
        near-frontal tags (3-8 m) usable, which bridge stretches where no tag is close.
    shared_quad_px : float
        Two detections whose corners all lie within this distance (px) are one quad read as
        two ids (a glint; :mod:`tagloc.localize.fiducial`, step 4).
    """

    mode: Literal["single", "joint"] = "single"
    cov_scale: float = Field(1.0, gt=0, le=1e6)
    min_cov_translation_m: float = Field(0.005, ge=0, le=1e3)
    min_cov_rotation_rad: float = Field(0.002, ge=0, le=4)
    prior_rotation_sigma_rad: float = Field(0.05, gt=0, le=4)
    ambiguity_log_odds_with_prior: float | None = Field(9.2, ge=0, le=1e6)
    shared_quad_px: float = Field(3.0, ge=0, le=1e4)


class TagSensorConfig(FiducialConfig):
    """The tag sensor: detector, pixel noise, and how fixes are formed (inherited from
    :class:`FiducialConfig`: one definition, one default each).

    ``noise`` is the corner noise model (:class:`~tagloc.tags.NoiseModel`; ``sigma_px`` is
    the one number to calibrate on your detector).
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

    noise: NoiseModel = NoiseModel()
    #: Detection in the regions where mapped tags are predicted (``docs/detection.md``).
    roi: RegionConfig = RegionConfig()
