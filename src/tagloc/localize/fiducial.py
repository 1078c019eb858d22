"""The fiducial fix source: one camera frame's tag detections -> gated :class:`TagFix` es.

Steps for one frame (:meth:`FiducialFixSource.frame_fixes`):

1. Ids twice in one frame (a mirror, a misread, a glint copying a real tag's id) are solved one
   detection at a time, so each stays its own fix and the filter's chi-square gate judges it.
2. :func:`~tagloc.tags.observe_tags` with the tag map's ``T_map_tag``: unknown ids, decoder
   gates, PnP, reprojection, range and viewing-angle gates, and the IPPE ambiguity policy with
   the filter's current estimate as the orientation prior (``T_map_cam = T_map_base @
   T_base_cam``) plus gravity. A tag that conflicts with that prior is solved again with gravity
   alone: the prior may resolve an ambiguity but never vetoes a tag (after a kidnap the prior
   is wrong, and only the filter's kidnap test may decide that).
3. One fix per accepted tag: ``T_map_base = T_map_tag @ T_cam_tag^-1 @ T_base_cam^-1`` with the
   covariance transported from ``cov_cam_tag`` (and the tag's survey covariance if the map has
   one), then inflated (``cov_scale``, see
   :class:`~tagloc.localize.config_tags.FiducialConfig`).
4. One quad decoded as two ids (a glint: a real tag's corners read as another id) cannot be
   both: the reading nearest the prior is kept, the others refused (``shared_quad``); without a
   prior all are refused. (Left to the chi-square gate alone, such glints would be rejected
   too, but they repeat the same wrong pose and so make the true tag's id look moved.)

Single-tag fixes (default) rather than one joint PnP per frame: each fix keeps the id of the one
tag it rests on as its ``source``, so the filter's per-source books can single out a moved tag
and a glint can only spoil its own fix (a wrong tag in a joint solve spoils the whole frame's
fix, or biases it when it still fits). The filter applies the fixes of one frame one after the
other, which for independent corner noise is the joint update. Joint PnP is available
(``mode="joint"``) for maps with tag bundles; it then replaces the single-tag fixes of its tags.

Rejected observations are returned as counted :class:`ObservationReject` s, never raised.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.localize.config_tags import FiducialConfig
from tagloc.localize.fix import FixQuality, TagFix
from tagloc.tags import (
    GateConfig,
    NoiseModel,
    ObservationResult,
    PosePrior,
    RejectReason,
    TagDetection,
    TagMap,
    map_base_from_cam,
    map_cam_from_tag,
    observe_tags,
)
from tagloc.tags.pnp import TagPoseEstimate

__all__ = ["FiducialConfig", "FiducialFixSource", "FrameFixes", "ObservationReject", "SourcedFix"]


#: An upright base's up axis (REP-103 ``base_link``).
E_Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True, slots=True)
class ObservationReject:
    """A detection the per-observation gates refused (it never reached the filter).

    Attributes
    ----------
    tag_id : int or None
        None for a refused joint estimate.
    reason : str
        A :class:`~tagloc.tags.RejectReason` value.
    detail : str
    range_m : float
        Rough camera-to-tag range from the corners' apparent size (``fx * size / side_px``),
        NaN when the tag's size is unknown.
    false_detection : bool or None
        Simulator truth for the detection, None if unknown.
    """

    tag_id: int | None
    reason: str
    detail: str
    range_m: float
    false_detection: bool | None


@dataclass(frozen=True, slots=True)
class SourcedFix:
    """A fix and the truth flag of the detection(s) it came from (None if unknown)."""

    fix: TagFix
    tag_ids: tuple[int, ...]
    false_detection: bool | None


@dataclass(frozen=True, slots=True)
class FrameFixes:
    """What one frame gave: fixes for the filter and refused observations."""

    fixes: tuple[SourcedFix, ...]
    rejects: tuple[ObservationReject, ...]


class FiducialFixSource:
    """Turns detections of one frame into gated tag fixes (module docstring).

    Parameters
    ----------
    camera : CameraModel
        Model of the raw image the corners are in.
    T_base_cam : SE3
        Camera optical frame in the base frame.
    tag_map : TagMap
        Only entries in frame ``map`` (``map_frame``) and of ``family`` are used.
    family : str
    gates : GateConfig, optional
    noise : NoiseModel, optional
    config : FiducialConfig, optional
    map_frame : str
    up_base : (3,) float or None
        "Up" in the base when a frame gives none (default ``+z``, an upright base); None: no
        gravity prior (an odometry that knows no up, such as camera-only visual odometry).
    """

    def __init__(
        self,
        camera: CameraModel,
        T_base_cam: SE3,
        tag_map: TagMap,
        *,
        family: str = "tag36h11",
        gates: GateConfig | None = None,
        noise: NoiseModel | None = None,
        config: FiducialConfig | None = None,
        map_frame: str = "map",
        up_base: FloatArray | None = E_Z,
    ) -> None:
        self.camera, self.T_base_cam = camera, T_base_cam
        self.up_base = None if up_base is None else np.asarray(up_base, dtype=np.float64)
        self.family = family
        self.gates = gates or GateConfig()
        self.noise = noise or NoiseModel()
        self.config = config or FiducialConfig()
        odds = self.config.ambiguity_log_odds_with_prior
        self._gates_prior = (
            self.gates
            if odds is None
            else self.gates.model_copy(update={"ambiguity_log_odds": odds})
        )
        entries = [t for t in tag_map.in_frame(map_frame) if t.family == family]
        self.T_map_tag: dict[int, SE3] = {t.id: t.T_frame_tag() for t in entries}
        self.cov_map_tag: dict[int, FloatArray | None] = {
            t.id: t.covariance_matrix() for t in entries
        }
        self.sizes: dict[int, float] = {t.id: t.size for t in entries}
        self._fx = float(camera.K[0, 0])
        c = self.config
        self._floor = np.diag(
            np.square([c.min_cov_translation_m] * 3 + [c.min_cov_rotation_rad] * 3)
        )

    def frame_fixes(
        self,
        stamp_ns: int,
        detections: Sequence[TagDetection],
        T_map_base_prior: SE3 | None = None,
        false_detection: Sequence[bool] | None = None,
        up_base: FloatArray | None = None,
    ) -> FrameFixes:
        """Fixes and refusals of one frame (steps in the module docstring).

        Parameters
        ----------
        stamp_ns : int
            Exposure stamp; every fix carries it.
        detections : sequence of TagDetection
        T_map_base_prior : SE3, optional
            The filter's estimate at ``stamp_ns`` (orientation prior of the ambiguity policy).
        false_detection : sequence of bool, optional
            Simulator truth per detection (carried into the results for evaluation only).
        up_base : (3,) float, optional
            "Up" in the base at ``stamp_ns`` (:class:`~tagloc.frames.OdometryFrameConfig`);
            None: the source's default (an upright base's ``+z``, or no gravity at all).
        """
        flags: list[bool | None] | None = (
            list(false_detection) if false_detection is not None else None
        )
        dets = [d for d in detections if d.family == self.family]
        det_flags = (
            [f for d, f in zip(detections, flags, strict=True) if d.family == self.family]
            if flags is not None
            else None
        )
        rejects = [
            ObservationReject(d.tag_id, RejectReason.UNKNOWN_TAG.value, "other family", math.nan, f)
            for d, f in zip(detections, flags or [None] * len(detections), strict=True)
            if d.family != self.family
        ]
        gravity = self._gravity(up_base)
        prior: PosePrior | None = gravity
        if T_map_base_prior is not None:
            prior = PosePrior(
                T_map_base_prior @ self.T_base_cam,
                self.config.prior_rotation_sigma_rad,
                None if gravity is None else gravity.up_cam,
            )
        # 1. ids seen twice are solved one detection at a time
        counts = Counter(d.tag_id for d in dets)
        groups: list[list[int]] = [[i for i, d in enumerate(dets) if counts[d.tag_id] == 1]]
        groups += [[i] for i, d in enumerate(dets) if counts[d.tag_id] > 1]
        fixes: list[SourcedFix] = []
        for group in groups:
            if not group:
                continue
            sub = [dets[i] for i in group]
            sub_flags = None if det_flags is None else {dets[i].tag_id: det_flags[i] for i in group}
            solved, refused = self._solve(stamp_ns, sub, prior, sub_flags, gravity)
            fixes += solved
            rejects += refused
        # 4. one quad read as two ids (a glint on a real tag's corners): keep the reading that
        # agrees with the prior, refuse the others (all of them without a prior)
        for ids in _shared_quads(dets, self.config.shared_quad_px):
            shared = [sf for sf in fixes if sf.tag_ids[0] in ids and len(sf.tag_ids) == 1]
            keep = None
            if T_map_base_prior is not None and shared:
                t_prior = T_map_base_prior.translation
                keep = min(
                    shared,
                    key=lambda sf: float(np.linalg.norm(sf.fix.T_map_base.translation - t_prior)),
                )
            for sf in shared:
                if sf is not keep:
                    fixes.remove(sf)
                    rejects.append(
                        ObservationReject(
                            sf.tag_ids[0], "shared_quad", "its corners were also read as another "
                            "id", sf.fix.quality.range_m, sf.false_detection,
                        )
                    )  # fmt: skip
        return FrameFixes(tuple(fixes), tuple(rejects))

    # ----- internals -------------------------------------------------------------------------
    def _solve(
        self,
        stamp_ns: int,
        dets: list[TagDetection],
        prior: PosePrior | None,
        flags: Mapping[int, bool | None] | None,
        gravity: PosePrior | None,
    ) -> tuple[list[SourcedFix], list[ObservationReject]]:
        """observe_tags on detections of distinct ids; prior conflicts retried on gravity."""
        result = self._observe(dets, prior)
        accepted = list(result.accepted)
        rejections = list(result.rejections)
        conflicts = {r.tag_id for r in rejections if r.reason is RejectReason.PRIOR_CONFLICT}
        if prior is not None and prior.T_map_cam is not None and conflicts:  # 2. no veto
            retry = self._observe([d for d in dets if d.tag_id in conflicts], gravity)
            rejections = [r for r in rejections if r.tag_id not in conflicts] + [
                r for r in retry.rejections if r.tag_id is not None
            ]
            accepted += retry.accepted
        by_id: dict[int | None, TagDetection] = {d.tag_id: d for d in dets}
        rejects = [
            ObservationReject(
                r.tag_id, r.reason.value, r.detail, self._rough_range(by_id.get(r.tag_id)),
                None if flags is None or r.tag_id is None else flags.get(r.tag_id),
            )
            for r in rejections
        ]  # fmt: skip
        fixes: list[SourcedFix] = []
        joint = result.joint if self.config.mode == "joint" and not conflicts else None
        if joint is not None and joint.T_map_base is not None and joint.cov_map_base is not None:
            in_joint = set(joint.tag_ids)
            est_joint = [e for e in accepted if e.tag_id in in_joint]
            quality = FixQuality(
                joint.reproj_err_px, len(joint.tag_ids),
                min((e.range_m for e in est_joint), default=math.nan),
                joint.ambiguity_ratio,
                min((e.view_angle_rad for e in est_joint), default=math.nan),
            )  # fmt: skip
            source = "tags:" + ",".join(str(i) for i in sorted(in_joint))
            fix = TagFix(stamp_ns, joint.T_map_base, self._inflate(joint.cov_map_base), source,
                         quality)  # fmt: skip
            truth = None if flags is None else any(flags.get(i, False) for i in in_joint)
            fixes.append(SourcedFix(fix, tuple(sorted(in_joint)), truth))
            accepted = [e for e in accepted if e.tag_id not in in_joint]
        for est in accepted:  # 3. one fix per tag
            fixes.append(
                SourcedFix(
                    self._tag_fix(stamp_ns, est), (est.tag_id,),
                    None if flags is None else flags.get(est.tag_id),
                )
            )  # fmt: skip
        return fixes, rejects

    def _observe(self, dets: list[TagDetection], prior: PosePrior | None) -> ObservationResult:
        gates = (
            self._gates_prior if prior is not None and prior.T_map_cam is not None else self.gates
        )
        return observe_tags(
            dets, self.camera, self.sizes, gates, tag_poses=self.T_map_tag,
            T_base_cam=self.T_base_cam, prior=prior, noise=self.noise,
        )  # fmt: skip

    def _gravity(self, up_base: FloatArray | None) -> PosePrior | None:
        """The gravity prior: "up" in the camera from ``up_base`` (default: the upright base's
        ``+z``; None when the odometry frame knows no up)."""
        if up_base is None:
            up_base = self.up_base
        if up_base is None:
            return None
        return PosePrior(up_cam=self.T_base_cam.rotation.inverse().act(np.asarray(up_base)))

    def _tag_fix(self, stamp_ns: int, est: TagPoseEstimate) -> TagFix:
        T_map_cam, cov_map_cam = map_cam_from_tag(
            est.T_cam_tag, est.cov_cam_tag, self.T_map_tag[est.tag_id],
            self.cov_map_tag.get(est.tag_id),
        )  # fmt: skip
        T_map_base, cov = map_base_from_cam(T_map_cam, cov_map_cam, self.T_base_cam)
        quality = FixQuality(
            est.reproj_err_px, 1, est.range_m, est.ambiguity_ratio, est.view_angle_rad
        )
        return TagFix(stamp_ns, T_map_base, self._inflate(cov), f"tag:{est.tag_id}", quality)

    def _inflate(self, cov: FloatArray) -> FloatArray:
        out: FloatArray = self.config.cov_scale * np.asarray(cov, dtype=np.float64) + self._floor
        return 0.5 * (out + out.T)

    def _rough_range(self, det: TagDetection | None) -> float:
        if det is None or det.tag_id not in self.sizes:
            return math.nan
        px = np.asarray(det.corners_px, dtype=np.float64)
        side = float(np.linalg.norm(px - np.roll(px, -1, axis=0), axis=1).mean())
        return self._fx * self.sizes[det.tag_id] / side if side > 0 else math.nan


def _shared_quads(dets: Sequence[TagDetection], tol_px: float) -> list[set[int]]:
    """Sets of distinct ids whose detections share one quad (corners within ``tol_px``)."""
    if len(dets) < 2:
        return []
    corners = np.array([np.asarray(d.corners_px, dtype=np.float64) for d in dets])
    groups: list[set[int]] = []
    for i in range(len(dets)):
        dist = np.linalg.norm(corners - corners[i], axis=2).max(axis=1)
        ids = {dets[int(j)].tag_id for j in np.flatnonzero(dist <= tol_px)}
        if len(ids) > 1 and ids not in groups:
            groups.append(ids)
    return groups
