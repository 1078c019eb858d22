"""The odometry path between two stamps, as the ``map -> odom`` estimator integrates it.

:class:`OdometryPath` reads ``T_odom_base`` from a :class:`~tagloc.frames.TransformBuffer` (the
caller inserts the ``odom -> base`` samples) and integrates the path between two stamps in steps
of the process noise's ``step_ns`` (:class:`~tagloc.localize.motion.ProcessNoise`): the random
walk ``Q``, the distance travelled and, with odometry calibration, the drift ``M`` per unit
calibration (:class:`~tagloc.localize.motion.PathMotion`).

Prediction: a random walk driven by motion plus the calibration drift
    Over the odometry path between two stamps (increments ending at ``A_k``): a random error
    ``n_k`` of an increment moves the correction by ``X <- X @ Exp(Ad(A_k) n_k)``, giving the
    walk ``Q_x = sum_k Ad(A_k) Q_k Ad(A_k)^T``; the calibration moves it by ``M c``,
    ``M = sum_k Ad(A_k) G_k``. So ``X <- X (+) M c``, ``c`` unchanged, and
    ``P <- F P F^T + Q`` with ``F = [[I, M], [0, I]]`` and ``Q = diag(Q_x, Q_c)`` (``Q_c``: the
    calibration's own walk per metre travelled; :meth:`OdometryPath.predicted`). Without
    calibration ``P <- P + Q_x``.

Two reuses keep a camera frame cheap (its prior and its first fix ask for the same things): the
last lookup is reused while the buffer is unchanged (its ``revision``), and the last path while
its stamps, end poses and the buffer are.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from tagloc._types import FloatArray
from tagloc.errors import TransformLookupError
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize.candidate import Candidate
from tagloc.localize.motion import N_CALIBRATION, CalibrationModel, PathMotion, ProcessNoise

__all__ = ["OdometryPath"]

logger = logging.getLogger(__name__)


class OdometryPath:
    """``T_odom_base`` lookups and path integrals over a transform buffer (module docstring).

    Parameters
    ----------
    buffer : TransformBuffer
        Holds the edge ``odom_frame -> base_frame``.
    odom_frame, base_frame : str
    noise : ProcessNoise
    planar : bool
        Integrate on SE(2) (the projections of the odometry poses).
    calibration : CalibrationModel, optional
        With it the paths carry the drift ``M`` and :meth:`full_noise` the calibration's walk.
    """

    def __init__(
        self, buffer: TransformBuffer, odom_frame: str, base_frame: str, noise: ProcessNoise,
        planar: bool, calibration: CalibrationModel | None = None,
    ) -> None:  # fmt: skip
        self.buffer, self.odom_frame, self.base_frame = buffer, odom_frame, base_frame
        self.noise, self.planar, self.calibration = noise, planar, calibration
        self._dof = 3 if planar else 6
        self._F: FloatArray | None = None  # predicted(): F = [[I, M], [0, I]], M set per call
        self._looked_up: tuple[tuple[int, int], SE3] | None = None  # (stamp, revision), value
        # the last path: ((t_from, t_to, buffer revision, drift), A_from, A_to, result)
        self._last_path: tuple[tuple[int, int, int, bool], SE3, SE3, PathMotion] | None = None

    def lookup(self, stamp_ns: int) -> SE3:
        """``T_odom_base`` at ``stamp_ns``; the last one is reused while the buffer is unchanged.

        Raises
        ------
        TransformLookupError
            If the odometry at ``stamp_ns`` is not buffered.
        """
        key = (stamp_ns, self.buffer.revision)
        if self._looked_up is not None and self._looked_up[0] == key:
            return self._looked_up[1]
        odom = self.buffer.lookup(self.odom_frame, self.base_frame, stamp_ns)
        self._looked_up = (key, odom)
        return odom

    def motion(
        self, t_from: int, t_to: int, A_from: SE3, A_to: SE3, *, drift: bool = True
    ) -> PathMotion:
        """:class:`PathMotion` of the odometry path from ``t_from`` (odometry ``A_from``) to
        ``t_to`` (``A_to``), either order: the drift ``M`` is negated for a path back in time;
        ``Q`` is the walk between them. ``M`` is computed only with calibration and ``drift``
        (else ``(d, 0)``). The last result is reused for the same stamps, end poses (the same
        objects) and buffer revision.

        A stretch of the path the buffer no longer holds is replaced by its chord (logged)."""
        drift = drift and self.calibration is not None
        key = (t_from, t_to, self.buffer.revision, drift)
        last = self._last_path
        if last is not None and last[0] == key and last[1] is A_from and last[2] is A_to:
            return last[3]
        motion = self._integrate(t_from, t_to, A_from, A_to, drift)
        self._last_path = (key, A_from, A_to, motion)
        return motion

    def _integrate(self, t_from: int, t_to: int, A_from: SE3, A_to: SE3, drift: bool) -> PathMotion:
        """:meth:`motion` without the reuse."""
        (lo, A_lo), (hi, A_hi) = sorted(((t_from, A_from), (t_to, A_to)), key=lambda p: p[0])
        R_lo, t_lo = A_lo.rotation.matrix, A_lo.translation
        R_hi, t_hi = A_hi.rotation.matrix, A_hi.translation
        n = math.ceil((hi - lo) / self.noise.step_ns)
        motion = None
        if n > 1:
            inner = lo + np.round(np.arange(1, n) * ((hi - lo) / n)).astype(np.int64)
            try:
                mid = self.buffer.lookup_many(self.odom_frame, self.base_frame, inner)
            except TransformLookupError as exc:
                logger.warning("odometry path %d..%d ns not buffered (%s): chord used", lo, hi, exc)
            else:
                stamps = np.concatenate([[lo], inner, [hi]])
                R = np.concatenate([R_lo[None], mid.rotation.matrix, R_hi[None]])
                t = np.concatenate([t_lo[None], mid.translation, t_hi[None]])
                motion = self.noise.path(stamps, R, t, self.planar, drift)
        if motion is None:
            motion = self.noise.increment(hi - lo, R_lo, t_lo, R_hi, t_hi, self.planar, drift)
        if t_to < t_from and drift:
            motion = PathMotion(motion.Q, motion.distance_m, -motion.M)
        return motion

    def pair_noise(self, a: Candidate, b: Candidate) -> FloatArray:
        """Random-walk covariance of the odometry path between two fixes (their ``Q_ij``)."""
        return self.motion(a.stamp_ns, b.stamp_ns, a.odom, b.odom, drift=False).Q

    def full_noise(self, motion: PathMotion) -> FloatArray:
        """Process noise of the whole state ``[pose, calibration]`` over ``motion``: the pose
        walk and, with calibration, the calibration's own walk per metre travelled."""
        if self.calibration is None:
            return motion.Q
        dof = self._dof
        n = dof + N_CALIBRATION
        Q = np.zeros((n, n))
        Q[:dof, :dof] = motion.Q
        Q[dof:, dof:] = np.diag(self.calibration.var_per_m * motion.distance_m)
        return Q

    def predicted(self, P: FloatArray, motion: PathMotion) -> FloatArray:
        """``F P F^T + Q`` with ``F = [[I, M], [0, I]]`` (the calibration drives the pose;
        without calibration ``P + Q``). ``F`` is kept between calls (only ``M`` changes) and
        ``Q`` added in place by blocks: the same floating-point operations as building both."""
        calibration = self.calibration
        if calibration is None:
            plain: FloatArray = P + motion.Q
            return plain
        d, n = self._dof, len(P)
        F = self._F
        if F is None or len(F) != n:
            F = self._F = np.eye(n)
        F[:d, d:] = motion.M
        out: FloatArray = F @ P @ F.T
        out[:d, :d] += motion.Q
        out[d:, d:] += np.diag(calibration.var_per_m * motion.distance_m)
        return out
