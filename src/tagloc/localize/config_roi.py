"""``localizer.yaml``: ``tags.roi``: detection in the regions where mapped tags are predicted.

See ``docs/detection.md`` (how the regions are predicted, when the full frame is used, and the
measurements behind each default). Units: pixels, metres, seconds, radians where named.
"""

from __future__ import annotations

from pydantic import Field

from tagloc.config import StrictModel

__all__ = ["RegionConfig"]


class RegionConfig(StrictModel):
    """Predicted-region detection (:mod:`tagloc.localize.roi`)."""

    #: Detect in predicted regions (the full frame on the fallback rules below; chosen by
    #: ``benchmarks/bench_pipeline.py``, see ``docs/detection.md``); the AprilTag backend only
    #: (another backend always sees the full frame); on the replay clock and on the wall
    #: clock's detection worker alike.
    enabled: bool = True
    #: Every this many camera frames, the full frame (1: always the full frame).
    full_frame_every: int = Field(10, ge=1, le=100_000)
    #: The full frame when frames are further apart than this, s.
    gap_s: float = Field(0.5, gt=0, le=1e6)
    #: Region margin: this many standard deviations of each corner's projected uncertainty.
    margin_sigma: float = Field(3.0, ge=0, le=100)
    #: Plus this many pixels, and this fraction of the tag's predicted side (its quiet zone and
    #: the detector's threshold tiles need white around the black border).
    min_margin_px: float = Field(12.0, ge=0, le=1e4)
    margin_side_fraction: float = Field(0.5, ge=0, le=10)
    #: Floors on the pose's 1-sigma (planar filters leave z, roll and pitch unknown; the
    #: extrinsics and the map carry their own errors), m and rad.
    min_translation_sigma_m: float = Field(0.03, ge=0, le=100)
    min_rotation_sigma_rad: float = Field(0.01, ge=0, le=3.2)
    #: The odometry may end before the frame's stamp: the base moves at most this fast over the
    #: difference (m/s, rad/s), added to the pose's uncertainty.
    max_speed_m_s: float = Field(2.0, ge=0, le=100)
    max_turn_rate_rad_s: float = Field(2.0, ge=0, le=100)
    #: Tags predicted smaller than this (side, px) or seen more obliquely than this are not
    #: looked for (the full frame would not find them either).
    min_tag_px: float = Field(10.0, ge=1, le=1e4)
    #: Tags whose predicted corners fall further outside the image than this (px) are not
    #: looked for: the full frame does not find a tag cut by the image's edge either.
    edge_tolerance_px: float = Field(8.0, ge=0, le=1e4)
    max_view_angle_deg: float = Field(85.0, gt=0, le=90)
    #: Decimation of a region: the largest integer up to ``max_quad_decimate`` that leaves the
    #: smallest predicted tag of the region at least ``min_decimated_side_px`` decimated pixels.
    min_decimated_side_px: float = Field(24.0, ge=4, le=1e4)
    max_quad_decimate: int = Field(2, ge=1, le=8)
    #: The full frame when the merged regions cover more than this fraction of it.
    max_area_fraction: float = Field(0.6, gt=0, le=1)
    #: The full frame when a predicted tag's corner sigma exceeds this (px): the prediction is
    #: too loose for its regions to be worth searching.
    max_sigma_px: float = Field(80.0, gt=0, le=1e5)
    #: After the filter gated a fix on the chi-square test, held one for a consistent set or
    #: re-initialized (the estimate may be wrong: a kidnap), the full frame for this many
    #: frames; and for the next frame after a region frame that found none of the tags found in
    #: the frame before it (0: neither).
    full_frames_after_alarm: int = Field(30, ge=0, le=100_000)
