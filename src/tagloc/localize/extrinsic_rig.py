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

The rig's cameras are judged together (:meth:`ExtrinsicRecorder.verdicts`): each camera's
check beside its mounting relative to the first camera, measured without the odometry
(:mod:`tagloc.localize.extrinsic_relative`).
"""

from __future__ import annotations

from collections.abc import Mapping
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
    tag_key,
)
from tagloc.localize.extrinsic_relative import (
    RelativeMounting,
    RigVerdict,
    relative_mounting,
    rig_verdicts,
)
from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.localize.run import FixAttempt
from tagloc.units import S_NS

__all__ = ["ExtrinsicRecorder"]

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
        return self.stamps[: self.n], rows[:, 61].astype(np.int64), SE3.from_rows(rows[:, 1:13])

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
        elif (
            isinstance(output, FixAttempt) and output.accepted and output.in_map and output.of_tags
            and self._m
        ):  # fmt: skip
            store = self._stores.get(output.camera)
            if store is None:
                store = self._stores[output.camera] = _FixStore(self.max_fixes, self._block_s)
            row = np.empty(_ROW)
            row[0] = output.range_m
            row[1:13] = output.T_map_base.as_rows()
            row[13:49] = np.asarray(output.cov, dtype=np.float64).ravel()
            # the odometry at the fix: between the two samples around its stamp
            i = int(np.searchsorted(self._stamps[: self._m], output.stamp_ns, side="right"))
            near = [max(i - 1, 0), min(i, self._m - 1)]
            row[49:61] = odometry_at(
                self._stamps[near], SE3.from_rows(self._odom[near]),
                np.array([output.stamp_ns], dtype=np.int64),
            )[0].as_rows()  # fmt: skip
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
        self._odom[self._m] = e.T_odom_base.as_rows()
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
            stamps, rows[:, 0], SE3.from_rows(rows[:, 1:13]), rows[:, 13:49].reshape(-1, 6, 6),
            SE3.from_rows(rows[:, 49:61]), T_base_cam, tag_keys=rows[:, 61].astype(np.int64),
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
