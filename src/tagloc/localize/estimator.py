"""``MapOdomEstimator``: the ``map -> odom`` correction as an iterated error-state EKF on SE(3).

The estimator is the state and its arithmetic: it applies what it is given. What it is given
(the gates, start-up, gaps, kidnap, suspect sources, the capped publication) is decided by
:class:`~tagloc.localize.policy.FixPolicy`; :class:`~tagloc.localize.filter.MapOdomFilter`
composes the two.

State: ``X = T_map_odom`` and, with odometry calibration (:mod:`tagloc.localize.motion`), its
parameters ``c = [scale, lateral, yaw_per_m, yaw_scale]``; error state ``[dx, dc]`` with
covariance ``P`` ((d + 4, d + 4); (d, d) without calibration), ``X_true = X @ Exp(dx)``,
``c_true = c + dc``, ``dx`` in the right tangent of ``X`` ordered ``[x, y, z, rx, ry, rz]``
(d = 6). Planar mode estimates ``(x, y, yaw)`` on SE(2) (d = 3, ``[x, y, theta]``): z, roll and
pitch of ``T_map_odom`` stay 0 and a fix enters as its planar projection
(:meth:`Candidate.of_fix <tagloc.localize.candidate.Candidate.of_fix>`). The odometry
``A = T_odom_base(t)`` comes from a :class:`~tagloc.frames.TransformBuffer` the caller fills.

- Prediction over the odometry path, ``X <- X (+) M c``, ``P <- F P F^T + Q``:
  :mod:`tagloc.localize.odometry_path`.
- The iterated update, late fixes (compared with the state moved back to their stamp) and
  partial fixes (the Schmidt gain): :mod:`tagloc.localize.iekf`.
"""

from __future__ import annotations

import numpy as np

from tagloc._types import FloatArray
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE2, SE3
from tagloc.localize.candidate import Candidate, Pose
from tagloc.localize.config import CalibrationConfig, FilterConfig, ProcessNoiseConfig
from tagloc.localize.config_tags import FramesConfig
from tagloc.localize.fix import (
    LocalizeError,
    PoseWithCovariance,
    check_covariance,
    planar_projection_jacobian,
)
from tagloc.localize.iekf import Innovation, innovate, iterated_update
from tagloc.localize.motion import N_CALIBRATION, CalibrationModel, PathMotion, ProcessNoise
from tagloc.localize.odometry_path import OdometryPath

__all__ = ["PLANAR_AXES", "MapOdomEstimator"]

PLANAR_AXES = [0, 1, 5]  # x, y, rz of [x, y, z, rx, ry, rz]


class MapOdomEstimator:
    """The state ``T_map_odom`` (and the odometry calibration), its covariance and its updates.

    Parameters
    ----------
    buffer : TransformBuffer
        Holds the odometry edge ``odom_frame -> base_frame`` (the caller inserts it).
    map_frame, odom_frame, base_frame : str
    planar : bool
        Estimate x, y, yaw only (z, roll, pitch of ``T_map_odom`` stay 0).
    noise : ProcessNoise
    calibration : CalibrationModel, optional
        Estimate the odometry's calibration with the state; None: a pure random walk.
    max_iterations : int
    relinearize_tol : float
        Iterated update: relinearize while the step seen at the base exceeds this (m or rad).

    Attributes
    ----------
    dof : int
        Pose tangent size: 6, or 3 planar.
    path : OdometryPath
        The odometry lookups and path integrals the estimator uses.
    revision : int
        Counts the changes of the state (a prediction, an applied fix, a reset, added noise):
        what is computed from the state stays valid while it is unchanged.
    """

    def __init__(
        self, buffer: TransformBuffer, *, map_frame: str, odom_frame: str, base_frame: str,
        planar: bool, noise: ProcessNoise, calibration: CalibrationModel | None = None,
        max_iterations: int, relinearize_tol: float,
    ) -> None:  # fmt: skip
        self.map_frame, self.base_frame = map_frame, base_frame
        self.planar = planar
        self.dof = 3 if planar else 6
        self.path = OdometryPath(buffer, odom_frame, base_frame, noise, planar, calibration)
        self._calib = calibration
        self._nc = N_CALIBRATION if calibration is not None else 0
        self._max_iter, self._tol = max_iterations, relinearize_tol
        self._X: Pose | None = None
        self._c = np.zeros(self._nc)  # odometry calibration (module motion)
        n = self.dof + self._nc  # error-state size: pose tangent, then calibration
        self._P = np.zeros((n, n))
        if calibration is not None:
            self._P[self.dof :, self.dof :] = np.diag(calibration.prior_var)
        self._stamp = self._updated_ns = 0  # predicted to; last fix applied at
        self._A = SE3.identity()  # T_odom_base at the state's stamp
        self._odometer_m = 0.0
        self.revision = 0

    @classmethod
    def from_config(
        cls, buffer: TransformBuffer, frames: FramesConfig, process_noise: ProcessNoiseConfig,
        calibration: CalibrationConfig, filter: FilterConfig,
    ) -> MapOdomEstimator:  # fmt: skip
        """Build from the sections of ``localizer.yaml`` (:meth:`ProcessNoise.from_config
        <tagloc.localize.motion.ProcessNoise.from_config>`, :meth:`CalibrationModel.from_config
        <tagloc.localize.motion.CalibrationModel.from_config>`)."""
        return cls(
            buffer, map_frame=frames.map_frame, odom_frame=frames.odom_frame,
            base_frame=frames.base_frame, planar=filter.planar,
            noise=ProcessNoise.from_config(process_noise, filter.planar),
            calibration=CalibrationModel.from_config(calibration),
            max_iterations=filter.max_iterations, relinearize_tol=filter.relinearize_tol,
        )  # fmt: skip

    # ----- the state -------------------------------------------------------------------------
    @property
    def initialized(self) -> bool:
        """True once the state exists (:meth:`initialize` or :meth:`reset`)."""
        return self._X is not None

    @property
    def stamp_ns(self) -> int:
        """Stamp the state was last predicted to (ns)."""
        return self._stamp

    @property
    def odom(self) -> SE3:
        """``T_odom_base`` at :attr:`stamp_ns`."""
        return self._A

    @property
    def odometer_m(self) -> float:
        """Distance the odometry travelled over the predictions so far, m."""
        return self._odometer_m

    @property
    def pose(self) -> Pose:
        """The estimate in the estimator's group: ``T_map_odom`` on SE(3), or SE(2) planar.
        Raises ``LocalizeError`` before initialization."""
        if self._X is None:
            raise LocalizeError(
                "the map -> odom filter is not initialized: it needs k consistent fixes "
                "(or initialize())"
            )
        return self._X

    @property
    def T_map_odom(self) -> SE3:
        """The estimate on SE(3) (planar: z, roll, pitch 0). Raises ``LocalizeError`` before
        initialization."""
        return _lift(self.pose)

    @property
    def covariance(self) -> FloatArray:
        """``(6, 6)`` right-tangent covariance of :attr:`T_map_odom`, ``[x, y, z, rx, ry, rz]``
        (planar: zero rows and columns for z, rx, ry)."""
        self.pose  # noqa: B018  (raises before initialization)
        return _embed(self.planar, self._P[: self.dof, : self.dof])

    @property
    def odometry_calibration(self) -> tuple[FloatArray, FloatArray] | None:
        """The estimated odometry calibration ``[scale, lateral, yaw_per_m (rad/m), yaw_scale]``
        and its 1-sigma (see :mod:`tagloc.localize.motion`), or None when not estimated."""
        if self._calib is None:
            return None
        sigma = np.sqrt(np.diag(self._P)[self.dof :])
        return self._c.copy(), sigma

    # ----- setting and predicting ------------------------------------------------------------
    def initialize(self, stamp_ns: int, T_map_odom: SE3, cov: FloatArray) -> None:
        """Set an explicit prior ``T_map_odom`` with its ``(6, 6)`` covariance (planar: its x,
        y, yaw, the covariance projected). Raises ``LocalizeError`` on a bad covariance,
        ``TransformLookupError`` without odometry at ``stamp_ns``."""
        cov6 = check_covariance(cov, 6, "initialize: cov")
        A = self.path.lookup(stamp_ns)
        if self.planar:
            J = planar_projection_jacobian(T_map_odom)
            self.reset(stamp_ns, A, SE2.from_se3(T_map_odom), J @ cov6 @ J.T)
        else:
            self.reset(stamp_ns, A, T_map_odom, cov6)

    def reset(self, stamp_ns: int, odom: SE3, X: Pose, P: FloatArray) -> None:
        """A new pose state ``X`` (the estimator's group) at ``stamp_ns`` with odometry ``odom``
        and ``P`` its ``(dof, dof)`` covariance; the odometry calibration is kept (it belongs
        to the odometry, not to the pose), its correlation with the pose dropped."""
        n = self.dof + self._nc
        full = np.zeros((n, n))
        full[: self.dof, : self.dof] = P
        full[self.dof :, self.dof :] = self._P[self.dof :, self.dof :]
        self._X, self._P, self._stamp, self._A = X, full, stamp_ns, odom
        self._updated_ns = stamp_ns
        self.revision += 1

    def predict(self, stamp_ns: int, odom: SE3 | None = None) -> PathMotion:
        """Predict over the odometry path from the state's stamp to ``stamp_ns`` (``odom``: its
        ``T_odom_base``, looked up if None): ``X <- X (+) M c``, ``P <- F P F^T + Q``. Returns
        the path's motion (a pose that drifts with the state moves by :meth:`drifted`).
        Raises ``LocalizeError`` before initialization or for a stamp older than the state's,
        ``TransformLookupError`` if the odometry at ``stamp_ns`` is not buffered."""
        X = self.pose
        if stamp_ns < self._stamp:
            raise LocalizeError(f"predict: {stamp_ns} ns is before the state ({self._stamp} ns)")
        A = self.path.lookup(stamp_ns) if odom is None else odom
        motion = self.path.motion(self._stamp, stamp_ns, self._A, A)
        self._P = self.path.predicted(self._P, motion)
        if self._nc:
            self._X = self.drifted(X, motion)
        self._stamp, self._A = stamp_ns, A
        self._odometer_m += motion.distance_m
        self.revision += 1
        return motion

    def drifted(self, X: Pose, motion: PathMotion) -> Pose:
        """``X (+) M c``: a correction moved by the calibrated odometry over ``motion`` (``X``
        unchanged without calibration)."""
        if not self._nc:
            return X
        return X.plus(motion.M @ self._c)

    def add_process_noise(self, Q: FloatArray) -> None:
        """Add ``Q`` ((6, 6), symmetric positive semi-definite, ``[x, y, z, rx, ry, rz]``) to the
        covariance of ``T_map_odom`` now (planar: its x, y, yaw block); nothing before
        initialization. Raises ``LocalizeError`` unless ``Q`` is (6, 6), finite, symmetric."""
        if self._X is None:
            return
        Q6 = np.asarray(Q, dtype=np.float64)
        if Q6.shape != (6, 6) or not np.isfinite(Q6).all() or not np.allclose(Q6, Q6.T):
            raise LocalizeError("add_process_noise: Q must be a finite symmetric (6, 6) matrix")
        block = Q6[np.ix_(PLANAR_AXES, PLANAR_AXES)] if self.planar else Q6
        self._P[: self.dof, : self.dof] += block
        self.revision += 1

    # ----- reading ---------------------------------------------------------------------------
    def pose_at(self, stamp_ns: int, correction: Pose | None = None) -> PoseWithCovariance:
        """``T_map_base = T_map_odom @ T_odom_base(stamp_ns)`` with covariance.

        The state predicted to ``stamp_ns`` (either way in time) over the odometry path from
        its stamp: ``T_map_base = (X (+) M c) @ A``, ``cov = Ad(A^-1) P' Ad(A^-1)^T`` with
        ``P'`` the pose block of ``F P F^T + Q`` (``F = [[I, M], [0, I]]``, ``Q`` the random
        walk between the two stamps; without calibration ``P + Q``). ``correction`` (the
        estimator's group): compose it, drifted the same way, instead of the estimate (same
        covariance; e.g. the published correction). Raises ``LocalizeError`` before
        initialization, ``TransformLookupError`` if the odometry at ``stamp_ns`` (or on the
        path to it) is not buffered."""
        X = self.pose
        A3 = self.path.lookup(stamp_ns)
        motion = self.path.motion(self._stamp, stamp_ns, self._A, A3)
        P = self.path.predicted(self._P, motion)[: self.dof, : self.dof]
        if correction is not None:
            X = correction
        X = self.drifted(X, motion)
        J = A3.inverse().adjoint()
        cov = J @ _embed(self.planar, P) @ J.T
        return PoseWithCovariance(
            stamp_ns, self.map_frame, self.base_frame, _lift(X) @ A3, 0.5 * (cov + cov.T)
        )

    def T_map_base_at(self, stamp_ns: int) -> SE3:
        """``T_map_base`` at ``stamp_ns`` from the estimate, without its covariance (cheaper than
        :meth:`pose_at`). Raises as :meth:`pose_at`."""
        X = self.pose
        A3 = self.path.lookup(stamp_ns)
        if self._nc and stamp_ns != self._stamp:
            X = self.drifted(X, self.path.motion(self._stamp, stamp_ns, self._A, A3))
        return _lift(X) @ A3

    # ----- fixes -----------------------------------------------------------------------------
    def innovation(self, cand: Candidate, *, late: bool = True) -> Innovation:
        """The fix ``cand`` linearized at the state: innovation, Jacobian, ``S^-1``, ``d2``
        (:class:`~tagloc.localize.iekf.Innovation`). A fix older than the state is compared
        with the state moved back to its stamp (:func:`~tagloc.localize.iekf.innovate`);
        ``late=False`` compares it with the state as it is. Raises ``LocalizeError`` before
        initialization."""
        X = self.pose
        back = Q_back = None
        if late and cand.stamp_ns < self._stamp:  # the path back to the fix's stamp
            back = self.path.motion(self._stamp, cand.stamp_ns, self._A, cand.odom)
            Q_back = self.path.full_noise(back)
        only_predicted = self._updated_ns <= cand.stamp_ns
        return innovate(cand, X, self._c, self._P, back, Q_back, only_predicted)

    def update(
        self, cand: Candidate, innov: Innovation | None = None, *, newest: bool = True
    ) -> None:
        """Apply a full fix (:func:`~tagloc.localize.iekf.iterated_update`); ``innov``: its
        :meth:`innovation` at the current state (computed if None). ``newest=False`` keeps the
        stamp of the newest applied fix as it is (the fixes of a restart after the first;
        a later late fix older than that stamp is updated conservatively). Raises
        ``LocalizeError`` before initialization or for a partial fix."""
        if cand.basis is not None:
            raise LocalizeError("update: a partial fix enters through update_partial")
        self._apply(cand, innov, newest)

    def update_partial(self, cand: Candidate, innov: Innovation | None = None) -> None:
        """Apply a partial fix (:meth:`Candidate.of_partial
        <tagloc.localize.candidate.Candidate.of_partial>`): the iterated update with the
        Schmidt gain, which never moves the estimate along an unmeasured direction
        (:mod:`tagloc.localize.projected_update`). Raises ``LocalizeError`` before
        initialization or for a full fix."""
        if cand.basis is None:
            raise LocalizeError("update_partial: a full fix enters through update")
        self._apply(cand, innov, True)

    def _apply(self, cand: Candidate, innov: Innovation | None, newest: bool) -> None:
        if innov is None:
            innov = self.innovation(cand)
        self._X, self._c, self._P = iterated_update(
            cand, innov, self.pose, self._c, self._P, max_iterations=self._max_iter,
            tol=self._tol, calibration=self._calib,
        )  # fmt: skip
        self.revision += 1
        if newest:
            self._updated_ns = max(self._updated_ns, cand.stamp_ns)


def _lift(X: Pose) -> SE3:
    return X.to_se3() if isinstance(X, SE2) else X


def _embed(planar: bool, P: FloatArray) -> FloatArray:
    """A pose covariance as ``(6, 6)`` ``[x, y, z, rx, ry, rz]`` (planar: zeros off the plane)."""
    if not planar:
        return P.copy()
    out = np.zeros((6, 6))
    out[np.ix_(PLANAR_AXES, PLANAR_AXES)] = P
    return out
