"""The mounting check of every camera of a rig, from the node's outputs, in bounded memory.

:class:`ExtrinsicRecorder` is a node sink: it keeps the odometry of a recent window and, per
camera (:attr:`~tagloc.localize.run.FixAttempt.camera`), the accepted fixes with the odometry
at their stamps. :meth:`ExtrinsicRecorder.check_by_camera` runs
:func:`~tagloc.localize.extrinsic_check.check_fixes` on each camera's own fixes with its own
extrinsics, so a camera mis-set on a rig is named, and the others are not blamed for it.

Memory does not grow with the drive: each camera keeps at most ``max_fixes`` fixes. Past them
it keeps the fixes of every second ``block_s`` block only, then of every fourth, and so on
(:func:`~tagloc.localize.extrinsic_check.thinned`: whole blocks, so the pairs and the
clusters within a kept block are as they were; the kept blocks span the whole drive). The
check's fit then never sees more than ``max_fixes`` fixes a camera either.

What the odometry, the map or the base frame's placement get wrong, every camera's check finds
alike; a camera's own mis-set only its own. Where two cameras see one tag at the same instant,
their relative mounting is measured without the odometry: ``T_cam0_cam1 = T_map_cam0^-1 @
T_map_cam1`` from the two fixes (the tag's surveyed pose cancels), against the calibration's
``T_base_cam0^-1 @ T_base_cam1`` (:func:`relative_mounting`: the mean of the tags' median
corrections, its covariance from the spread over tags, Hotelling's test over the tags). When it
agrees, a mis-set of one of the two alone is ruled out, and the warnings of both are withdrawn
in favour of one line for the rig (:func:`rig_verdicts`): on the dupont stereo drive the two
cameras' checks find the same correction in the base frame (0.3 deg, 9-10 cm), while their
relative mounting agrees with the calibration to 0.01 deg and 0.2 cm.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.localize.extrinsic_check import (
    BLOCK_S,
    MAX_FIXES,
    ExtrinsicCheck,
    check_fixes,
    odometry_at,
    pose_rows,
    poses_of,
    tag_key,
)
from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.localize.run import FixAttempt
from tagloc.units import S_NS

__all__ = [
    "ExtrinsicRecorder",
    "RelativeMounting",
    "RigVerdict",
    "relative_mounting",
    "rig_verdicts",
]

#: One accepted fix as a store keeps it (its stamp aside): range, ``T_map_base`` (rotation
#: matrix, translation), its covariance, the odometry ``T_odom_base`` at its stamp, its tag.
_ROW = 1 + 12 + 36 + 12 + 1


class _FixStore:
    """One camera's accepted fixes, at most ``max_fixes`` (module docstring)."""

    def __init__(self, max_fixes: int, block_s: float) -> None:
        self.max_fixes, self._block_ns = max_fixes, max(round(block_s * S_NS), 1)
        self.rows = np.empty((0, _ROW))
        self.stamps = np.empty(0, dtype=np.int64)
        self.n = self.level = 0

    def _kept(self, stamps: npt.NDArray[np.int64]) -> npt.NDArray[np.bool_]:
        return np.asarray((stamps // self._block_ns) % (1 << self.level) == 0)

    def keyed(self) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], SE3]:
        """The stamps, tags and ``T_map_base`` of the fixes held."""
        rows = self.rows[: self.n]
        return self.stamps[: self.n], rows[:, 61].astype(np.int64), poses_of(rows[:, 1:13])

    def add(self, stamp_ns: int, row: FloatArray) -> None:
        stamp = np.array([stamp_ns], dtype=np.int64)
        while self._kept(stamp)[0] and self.n >= self.max_fixes:
            if self.level >= 62:
                return
            self.level += 1  # thin: keep every other block of those kept
            keep = np.flatnonzero(self._kept(self.stamps[: self.n]))
            self.rows[: len(keep)], self.stamps[: len(keep)] = self.rows[keep], self.stamps[keep]
            self.n = len(keep)
        if not self._kept(stamp)[0]:
            return
        if self.n == len(self.stamps):
            size = min(max(2 * self.n, 256), self.max_fixes)
            self.rows = np.resize(self.rows, (size, _ROW))
            self.stamps = np.resize(self.stamps, size)
        self.rows[self.n], self.stamps[self.n] = row, stamp_ns
        self.n += 1


class ExtrinsicRecorder:
    """A node sink keeping what the mounting check of each camera needs (module docstring).

    Fix records reach the sinks a few seconds after their stamps (once no batch decision can
    revise them), so the recorder keeps the odometry of the last ``odometry_window`` to twice
    that many samples (100-200 s at 200 Hz) in arrays and, for each accepted fix, one row of 62
    numbers (the fix's pose and covariance, the odometry interpolated at its stamp, its tag).
    :attr:`held` counts what it holds.
    """

    def __init__(
        self, max_fixes: int = MAX_FIXES, odometry_window: int = 20_000,
        block_s: float = BLOCK_S,
    ) -> None:  # fmt: skip
        self.max_fixes, self._window, self._block_s = max_fixes, odometry_window, block_s
        self._stores: dict[str, _FixStore] = {}
        self._stamps = np.empty(0, dtype=np.int64)
        self._odom = np.empty((0, 12))
        self._m = 0  # odometry samples held

    @property
    def held(self) -> dict[str, int]:
        """What the recorder holds: accepted fixes (all cameras), odometry samples, numbers
        allocated, and the thinning level (the most thinned camera's)."""
        stores = self._stores.values()
        numbers = sum(s.rows.size + s.stamps.size for s in stores) + 13 * len(self._stamps)
        return {"fixes": sum(s.n for s in stores), "odometry": self._m, "numbers": numbers,
                "thinning": max((s.level for s in stores), default=0)}  # fmt: skip

    @property
    def cameras(self) -> tuple[str, ...]:
        """The cameras whose accepted fixes were recorded, in the order first seen."""
        return tuple(self._stores)

    def write(self, output: NodeOutput) -> None:
        if isinstance(output, Estimate):
            self._odometry(output)
        elif isinstance(output, FixAttempt) and output.accepted and self._m:
            store = self._stores.get(output.camera)
            if store is None:
                store = self._stores[output.camera] = _FixStore(self.max_fixes, self._block_s)
            row = np.empty(_ROW)
            row[0] = output.range_m
            row[1:13] = pose_rows(output.T_map_base)
            row[13:49] = np.asarray(output.cov, dtype=np.float64).ravel()
            # the odometry at the fix: between the two samples around its stamp
            i = int(np.searchsorted(self._stamps[: self._m], output.stamp_ns, side="right"))
            near = [max(i - 1, 0), min(i, self._m - 1)]
            row[49:61] = pose_rows(odometry_at(
                self._stamps[near], poses_of(self._odom[near]),
                np.array([output.stamp_ns], dtype=np.int64),
            )[0])  # fmt: skip
            row[61] = tag_key(output)
            store.add(output.stamp_ns, row)

    def _odometry(self, e: Estimate) -> None:
        if self._m and e.stamp_ns <= self._stamps[self._m - 1]:
            self._m = 0  # the clock jumped back: the node started over
        if self._m == len(self._stamps):
            if self._m >= 2 * self._window:  # full: keep the newest window
                keep = slice(self._m - self._window, self._m)
                self._stamps[: self._window] = self._stamps[keep]
                self._odom[: self._window] = self._odom[keep]
                self._m = self._window
            else:
                size = min(max(2 * self._m, 1024), 2 * self._window)
                self._stamps = np.resize(self._stamps, size)
                self._odom = np.resize(self._odom, (size, 12))
        self._stamps[self._m] = e.stamp_ns
        self._odom[self._m] = pose_rows(e.T_odom_base)
        self._m += 1

    def check(
        self, T_base_cam: SE3 | None, *, camera: str = "", **options: Any
    ) -> ExtrinsicCheck | None:
        """The check of ``camera`` (``""``: the node's only camera) over what was recorded
        (None without extrinsics or a verdict); ``options`` of
        :func:`~tagloc.localize.extrinsic_check.check_fixes`."""
        store = self._stores.get(camera)
        if T_base_cam is None or store is None or store.n < 2:
            return None
        order = np.argsort(store.stamps[: store.n], kind="stable")
        stamps, rows = store.stamps[: store.n][order], store.rows[: store.n][order]
        options = {"block_s": self._block_s, "max_fixes": self.max_fixes, **options}
        return check_fixes(
            stamps, rows[:, 0], poses_of(rows[:, 1:13]), rows[:, 13:49].reshape(-1, 6, 6),
            poses_of(rows[:, 49:61]), T_base_cam, tag_keys=rows[:, 61].astype(np.int64),
            camera=camera, **options,
        )  # fmt: skip

    def check_by_camera(
        self, T_base_cam_by_camera: Mapping[str, SE3 | None], **options: Any
    ) -> dict[str, ExtrinsicCheck | None]:
        """:meth:`check` of each camera with its extrinsics (None: no verdict)."""
        return {name: self.check(X, camera=name, **options)
                for name, X in T_base_cam_by_camera.items()}  # fmt: skip

    def verdicts(
        self, T_base_cam_by_camera: Mapping[str, SE3 | None], **options: Any
    ) -> tuple[dict[str, RigVerdict], str | None]:
        """Each camera's check and relative mounting, judged together (:func:`rig_verdicts`)."""
        return rig_verdicts(self.check_by_camera(T_base_cam_by_camera, **options),
                            self.relative(T_base_cam_by_camera))  # fmt: skip

    def relative(
        self, T_base_cam_by_camera: Mapping[str, SE3 | None], **options: Any
    ) -> dict[str, RelativeMounting | None]:
        """:func:`relative_mounting` of each camera but the first against the first (None:
        no extrinsics, or too few instants where both saw one tag)."""
        names = [n for n, X in T_base_cam_by_camera.items() if X is not None and n in self._stores]
        out: dict[str, RelativeMounting | None] = {}
        if not names:
            return out
        ref = self._stores[names[0]]
        X_ref = T_base_cam_by_camera[names[0]]
        assert X_ref is not None
        for name in names[1:]:
            X = T_base_cam_by_camera[name]
            assert X is not None
            other = self._stores[name]
            out[name] = relative_mounting(
                names[0], name, *ref.keyed(), *other.keyed(), X_ref, X, **options
            )
        return out


@dataclass(frozen=True, slots=True)
class RelativeMounting:
    """A camera's mounting relative to the reference camera, measured from the instants both
    saw one tag, against the calibration: ``T_ref_cam = T_ref_cam_calibrated @ Exp(xi)``.

    Attributes
    ----------
    reference, camera : str
    xi, sigma : (6,) float
        ``[x, y, z, rx, ry, rz]`` (m, rad) in the camera's frame, and standard deviations.
    n_pairs, n_tags : int
        Simultaneous fixes of one tag used, and their tags (the clusters).
    d2, d2_threshold : float
        Mahalanobis distance squared of ``xi`` from 0 and Hotelling's threshold (``inf`` with
        no more tags than 6).
    warn_rotation_deg, warn_translation_m : float
    """

    reference: str
    camera: str
    xi: FloatArray
    sigma: FloatArray
    n_pairs: int
    n_tags: int
    d2: float
    d2_threshold: float
    warn_rotation_deg: float = 0.5
    warn_translation_m: float = 0.02

    @property
    def agrees(self) -> bool:
        """The calibration holds: the measured difference is not both significant and large
        (and there were enough tags to tell)."""
        large = (math.degrees(float(np.linalg.norm(self.xi[3:]))) > self.warn_rotation_deg
                 or float(np.linalg.norm(self.xi[:3])) > self.warn_translation_m)  # fmt: skip
        return math.isfinite(self.d2_threshold) and not (large and self.d2 > self.d2_threshold)

    def to_dict(self) -> dict[str, Any]:
        axes = ("x", "y", "z", "rx", "ry", "rz")
        return {
            "reference": self.reference, "n_pairs": self.n_pairs, "n_tags": self.n_tags,
            "correction_cam": dict(zip(axes, self.xi.tolist(), strict=True)),
            "sigma_cam": dict(zip(axes, self.sigma.tolist(), strict=True)),
            "d2": self.d2, "d2_threshold": self.d2_threshold, "agrees": self.agrees,
        }  # fmt: skip


def relative_mounting(
    reference: str, camera: str,
    stamps_ref: npt.NDArray[np.int64], tags_ref: npt.NDArray[np.int64], T_map_base_ref: SE3,
    stamps: npt.NDArray[np.int64], tags: npt.NDArray[np.int64], T_map_base: SE3,
    T_base_ref: SE3, T_base_cam: SE3, *, alpha: float = 1e-3, min_pairs: int = 20,
) -> RelativeMounting | None:  # fmt: skip
    """The camera's mounting relative to the reference from their fixes of one tag at one
    stamp (module docstring); None with fewer than ``min_pairs`` such instants."""
    from scipy.stats import f as f_dist

    index = {key: k for k, key in enumerate(zip(stamps_ref.tolist(), tags_ref.tolist(),
                                                strict=True))}  # fmt: skip
    pairs = zip(stamps.tolist(), tags.tolist(), strict=True)
    matches = [(index[key], k) for k, key in enumerate(pairs) if key in index and key[1] >= 0]
    if len(matches) < min_pairs:
        return None
    i, j = (np.array(m) for m in zip(*matches, strict=True))
    T_ref_cam = (T_map_base_ref[i] @ T_base_ref).inverse() @ (T_map_base[j] @ T_base_cam)
    calibrated = T_base_ref.inverse() @ T_base_cam
    delta = (calibrated.inverse() @ T_ref_cam).log()  # (K, 6)
    keys = tags[j]
    medians = np.array([np.median(delta[keys == t], axis=0) for t in np.unique(keys)])
    g = len(medians)
    xi = medians.mean(axis=0)
    cov = np.cov(medians.T) / g if g > 1 else np.full((6, 6), np.inf)
    sigma = np.sqrt(np.diag(cov))
    if g <= 6 or not np.isfinite(cov).all():
        return RelativeMounting(reference, camera, xi, sigma, len(i), g, 0.0, math.inf)
    d2 = float(xi @ np.linalg.pinv(cov) @ xi)
    threshold = float(6 * (g - 1) / (g - 6) * f_dist.ppf(1.0 - alpha, 6, g - 6))
    return RelativeMounting(reference, camera, xi, sigma, len(i), g, d2, threshold)


@dataclass(frozen=True, slots=True)
class RigVerdict:
    """One camera's verdict on a rig: its own check, its relative mounting to the reference
    (None: the reference, or not measured), and the warning that stands (None: none, or
    withdrawn as common to the rig: ``shared``)."""

    check: ExtrinsicCheck | None
    relative: RelativeMounting | None
    warning: str | None
    shared: bool

    def to_dict(self) -> dict[str, Any] | None:
        if self.check is None:
            return None
        return {**self.check.to_dict(), "warning": self.warning, "shared_with_rig": self.shared,
                "own_warning": self.check.warning,
                "relative": None if self.relative is None else self.relative.to_dict()}  # fmt: skip


def rig_verdicts(
    checks: Mapping[str, ExtrinsicCheck | None], relative: Mapping[str, RelativeMounting | None]
) -> tuple[dict[str, RigVerdict], str | None]:
    """Each camera's verdict, and one line for the rig when warnings were withdrawn.

    A camera's warning is withdrawn when its mounting relative to another camera was measured
    and agrees with the calibration (the reference's: when any camera's relative mounting
    agrees): a mis-set of it alone is then ruled out, and what its check found is common to
    the rig (the odometry, the map, or the placement of the base frame)."""
    names = list(checks)
    agreeing = {n for n, r in relative.items() if r is not None and r.agrees}
    if agreeing and names:
        agreeing.add(names[0])
    verdicts: dict[str, RigVerdict] = {}
    withdrawn = []
    for name, check in checks.items():
        own = None if check is None else check.warning
        shared = own is not None and name in agreeing
        if shared:
            withdrawn.append(name)
        verdicts[name] = RigVerdict(check, relative.get(name), None if shared else own, shared)
    line = None
    if withdrawn:
        line = (
            f"the mounting check of {', '.join(withdrawn)} finds a correction the rig's "
            "cameras share (their relative mounting agrees with the calibration): the "
            "odometry, the map or the base frame's placement, not one camera's mounting"
        )
    return verdicts, line
