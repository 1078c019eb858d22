"""Fiducial tags: detection behind one :class:`TagDetection` type, and tag bitmaps.

- :class:`TagDetection`: tag id, family, the four black-border corners in **one** convention
  (OpenCV pixel centers; top-left, top-right, bottom-right, bottom-left of the upright tag, which
  is the order of :func:`tag_object_points` and of ``cv2.SOLVEPNP_IPPE_SQUARE``), hamming,
  decision margin, center. Recorded corners in other orders enter via
  :meth:`TagDetection.from_corners`. The convention is spelled out in
  :mod:`tagloc.tags.detection`.
- :class:`TagDetector` (protocol) and :func:`make_detector` over an explicit registry:
  ``"apriltag"`` (AprilTag 3 via pupil-apriltags, default) and ``"aruco"`` (OpenCV 5 ArUco).
  Each backend module documents how its library's corner order, pixel-center offset and tag
  frame were reconciled, with the measured numbers.
- :func:`tag_bitmap`: upright black-and-white images of real tags for the simulator.

Errors are :class:`TagError` (``tagloc.tags.errors``).

Example
-------
>>> detector = make_detector("apriltag", "tag36h11")            # doctest: +SKIP
>>> for det in detector.detect(image_gray):                      # doctest: +SKIP
...     ok, rvec, tvec = cv2.solvePnP(tag_object_points(0.16), det.corners_px, K, dist,
...                                   flags=cv2.SOLVEPNP_IPPE_SQUARE)   # T_cam_tag
"""

from tagloc.tags.apriltag_backend import AprilTagDetector
from tagloc.tags.aruco_backend import ArucoTagDetector
from tagloc.tags.backends import available_backends, make_detector, register_backend
from tagloc.tags.bitmaps import bitmap_corners_px, tag_bitmap
from tagloc.tags.covariance import (
    NoiseModel,
    ambiguity_mixture,
    map_base_from_cam,
    map_cam_from_tag,
    nees,
    pose_covariance,
)
from tagloc.tags.detection import (
    APRILTAG3_ORDER,
    TAGLOC_ORDER,
    TagDetection,
    TagDetector,
    corner_permutation,
    tag_object_points,
)
from tagloc.tags.errors import TagBackendError, TagError, TagInputError
from tagloc.tags.families import TagFamily, family_spec, known_families
from tagloc.tags.gates import (
    AmbiguityDecision,
    GateConfig,
    OrientationPrior,
    Rejection,
    RejectReason,
    check_detection,
    check_estimate,
    prior_evidence,
    resolve_ambiguity,
    tag_prior_evidence,
)
from tagloc.tags.images import as_gray_u8
from tagloc.tags.observation import ObservationResult, PosePrior, observe_tags
from tagloc.tags.pnp import (
    JointPoseEstimate,
    TagPoseError,
    TagPoseEstimate,
    estimate_joint_pose,
    estimate_tag_pose,
    estimate_tag_poses,
)
from tagloc.tags.tag_entry import TagEntry
from tagloc.tags.tagmap import TagMap, load_tag_map, save_tag_map
from tagloc.tags.tagmap_checks import TagMapError, TagMapLookupError
from tagloc.tags.tagmap_diff import (
    TagChange,
    TagMapDiff,
    TagMove,
    diff_tag_maps,
    format_tag_map_diff,
)

__all__ = [
    "APRILTAG3_ORDER",
    "TAGLOC_ORDER",
    "AmbiguityDecision",
    "AprilTagDetector",
    "ArucoTagDetector",
    "GateConfig",
    "JointPoseEstimate",
    "NoiseModel",
    "ObservationResult",
    "OrientationPrior",
    "PosePrior",
    "RejectReason",
    "Rejection",
    "TagBackendError",
    "TagChange",
    "TagDetection",
    "TagDetector",
    "TagEntry",
    "TagError",
    "TagFamily",
    "TagInputError",
    "TagMap",
    "TagMapDiff",
    "TagMapError",
    "TagMapLookupError",
    "TagMove",
    "TagPoseError",
    "TagPoseEstimate",
    "ambiguity_mixture",
    "as_gray_u8",
    "available_backends",
    "bitmap_corners_px",
    "check_detection",
    "check_estimate",
    "corner_permutation",
    "diff_tag_maps",
    "estimate_joint_pose",
    "estimate_tag_pose",
    "estimate_tag_poses",
    "family_spec",
    "format_tag_map_diff",
    "known_families",
    "load_tag_map",
    "make_detector",
    "map_base_from_cam",
    "map_cam_from_tag",
    "nees",
    "observe_tags",
    "pose_covariance",
    "prior_evidence",
    "register_backend",
    "resolve_ambiguity",
    "save_tag_map",
    "tag_bitmap",
    "tag_object_points",
    "tag_prior_evidence",
]
