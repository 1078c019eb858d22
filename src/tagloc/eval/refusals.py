"""Fix attempts by decision and reason, acceptance per camera, and the line that says what to check.

Every fix attempt of a run ends in one decision (:attr:`~tagloc.localize.run.FixAttempt.
decision`): applied (``accepted``, ``initialized``, ``reinitialized_kidnap``), refused by the
per-observation gates before the filter (``rejected:<reason>``, the reason a
:class:`~tagloc.tags.RejectReason` value or ``shared_quad``) or decided otherwise by the filter
(``gated_chi2``, ``pending_consistency``, ...). :class:`DecisionBook` counts them as the run
streams (constant memory: one counter per decision and camera) and :class:`FixDecisions` is the
result: the counts, the per-camera acceptance, and, when one refusal reason accounts for more
than half of all attempts, one hint line naming it and what to check (:data:`WHAT_TO_CHECK`).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from tagloc.localize.events import APPLIED
from tagloc.localize.run import FixAttempt

__all__ = [
    "WHAT_TO_CHECK",
    "CameraAcceptance",
    "DecisionBook",
    "FixDecisions",
    "dominant_refusal",
    "fix_decisions",
]

#: What a refusal reason means and what to check when it refuses most attempts.
WHAT_TO_CHECK: dict[str, str] = {
    "rejected:prior_conflict": (
        "the tag's orientation contradicts the filter's and gravity's: check the odometry "
        "frame's up axis (localizer.yaml odometry_frame: gravity_aligned, up_axis, "
        "base_up_axis), the camera extrinsics (--camera-poses, --tagslam) and the map"
    ),
    "rejected:ambiguous": (
        "the two PnP solutions of a tag cannot be told apart (far or face-on tags): check "
        "the gravity prior (odometry_frame), tag sizes in the map, gates.ambiguity_log_odds"
    ),
    "rejected:reprojection": (
        "the pose does not explain the corners: check the camera model (--cameras: "
        "intrinsics, distortion), the corner order (--corner-order) and the tag sizes"
    ),
    "rejected:unknown_tag": (
        "the ids seen are not in the map: check the map (--tags), tags.family and the "
        "detector's family"
    ),
    "rejected:hamming": "the decoder corrected too many bits: check gates.max_hamming and focus",
    "rejected:decision_margin": (
        "weak decodes: check gates.min_decision_margin, exposure and focus"
    ),
    "rejected:degenerate": "corners give no pose: check the camera model and the corner order",
    "rejected:range": "tags beyond gates.max_range_m: check the range gate and tag sizes",
    "rejected:view_angle": "tags seen too obliquely: check gates.max_view_angle_deg",
    "rejected:shared_quad": "one quad read as two ids: check the detector (glints, reflections)",
    "gated_chi2": (
        "fixes disagree with the estimate: check the map (moved tags), the camera extrinsics, "
        "the odometry frame and the odometry's noise (process_noise)"
    ),
    "gated_reproj": "fixes over the reprojection limit: check the camera model",
    "gated_quality": "fixes over the quality limits: check gates.max_reproj_err_px, max_range_m",
    "rejected_suspect": "fixes of tags flagged as moved: check the map (re-survey those tags)",
    "pending_consistency": (
        "the filter never saw gates.k_consistent agreeing fixes: check the map and the "
        "extrinsics"
    ),
    "discarded_candidate": "start-up candidates that did not agree: check the map, extrinsics",
    "unused_no_state": "fixes before the filter had a state: check gates.k_consistent",
    "no_odometry": "fixes without odometry at their stamp: check the odometry topic and stamps",
}


@dataclass(frozen=True, slots=True)
class CameraAcceptance:
    """Attempts and accepted fixes of one camera (``""``: the node's only camera)."""

    camera: str
    n_attempts: int
    n_accepted: int

    @property
    def acceptance(self) -> float:
        """``n_accepted / n_attempts`` (NaN without attempts)."""
        return self.n_accepted / self.n_attempts if self.n_attempts else math.nan


@dataclass(frozen=True, slots=True)
class FixDecisions:
    """The fix attempts of a run by decision, and per camera (module docstring).

    Attributes
    ----------
    n_attempts, n_accepted : int
    by_decision : dict of str -> int
        Attempts per decision string, most frequent first.
    by_camera : tuple of CameraAcceptance
        Per camera, in name order (one row ``""`` for a single-camera node).
    hint : str or None
        One line when one refusal accounts for more than half of the attempts.
    """

    n_attempts: int
    n_accepted: int
    by_decision: dict[str, int]
    by_camera: tuple[CameraAcceptance, ...]
    hint: str | None

    @property
    def acceptance(self) -> float:
        return self.n_accepted / self.n_attempts if self.n_attempts else math.nan

    def to_dict(self) -> dict[str, Any]:
        """JSON form (``summary.json``'s ``fix_decisions``)."""
        return {
            "attempts": self.n_attempts, "accepted": self.n_accepted,
            "acceptance": _num(self.acceptance), "by_decision": dict(self.by_decision),
            "by_camera": {c.camera: {"attempts": c.n_attempts, "accepted": c.n_accepted,
                                     "acceptance": _num(c.acceptance)} for c in self.by_camera},
            "hint": self.hint,
        }  # fmt: skip

    def lines(self) -> list[str]:
        """Console lines: the decisions with their shares, the cameras, the hint."""
        if not self.n_attempts:
            return ["fix decisions: no fix attempt"]
        n = self.n_attempts
        parts = [f"{k} {v} ({100 * v / n:.1f} %)" for k, v in self.by_decision.items()]
        out = [f"fix decisions ({n} attempts): " + ", ".join(parts)]
        if len(self.by_camera) > 1 or (self.by_camera and self.by_camera[0].camera):
            out.append("accepted per camera: " + ", ".join(
                f"{c.camera} {c.n_accepted}/{c.n_attempts} ({100 * c.acceptance:.1f} %)"
                for c in self.by_camera if c.n_attempts))  # fmt: skip
        if self.hint:
            out.append(f"HINT: {self.hint}")
        return out


class DecisionBook:
    """Counts fix attempts as they stream (a sink of :class:`FixAttempt` s; constant memory)."""

    def __init__(self) -> None:
        self._decisions: Counter[str] = Counter()
        self._attempts: Counter[str] = Counter()
        self._accepted: Counter[str] = Counter()

    def add(self, attempt: FixAttempt) -> None:
        self._decisions[attempt.decision] += 1
        self._attempts[attempt.camera] += 1
        self._accepted[attempt.camera] += attempt.accepted

    def result(self) -> FixDecisions:
        n = sum(self._decisions.values())
        accepted = sum(v for k, v in self._decisions.items() if k in APPLIED)
        by_decision = dict(sorted(self._decisions.items(), key=lambda kv: (-kv[1], kv[0])))
        cameras = tuple(
            CameraAcceptance(c, self._attempts[c], self._accepted[c])
            for c in sorted(self._attempts)
        )
        return FixDecisions(n, accepted, by_decision, cameras, dominant_refusal(by_decision))


def fix_decisions(fixes: Iterable[FixAttempt]) -> FixDecisions:
    """:class:`FixDecisions` of a run's attempts."""
    book = DecisionBook()
    for attempt in fixes:
        book.add(attempt)
    return book.result()


def dominant_refusal(by_decision: dict[str, int]) -> str | None:
    """The hint line when one refusal (any decision that does not apply the fix) accounts for
    more than half of all attempts; None otherwise."""
    n = sum(by_decision.values())
    refusals = [(v, k) for k, v in by_decision.items() if k not in APPLIED]
    if not n or not refusals:
        return None
    count, decision = max(refusals)
    if 2 * count <= n:
        return None
    reason = decision.removeprefix("rejected:")
    check = WHAT_TO_CHECK.get(decision, "check what its name says against the configuration")
    return f"{count} of {n} fix attempts ({100 * count / n:.0f} %) are refused as {reason}: {check}"


def _num(value: float) -> float | None:
    return value if math.isfinite(value) else None
