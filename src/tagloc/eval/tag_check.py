"""One camera image through the tag sensor, with every number shown: :func:`check_frame`.

What a technician needs to see to trust a camera and its calibration on a tag (``tagloc
detect``). Steps for one image:

1. The image size against the camera model (:func:`tagloc.camera.check_image`: a camera file
   of another resolution is refused, one line).
2. Detection with the localizer's backend; and again on the left-right mirrored image: a tag
   that decodes only there is *mirrored* (seen in a mirror, or printed reversed), which the
   detector otherwise silently ignores.
3. The tag's size: the map's entry (``--tags``), else ``--size``; a map entry and a ``--size``
   that disagree are named.
4. PnP with both IPPE branches and their covariances
   (:func:`tagloc.tags.estimate_tag_poses`), then every gate on its own, so the report shows
   each value against its limit (not just the first to fail): hamming, decision margin,
   reprojection, the ambiguity policy from the pixels (:func:`tagloc.tags.resolve_ambiguity`;
   a single image has no orientation prior), range and viewing angle on the chosen branch, and
   the localizer's own fix-quality limits (:class:`tagloc.localize.QualityLimits`).
5. The verdict is the tag layer's :func:`tagloc.tags.observe_tags` (what the localizer's
   fiducial source runs, with the map's poses: the ambiguity mixture and the joint estimate
   included), so *accepted* here means accepted there, bar the prior the filter adds.
6. Sizes against each other (:func:`tagloc.eval.tag_check_sizes.size_ratios`): with >= 2
   mapped tags in view, each tag's PnP depth against where the other tags and the map put
   it; a tag printed at another size than the map's sits at the wrong depth by exactly the
   ratio of the sizes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel, check_image
from tagloc.errors import CameraModelError
from tagloc.geometry import SE3
from tagloc.localize import FixQuality, QualityLimits
from tagloc.localize.config import LocalizerConfig
from tagloc.tags import (
    AmbiguityDecision,
    JointPoseEstimate,
    TagDetection,
    TagDetector,
    TagMap,
    TagPoseEstimate,
    as_gray_u8,
    estimate_tag_poses,
    observe_tags,
    resolve_ambiguity,
)
from tagloc.tags.observation import ObservationResult

__all__ = ["FrameCheck", "GateResult", "TagCheck", "check_frame"]

#: Two quads whose corners all lie within this distance (px) are the same tag.
SAME_QUAD_PX = 4.0


@dataclass(frozen=True, slots=True)
class GateResult:
    """One gate: its value against its limit; ``passed`` None where it does not apply."""

    name: str
    value: float
    limit: float
    passed: bool | None
    detail: str = ""


@dataclass(frozen=True, slots=True)
class TagCheck:
    """Everything about one detected tag (module docstring, steps 3-6).

    Attributes
    ----------
    detection : TagDetection
    size_m : float or None
        The size PnP used (None: unknown tag, no ``--size``).
    in_map : bool
    estimate : TagPoseEstimate or None
        Both IPPE branches as PnP ranked them (None: no size, or no pose).
    decision : AmbiguityDecision or None
        The ambiguity policy from the pixels alone.
    gates : tuple of GateResult
    accepted : TagPoseEstimate or None
        ``observe_tags``' accepted estimate (chosen branch, ambiguity folded into the
        covariance), None if refused.
    refusal : str
        ``"reason: detail"`` of the refusal ('' if accepted).
    notes : list of str
        Sizes that disagree and the like, one line each.
    """

    detection: TagDetection
    size_m: float | None
    in_map: bool
    estimate: TagPoseEstimate | None
    decision: AmbiguityDecision | None
    gates: tuple[GateResult, ...]
    accepted: TagPoseEstimate | None
    refusal: str
    notes: list[str] = field(default_factory=list)

    @property
    def sigma(self) -> FloatArray | None:
        """1-sigma of the reported pose: ``[x, y, z]`` m, ``[rx, ry, rz]`` rad (right tangent)."""
        est = self.accepted if self.accepted is not None else self.estimate
        return None if est is None else np.sqrt(np.clip(np.diag(est.cov_cam_tag), 0.0, None))


@dataclass(frozen=True, slots=True)
class FrameCheck:
    """One image's result: its tags, the mirrored ones, the joint estimate and notes."""

    name: str
    image_size: tuple[int, int]
    tags: tuple[TagCheck, ...]
    mirrored: tuple[TagDetection, ...]
    joint: JointPoseEstimate | None
    notes: tuple[str, ...]


def check_frame(
    image: npt.NDArray[np.uint8],
    camera: CameraModel,
    detector: TagDetector,
    config: LocalizerConfig,
    *,
    tag_map: TagMap | None = None,
    size_m: float | None = None,
    name: str = "image",
) -> FrameCheck:
    """Run steps 1-6 of the module docstring on one image.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint8
    camera : CameraModel
    detector : TagDetector
        Of the family ``config.tags.family``.
    config : LocalizerConfig
        Gates, noise model, family (``localizer.yaml``).
    tag_map : TagMap, optional
        Sizes and ``map``-frame poses.
    size_m : float, optional
        Size of tags the map does not have (or of every tag, without a map).
    name : str
        The image's name in messages.

    Raises
    ------
    CameraModelError
        The image's size is not the camera's.
    """
    # 1. image size
    height, width = np.shape(image)[:2]
    if (width, height) != tuple(camera.image_size):
        raise CameraModelError(
            f"{name}: the image is {width}x{height} px but the camera file is for "
            f"{camera.image_size[0]}x{camera.image_size[1]} px (a calibration of another "
            "resolution or another camera)"
        )
    check_image(image, camera, name)
    gray = as_gray_u8(image, name)
    # 2. detections, and the mirrored ones
    family = config.tags.family
    detections = [d for d in detector.detect(gray) if d.family == family]
    mirrored = _mirrored(detector, gray, detections)
    # 3. sizes and map poses
    entries = (
        {} if tag_map is None else {t.id: t for t in tag_map.in_frame("map") if t.family == family}
    )
    sizes: dict[int, float] = {}
    notes: list[str] = []
    for det in detections:
        entry = entries.get(det.tag_id)
        if entry is not None:
            sizes[det.tag_id] = entry.size
            if size_m is not None and not math.isclose(entry.size, size_m, rel_tol=1e-6):
                notes.append(
                    f"tag {det.tag_id}: the map says {entry.size:g} m, --size "
                    f"{size_m:g} m; using the map's"
                )
        elif size_m is not None:
            sizes[det.tag_id] = size_m
    tag_poses = {i: e.T_frame_tag() for i, e in entries.items()} if tag_map is not None else None
    # 4. PnP (both branches) and every gate
    known = [d for d in detections if d.tag_id in sizes]
    noise, gates = config.tags.noise, config.gates
    estimates = estimate_tag_poses(
        [d.tag_id for d in known],
        np.array([d.corners_px for d in known]).reshape(-1, 4, 2),
        [sizes[d.tag_id] for d in known],
        camera,
        noise,
    )
    by_det = {id(d): e for d, e in zip(known, estimates, strict=True)}
    # 5. the verdict of the tag layer (ids seen twice: one detection at a time, as the
    # localizer's fiducial source does)
    results = _observe(detections, camera, sizes, config, tag_poses)
    limits = QualityLimits(gates.max_reproj_err_px, gates.max_ambiguity_ratio, gates.max_range_m)
    tags = []
    for det in detections:
        est = by_det.get(id(det))
        decision = None
        if est is not None:
            decision = resolve_ambiguity(
                est.sse_px2, est.sse_alt_px2, noise.sigma_px, gates.ambiguity_log_odds
            )
        result = results[id(det)]
        accepted = next((e for e in result.accepted if e.tag_id == det.tag_id), None)
        refusal = next(
            (f"{r.reason}: {r.detail}" for r in result.rejections if r.tag_id == det.tag_id), ""
        )
        tags.append(
            TagCheck(
                det,
                sizes.get(det.tag_id),
                det.tag_id in entries,
                est,
                decision,
                _gates(det, est, decision, config, limits),
                accepted,
                refusal,
            )
        )
    # 6. sizes against each other
    if tag_poses is not None:
        from tagloc.eval.tag_check_sizes import size_notes

        notes += size_notes(tags, tag_poses)
    joint = next((r.joint for r in results.values() if r.joint is not None), None)
    for det in mirrored:
        notes.append(
            f"tag {det.tag_id} ({family}) near pixel ({det.center_px[0]:.0f}, "
            f"{det.center_px[1]:.0f}) is mirrored: it decodes only in the mirrored "
            "image (seen in a mirror or printed reversed); the localizer ignores it"
        )
    shape = (int(gray.shape[1]), int(gray.shape[0]))
    return FrameCheck(name, shape, tuple(tags), tuple(mirrored), joint, tuple(notes))


def _mirrored(
    detector: TagDetector, gray: npt.NDArray[np.uint8], found: list[TagDetection]
) -> list[TagDetection]:
    """Detections of the left-right mirrored image at no quad of ``found``, in image pixels."""
    width = gray.shape[1]
    out = []
    for det in detector.detect(np.ascontiguousarray(gray[:, ::-1])):
        corners = np.asarray(det.corners_px, dtype=np.float64).copy()
        corners[:, 0] = width - 1 - corners[:, 0]
        corners = corners[::-1]  # the mirror reverses the winding
        same = any(
            np.linalg.norm(np.asarray(f.corners_px)[:, None] - corners[None], axis=2).min(1).max()
            <= SAME_QUAD_PX
            for f in found
        )
        if not same:
            out.append(
                TagDetection(det.tag_id, det.family, corners, det.hamming, det.decision_margin)
            )
    return out


def _observe(
    detections: list[TagDetection],
    camera: CameraModel,
    sizes: dict[int, float],
    config: LocalizerConfig,
    tag_poses: dict[int, SE3] | None,
) -> dict[int, ObservationResult]:
    """``observe_tags`` per detection: one call for the ids seen once, one per repeated id."""
    counts: dict[int, int] = {}
    for det in detections:
        counts[det.tag_id] = counts.get(det.tag_id, 0) + 1
    groups = [[d for d in detections if counts[d.tag_id] == 1]]
    groups += [[d] for d in detections if counts[d.tag_id] > 1]
    out: dict[int, ObservationResult] = {}
    for group in groups:
        if not group:
            continue
        result = observe_tags(
            group, camera, sizes, config.gates, tag_poses=tag_poses, noise=config.tags.noise
        )
        out.update({id(d): result for d in group})
    return out


def _gates(
    det: TagDetection,
    est: TagPoseEstimate | None,
    decision: AmbiguityDecision | None,
    config: LocalizerConfig,
    limits: QualityLimits,
) -> tuple[GateResult, ...]:
    """Every gate of step 4, each on its own."""
    g = config.gates
    margin = det.decision_margin
    out = [
        GateResult("hamming", det.hamming, g.max_hamming, det.hamming <= g.max_hamming),
        GateResult(
            "decision_margin",
            margin,
            g.min_decision_margin,
            None if math.isnan(margin) else margin >= g.min_decision_margin,
        ),
    ]
    if est is None:
        return (*out, GateResult("pose", math.nan, math.nan, False, "no size or no pose"))
    chosen = est.swapped() if decision is not None and decision.choose_alt else est
    out += [
        GateResult(
            "reprojection_px",
            est.reproj_err_px,
            g.max_reproj_err_px,
            est.reproj_err_px <= g.max_reproj_err_px,
        ),
        GateResult(
            "ambiguity_log_odds",
            decision.log_odds if decision else math.nan,
            g.ambiguity_log_odds,
            decision is not None and decision.reason is None,
            decision.detail if decision else "",
        ),
        GateResult("range_m", chosen.range_m, g.max_range_m, chosen.range_m <= g.max_range_m),
        GateResult(
            "view_angle_deg",
            math.degrees(chosen.view_angle_rad),
            g.max_view_angle_deg,
            math.degrees(chosen.view_angle_rad) <= g.max_view_angle_deg,
        ),
    ]
    quality = FixQuality(
        chosen.reproj_err_px, 1, chosen.range_m, chosen.ambiguity_ratio, chosen.view_angle_rad
    )
    refused = limits.check(quality)
    out.append(
        GateResult(
            "fix_quality",
            math.nan if refused is None else refused[1],
            math.nan if refused is None else refused[2],
            refused is None,
            "" if refused is None else refused[3],
        )
    )
    return tuple(out)
