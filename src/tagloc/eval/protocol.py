"""The per-opportunity reliability protocol and time to relocalize after a kidnap.

Reliability of a localization primitive is counted per opportunity, not per hour: an
*opportunity* is a camera frame with a tag truly in view within ``Z`` m
(:attr:`CameraFrameRecord.nearest_visible_tag_m` ``<= Z``); it is a *success* when a fix from
that frame was accepted and the published ``T_map_base`` right after (at the first odometry
stamp at or after the frame, the row at which the pipeline applies the frame's fixes) is within
``X`` m and ``Y`` degrees of ground truth. Defaults: ``Z = 3 m``, ``X = 5 cm``, ``Y = 2 deg``.

Two populations, reported apart and summed. A *cab* opportunity sees, within ``Z``, only the
tags of an elevator cab (posed in the cab's frame; :attr:`CameraFrameRecord.nearest_by_frame`):
there the node localizes relative to the cab, so it is judged against the cab: a success when a
fix of the cab's tags from that frame was accepted (by the cab's estimator,
:attr:`FixAttempt.frame`) and the published ``T_<cab>_base`` at that same row (the node's
:class:`~tagloc.localize.run.CabEstimate`) is within ``X`` / ``Y`` of the simulator's base
relative to the cab at that stamp (:class:`~tagloc.eval.cab_protocol.CabErrors`); no cab
estimate at that row is a miss. Every other opportunity (a tag of the map within ``Z``) is a
*map* opportunity, judged as above.

Time to relocalize after a kidnap: from the first frame after the kidnap that sees a tag (truly in
view and detected) to the first accepted fix after the kidnap whose published pose right after is
within ``X`` / ``Y`` of truth.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from pydantic import Field

from tagloc.config import StrictModel
from tagloc.eval.cab_protocol import CabErrors, cab_successes
from tagloc.eval.trajectories import PoseErrors
from tagloc.localize.run import CameraFrameRecord, FixAttempt


class EvalConfig(StrictModel):
    """Thresholds of the evaluation (units in the names) and the pass/fail targets."""

    opportunity_range_m: float = Field(3.0, gt=0, description="Z: tag in view within this range")
    position_tol_m: float = Field(0.05, gt=0, description="X: position error of a success")
    rotation_tol_deg: float = Field(2.0, gt=0, description="Y: rotation error of a success")
    rpe_delta_m: float = Field(1.0, gt=0, description="RPE pair spacing along the truth path")
    range_bin_edges_m: tuple[float, ...] = Field(
        (0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0), description="acceptance-vs-range bins"
    )
    angle_bin_edges_deg: tuple[float, ...] = Field(
        (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0), description="acceptance-vs-angle bins"
    )
    target_fused_ate_m: float = Field(0.05, gt=0, description="pass: fused ATE RMSE at most")
    target_reliability: float = Field(0.99, gt=0, le=1, description="pass: fraction at least")
    target_false_fixes: int = Field(0, ge=0, description="pass: false fixes accepted at most")
    target_relocalize_s: float = Field(1.0, gt=0, description="pass: kidnap recovery at most")


@dataclass(frozen=True, slots=True)
class Population:
    """The protocol's counts over one population of opportunities (module docstring).

    Attributes
    ----------
    n_opportunities, n_fix_accepted, n_success : int
        As :class:`Reliability`'s, over this population.
    fraction : float
        ``n_success / n_opportunities`` (NaN with no opportunity).
    """

    n_opportunities: int
    n_fix_accepted: int
    n_success: int
    fraction: float

    @classmethod
    def count(
        cls, opportunity: npt.NDArray[np.bool_], fix_accepted: npt.NDArray[np.bool_],
        success: npt.NDArray[np.bool_],
    ) -> Population:  # fmt: skip
        n, k = int(np.count_nonzero(opportunity)), int(np.count_nonzero(opportunity & success))
        accepted = int(np.count_nonzero(opportunity & fix_accepted))
        return cls(n, accepted, k, k / n if n else float("nan"))


@dataclass(frozen=True, slots=True)
class Reliability:
    """Outcome of the per-opportunity protocol (module docstring).

    Attributes
    ----------
    n_opportunities : int
        Frames with a tag truly in view within ``range_m``.
    n_fix_accepted : int
        Of those, frames with at least one accepted fix (of the population's estimator).
    n_success : int
        Of those, frames whose pose right after was within tolerance.
    fraction : float
        ``n_success / n_opportunities`` (NaN with no opportunity).
    range_m, position_tol_m, rotation_tol_deg : float
        The protocol's ``Z``, ``X``, ``Y``.
    in_map, in_cab : Population
        The map's opportunities, judged against ``map``; the cab-only ones, judged against the
        cab (the counts above are their sums).
    """

    n_opportunities: int
    n_fix_accepted: int
    n_success: int
    fraction: float
    range_m: float
    position_tol_m: float
    rotation_tol_deg: float
    in_map: Population
    in_cab: Population


def rows_after(
    stamps_ns: npt.NDArray[np.int64], event_stamps_ns: npt.ArrayLike
) -> npt.NDArray[np.intp]:
    """Index of the first odometry row at or after each stamp (clipped to the last row)."""
    rows = np.searchsorted(stamps_ns, np.asarray(event_stamps_ns, dtype=np.int64), side="left")
    return np.minimum(rows, len(stamps_ns) - 1).astype(np.intp)


def within_tolerance(
    errors: PoseErrors, position_tol_m: float, rotation_tol_deg: float
) -> npt.NDArray[np.bool_]:
    """Per stamp: position error <= ``position_tol_m`` and rotation <= ``rotation_tol_deg``."""
    return (errors.translation_m <= position_tol_m) & (errors.rotation_deg <= rotation_tol_deg)


def reliability_protocol(
    frames: Sequence[CameraFrameRecord],
    stamps_ns: npt.NDArray[np.int64],
    errors: PoseErrors,
    config: EvalConfig,
    *,
    accepted_per_frame: Sequence[int] | None = None,
    cab_frames: Iterable[str] = (),
    cab: CabErrors | None = None,
) -> Reliability:
    """Count opportunities and successes (module docstring).

    Parameters
    ----------
    frames : sequence of CameraFrameRecord
    stamps_ns : (N,) int64
        Odometry stamps of the estimate.
    errors : PoseErrors
        Error of the published ``T_map_base`` against truth at ``stamps_ns``.
    config : EvalConfig
    accepted_per_frame : sequence of int, optional
        Fixes accepted per frame, to score another estimator (the baseline) on the same frames;
        default :attr:`CameraFrameRecord.n_fixes_accepted`.
    cab_frames : iterable of str
        The tag map's cab frames (default ``cab.cab_frames``; none: every opportunity is the
        map's).
    cab : CabErrors, optional
        The estimate relative to the cab; None: no such estimate, every cab opportunity is a
        miss (the baseline has none).
    """
    Z = config.opportunity_range_m
    cabs = frozenset(cab_frames) | (cab.cab_frames if cab is not None else frozenset())
    accepted = (
        np.array([f.n_fixes_accepted for f in frames])
        if accepted_per_frame is None
        else np.asarray(accepted_per_frame)
    )
    nearest_m = np.array([f.nearest_visible_tag_m for f in frames], dtype=np.float64)
    opportunity = nearest_m <= Z
    in_cab = opportunity & np.array(
        [bool(cabs and f.nearest_by_frame) and f.nearest_in(cabs, inside=False) > Z
         for f in frames], dtype=bool,
    )  # fmt: skip
    ok = within_tolerance(errors, config.position_tol_m, config.rotation_tol_deg)
    rows = rows_after(stamps_ns, [f.stamp_ns for f in frames])
    fix_accepted = accepted > 0
    success = fix_accepted & ok[rows] if len(frames) else fix_accepted
    in_map = opportunity & ~in_cab
    row_stamps = stamps_ns[rows] if len(frames) else np.zeros(0, dtype=np.int64)
    cab_accepted, cab_ok = cab_successes(
        frames, in_cab, row_stamps, cab, config.position_tol_m, config.rotation_tol_deg
    )
    fix_accepted = np.where(in_cab, cab_accepted, fix_accepted)
    success = np.where(in_cab, cab_ok, success)
    n = int(np.count_nonzero(opportunity))
    n_success = int(np.count_nonzero(opportunity & success))
    return Reliability(
        n_opportunities=n,
        n_fix_accepted=int(np.count_nonzero(opportunity & fix_accepted)),
        n_success=n_success,
        fraction=n_success / n if n else float("nan"),
        range_m=Z,
        position_tol_m=config.position_tol_m,
        rotation_tol_deg=config.rotation_tol_deg,
        in_map=Population.count(in_map, fix_accepted, success),
        in_cab=Population.count(in_cab, fix_accepted, success),
    )


@dataclass(frozen=True, slots=True)
class KidnapRecovery:
    """Relocalization after one kidnap (stamps in ns; -1 / NaN when it did not happen).

    Attributes
    ----------
    kidnap_ns : int
    first_sighting_ns : int
        First frame after the kidnap with a tag truly in view and at least one detection.
    relocalized_ns : int
        First accepted fix after the kidnap with the published pose right after within tolerance.
    time_to_relocalize_s : float
        ``relocalized_ns - first_sighting_ns`` in seconds (NaN if either is missing).
    """

    kidnap_ns: int
    first_sighting_ns: int
    relocalized_ns: int
    time_to_relocalize_s: float


def relocalization_times(
    kidnaps_ns: Sequence[int],
    frames: Sequence[CameraFrameRecord],
    fixes: Sequence[FixAttempt],
    stamps_ns: npt.NDArray[np.int64],
    errors: PoseErrors,
    config: EvalConfig,
) -> list[KidnapRecovery]:
    """One :class:`KidnapRecovery` per kidnap; the search for each ends at the next kidnap."""
    ok = within_tolerance(errors, config.position_tol_m, config.rotation_tol_deg)
    starts = sorted(int(k) for k in kidnaps_ns)
    ends = [*starts[1:], int(np.iinfo(np.int64).max)]
    out = []
    for kidnap, end in zip(starts, ends[: len(starts)], strict=True):
        sighting = next(
            (
                f.stamp_ns
                for f in frames
                if kidnap <= f.stamp_ns < end
                and np.isfinite(f.nearest_visible_tag_m)
                and f.n_detections > 0
            ),
            -1,
        )
        candidates = sorted(
            a.stamp_ns for a in fixes if a.accepted and a.in_map and kidnap <= a.stamp_ns < end
        )
        good = [
            s for s, r in zip(candidates, rows_after(stamps_ns, candidates), strict=True) if ok[r]
        ]
        relocalized = good[0] if good else -1
        seconds = (
            (relocalized - sighting) * 1e-9 if sighting >= 0 and relocalized >= 0 else float("nan")
        )
        out.append(KidnapRecovery(int(kidnap), int(sighting), int(relocalized), seconds))
    return out
