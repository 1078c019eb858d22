"""Edits of a simulated drive: a kidnap (the truth skips ahead, the odometry does not:
:class:`SplicedDrive`) and the first seconds of a drive (:func:`truncate_drive`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from tagloc.errors import SimulationError
from tagloc.geometry import SE3
from tagloc.sim.drive import Drive
from tagloc.sim.trajectory import Trajectory
from tagloc.units import S_NS

__all__ = ["SplicedDrive", "truncate_drive"]


@dataclass(frozen=True, slots=True)
class SplicedDrive(Drive):
    """A drive whose ground truth skips ``skip_ns`` of the route from ``kidnap_ns`` on."""

    kidnap_ns: int = 0
    skip_ns: int = 0

    def ground_truth_at(self, stamps_ns: npt.NDArray[np.int64]) -> Trajectory:
        """Truth at ``stamps_ns``: the route's, shifted by ``skip_ns`` from the kidnap on."""
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        shifted = np.where(stamps >= self.kidnap_ns, stamps + self.skip_ns, stamps)
        return self.plan.sample(shifted, self.t0_ns)

    def route_s(self, stamps_ns: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Route time at ``stamps_ns``, shifted by ``skip_ns`` from the kidnap on."""
        stamps = np.atleast_1d(np.asarray(stamps_ns, dtype=np.int64))
        shifted = np.where(stamps >= self.kidnap_ns, stamps + self.skip_ns, stamps)
        return (shifted - np.int64(self.t0_ns)).astype(np.float64) * 1e-9


def _splice(drive: Drive, kidnap_at_s: float, skip_s: float) -> SplicedDrive:
    """Truth from ``kidnap_at`` on is the route ``skip_s`` later; odometry keeps its own path
    (the increments of the skipped-to stretch) without a jump."""
    step = int(drive.stamps_ns[1] - drive.stamps_ns[0])
    k = int(np.searchsorted(drive.stamps_ns, drive.t0_ns + round(kidnap_at_s * S_NS)))
    skip = round(skip_s * S_NS / step)
    n = len(drive.stamps_ns) - skip
    if k >= n:
        raise SimulationError(f"kidnap at {kidnap_at_s} s + {skip_s} s is past the drive's end")
    idx = np.concatenate([np.arange(k), np.arange(k, n) + skip])
    T_odom = drive.T_odom_base
    T_odom_after = T_odom[k - 1] @ T_odom[k - 1 + skip].inverse() @ T_odom[idx[k:]]
    T_odom_base = SE3.stack([*T_odom[:k], *T_odom_after])
    stamps = drive.stamps_ns[:n]
    cams = drive.camera_stamps_ns[drive.camera_stamps_ns <= stamps[-1]]
    return SplicedDrive(
        world=drive.world, stamps_ns=stamps, T_map_base=drive.T_map_base[idx],
        T_odom_base=T_odom_base, camera_stamps_ns=cams, distance_m=drive.distance_m[idx],
        trajectory=drive.trajectory, plan=drive.plan, t0_ns=drive.t0_ns, seed=drive.seed,
        kidnap_ns=int(stamps[k]), skip_ns=skip * step,
    )  # fmt: skip


def truncate_drive(drive: Drive, duration_s: float) -> Drive:
    """The first ``duration_s`` seconds of ``drive`` (odometry, truth and camera stamps)."""
    end = drive.t0_ns + round(duration_s * S_NS)
    n = int(np.searchsorted(drive.stamps_ns, end, side="right"))
    return replace(
        drive,
        stamps_ns=drive.stamps_ns[:n],
        T_map_base=drive.T_map_base[:n],
        T_odom_base=drive.T_odom_base[:n],
        camera_stamps_ns=drive.camera_stamps_ns[drive.camera_stamps_ns <= drive.stamps_ns[n - 1]],
        distance_m=drive.distance_m[:n],
    )
