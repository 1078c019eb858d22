"""``MapOdomFilter``: the ``map -> odom`` correction as an iterated error-state EKF on SE(3).

State and frames
    ``X = T_map_odom`` and, with odometry calibration (the default; :mod:`tagloc.localize.motion`),
    its 4 parameters ``c = [scale, lateral, yaw_per_m, yaw_scale]``. The error state is
    ``[dx, dc]`` with covariance ``P`` ((d + 4, d + 4); (d, d) without calibration):
    ``X_true = X @ Exp(dx)``, ``c_true = c + dc``, ``dx`` in the right tangent of ``X``, ordered
    ``[x, y, z, rx, ry, rz]`` (d = 6). Planar mode estimates ``(x, y, yaw)`` on SE(2) (d = 3,
    ``[x, y, theta]``): z, roll and pitch of ``T_map_odom`` are pinned at 0 and a fix enters as
    its planar projection (:meth:`TagFix.to_planar <tagloc.localize.fix.TagFix.to_planar>`), so
    its z, roll and pitch are ignored. Odometry ``A = T_odom_base(t)`` is read from a
    :class:`~tagloc.frames.TransformBuffer` into which the caller inserts ``odom -> base``
    samples.
Prediction: a random walk driven by motion plus the calibration drift (:class:`ProcessNoise`)
    Over the odometry path between two stamps (increments ending at ``A_k``): a random error
    ``n_k`` of an increment moves the correction by ``X <- X @ Exp(Ad(A_k) n_k)``, giving the
    walk ``Q_x = sum_k Ad(A_k) Q_k Ad(A_k)^T``; the calibration moves it by ``M c``,
    ``M = sum_k Ad(A_k) G_k``. So ``X <- X (+) M c``, ``c`` unchanged, and
    ``P <- F P F^T + Q`` with ``F = [[I, M], [0, I]]`` and ``Q = diag(Q_x, Q_c)`` (``Q_c``: the
    calibration's own walk per metre travelled). Without calibration ``P <- P + Q_x``.
Update: iterated error-state EKF on the manifold (J. Sola, J. Deray, D. Atchuthan, "A micro Lie
theory for state estimation in robotics", 2018, arXiv:1812.01537, the ESKF with right
perturbations; iterated as Gauss-Newton, B. Bell and F. Cathey, IEEE TAC 1993)
    A fix ``z = T_map_base`` at ``t`` with covariance ``R``; ``A`` looked up at the same ``t`` (a
    late fix composes with the odometry of its own time); ``h(X) = X @ A``; innovation
    ``nu = z (-) h(X) = Log(h^-1 z)``. A right perturbation of ``X`` moves ``h`` by
    ``Ad(A^-1)``: ``nu(X (+) dx) ~ nu - H_x dx`` with ``H_x = Jl^-1(nu) Ad(A^-1)``; an on-time
    fix does not see ``c`` (``H = [H_x, 0]``; a late one does, :meth:`MapOdomFilter._linearize`);
    ``S = H P H^T + R``; gate ``d2 = nu^T S^-1 nu <= chi2.ppf(q, dof)``. Iterate from
    ``X_0 = X``: prior residual ``e = [X_i (-) X_0, c_i - c_0]``, ``m = -J e``,
    ``P_i = J P J^T`` (``J = diag(Jr(X_i (-) X_0), I)``), ``K = P_i H^T S^-1``,
    ``dx = m + K (nu - H m)``, ``X_{i+1} = X_i (+) dx_x``, ``c_{i+1} = c_i + dx_c``, while the
    step seen at the base, ``|H dx|``, exceeds ``relinearize_tol``. Then
    ``P <- Jd [(I-KH) P_i (I-KH)^T + K R K^T] Jd^T`` with ``Jd = diag(Jr(dx_x), I)`` (Joseph
    form, then the reset to the tangent at the new ``X``); ``c`` is clamped to ``max_abs``.
Late fixes
    A fix older than the state is compared with the state moved back to its stamp,
    ``X (+) M c`` (``M`` of the path back; ``F``, ``Q`` of the path between the two stamps):
    if the state was only predicted since, the gain uses ``P - Q`` (the prior at the fix's
    stamp carried forward by ``F``; ``H`` maps back through ``M``, :meth:`MapOdomFilter._linearize`)
    and ``Q`` is added back after the update, which for
    this linear model is exactly updating on time and then predicting; if a newer fix was
    applied meanwhile, the pose walk is added to the fix's noise instead,
    ``R <- R + H_x Q_x H_x^T`` (conservative).

Policies (start-up, gaps, kidnap, moved tags, the cap) are in :meth:`MapOdomFilter.update`
and :mod:`tagloc.localize.gating`. A fix that measures only some directions (a lidar scan match)
enters through :meth:`MapOdomFilter.update_partial` (:mod:`tagloc.localize.projected_update`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from tagloc.errors import TransformLookupError
from tagloc.frames import TransformBuffer
from tagloc.geometry import (
    SE2,
    SE3,
)
from tagloc.localize._series import jr as _jr
from tagloc.localize._series import jr_inv as _jr_inv
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.events import EventKind, EventLog, FilterEvent
from tagloc.localize.fix import (
    CorrectionUpdate,
    FloatArray,
    LocalizeError,
    PartialFix,
    PoseWithCovariance,
    TagFix,
    check_covariance,
    planar_projection_jacobian,
)
from tagloc.localize.gating import (
    Candidate,
    ConsistencyBuffer,
    CorrectionCap,
    Pose,
    QualityLimits,
    SourceMonitor,
    chi2_threshold,
    pair_d2,
)
from tagloc.localize.motion import (
    N_CALIBRATION,
    CalibrationModel,
    PathMotion,
    ProcessNoise,
)
from tagloc.localize.projected_update import planar_constraint, project_step, projector
from tagloc.localize.publisher import CorrectionPublisher

logger = logging.getLogger(__name__)
S_NS = 1_000_000_000
PLANAR_AXES = [0, 1, 5]  # x, y, rz of [x, y, z, rx, ry, rz]


__all__ = ["MapOdomFilter", "ProcessNoise"]


@dataclass(frozen=True, slots=True)
class _Innovation:
    """A fix linearized at the state: ``nu (d,)``, ``H`` (d, n) over the whole state (pose and
    calibration), ``S^-1``, ``R`` (d, d), the prior covariance ``P_fix`` (n, n) the gain uses (the
    state's at the fix's stamp), ``M`` (d, 4): the calibration drift from the state's stamp to the
    fix's (None for a fix at the state's stamp or without calibration), and ``d2``."""

    nu: FloatArray
    H: FloatArray
    S_inv: FloatArray
    R: FloatArray
    P_fix: FloatArray
    M: FloatArray | None
    d2: float


class MapOdomFilter:
    """The ``map -> odom`` filter: fixes in, corrections, poses and events out.

    Parameters
    ----------
    buffer : TransformBuffer
        Holds the odometry edge ``odom_frame -> base_frame`` (the caller inserts it).
    map_frame, odom_frame, base_frame : str
    planar : bool
        Estimate x, y, yaw only (z, roll, pitch of ``T_map_odom`` stay 0).
    noise : ProcessNoise
    chi2_quantile : float
        Gate quantile; the threshold is ``chi2.ppf(q, dof)``, dof 6 (3 planar).
    quality : QualityLimits
    k_consistent, consistency_window_ns : int
        Start-up and re-acquisition after a gap need ``k`` mutually consistent fixes in the
        window.
    gap_ns : int
    gap_m : float
        A gap: no accepted fix for longer than ``gap_ns`` or over more than ``gap_m`` travelled.
    cap : CorrectionCap
    kidnap_n, kidnap_min_sources, kidnap_window_ns : int
        Re-initialize from ``kidnap_n`` gated, mutually consistent fixes of at least
        ``kidnap_min_sources`` sources within the window, with no accepted fix among them
        (``kidnap_n = 0`` disables it).
    kidnap_n_one_source : int
        Or from this many such fixes of one source (0: never from one source), each putting the
        base at least ``kidnap_one_source_min_jump_m`` from the estimate.
    suspect_min_gated, suspect_clear_after : int
        See :class:`~tagloc.localize.gating.SourceMonitor`.
    suspect_spread : CorrectionCap
        Consecutive gated fixes of a source are "wrong the same way" only if the corrections
        they imply differ by less than this (a cap used as a bound).
    max_iterations : int
    relinearize_tol : float
    history_size, max_events : int
        Published corrections and events kept.
    calibration : CalibrationModel, optional
        Estimate the odometry's calibration with the state (:mod:`tagloc.localize.motion`);
        None: the correction is a pure random walk.

    Attributes
    ----------
    revision : int
        Counts the changes of the state (``X``, calibration, ``P``, stamp: a prediction, an
        applied fix, a (re)initialization): what is computed from the state stays valid while
        it is unchanged (for callers that cache, e.g. :meth:`pose_at`).
    """

    def __init__(
        self, buffer: TransformBuffer, *, map_frame: str, odom_frame: str, base_frame: str,
        planar: bool, noise: ProcessNoise, chi2_quantile: float, quality: QualityLimits,
        k_consistent: int, consistency_window_ns: int, gap_ns: int, gap_m: float,
        cap: CorrectionCap, kidnap_n: int, kidnap_min_sources: int, kidnap_window_ns: int,
        kidnap_n_one_source: int = 0, kidnap_one_source_min_jump_m: float = 1.0,
        suspect_min_gated: int, suspect_clear_after: int, suspect_spread: CorrectionCap,
        max_iterations: int,
        relinearize_tol: float, history_size: int, max_events: int,
        calibration: CalibrationModel | None = None,
        speed_limit: tuple[float, float] | None = None,
    ) -> None:  # fmt: skip
        self._buffer = buffer
        self.map_frame, self.odom_frame, self.base_frame = map_frame, odom_frame, base_frame
        self.planar = planar
        self.dof = 3 if planar else 6
        self._calib = calibration
        self._nc = N_CALIBRATION if calibration is not None else 0
        self._n = self.dof + self._nc  # error-state size: pose tangent, then calibration
        self._noise, self._quality, self._cap = noise, quality, cap
        self.threshold = chi2_threshold(chi2_quantile, self.dof)
        self._quantile = chi2_quantile
        self._gap_ns, self._gap_m = gap_ns, gap_m
        self._kidnap_on = kidnap_n > 0
        self._max_iter, self._tol = max_iterations, relinearize_tol
        self._candidates = ConsistencyBuffer(
            k_consistent, consistency_window_ns, self.threshold, 1, self._pair_noise
        )
        self._kidnap = ConsistencyBuffer(
            max(kidnap_n, 2), kidnap_window_ns, self.threshold, kidnap_min_sources,
            self._pair_noise,
        )  # fmt: skip
        self._kidnap_one = (
            ConsistencyBuffer(
                kidnap_n_one_source, kidnap_window_ns, self.threshold, 1, self._pair_noise
            )
            if kidnap_n_one_source > 0
            else None
        )
        self._kidnap_one_min_m = kidnap_one_source_min_jump_m
        self._sources = SourceMonitor(suspect_min_gated, suspect_clear_after)
        self._last_gated: dict[str, Candidate] = {}  # per source, for the suspect test
        self._suspect_window_ns = kidnap_window_ns
        self._suspect_spread = suspect_spread
        self._batch: tuple[tuple[TagFix, EventKind], ...] = ()
        self.batch_serial = 0
        self.events = EventLog(max_events)
        self._out = CorrectionPublisher(cap, history_size, planar, self._capped, speed_limit)
        self._X: Pose | None = None
        self._c = np.zeros(self._nc)  # odometry calibration (module motion)
        self._P = np.zeros((self._n, self._n))  # [pose tangent, calibration]
        if calibration is not None:
            self._P[self.dof :, self.dof :] = np.diag(calibration.prior_var)
        self._stamp = self._updated_ns = 0  # predicted to; last fix applied at
        self._A = SE3.identity()  # T_odom_base at the state's stamp
        self._odometer_m = 0.0
        self._looked_up: tuple[tuple[int, int], SE3] | None = None  # (stamp, revision), value
        # the last _path: ((t_from, t_to, buffer revision, drift), A_from, A_to, result); a
        # frame's prior (T_map_base_at) and its first fix's prediction ask for the same path
        self._last_path: tuple[tuple[int, int, int, bool], SE3, SE3, PathMotion] | None = None
        self.revision = 0  # bumped on every change of the state (X, c, P, stamp)
        self._gap = False
        self._ref_stamp, self._ref_odometer = 0, 0.0

    @classmethod
    def from_config(cls, config: LocalizerConfig, buffer: TransformBuffer) -> MapOdomFilter:
        """Build the filter from ``localizer.yaml``'s model (seconds become nanoseconds, the cap's
        degrees radians, standard deviations variances)."""
        f, n, g, k = config.frames, config.process_noise, config.gates, config.kidnap
        axes = PLANAR_AXES if config.filter.planar else list(range(6))

        def var(sigmas: tuple[float, ...]) -> FloatArray:
            return np.square(np.asarray(sigmas, dtype=np.float64))[axes]

        cal = config.calibration
        deg = np.array([1.0, 1.0, math.pi / 180.0, 1.0])  # yaw_per_m is in degrees
        calibration = (
            CalibrationModel(
                np.square(np.asarray(cal.prior_sigma) * deg),
                np.square(np.asarray(cal.sigma_per_sqrt_m) * deg),
                np.asarray(cal.max_abs) * deg,
            )
            if cal.enabled
            else None
        )

        return cls(
            buffer, map_frame=f.map_frame, odom_frame=f.odom_frame, base_frame=f.base_frame,
            planar=config.filter.planar,
            noise=ProcessNoise(
                var(n.sigma_per_sqrt_m), var(n.sigma_per_sqrt_rad), var(n.sigma_per_sqrt_s),
                round(n.motion_step_s * S_NS),
            ),
            chi2_quantile=g.chi2_quantile,
            quality=QualityLimits(g.max_reproj_err_px, g.max_ambiguity_ratio, g.max_range_m),
            k_consistent=g.k_consistent, consistency_window_ns=round(g.consistency_window_s * S_NS),
            gap_ns=round(g.gap_s * S_NS), gap_m=g.gap_m,
            cap=CorrectionCap(
                config.cap.max_translation_m, math.radians(config.cap.max_rotation_deg),
                config.cap.snap_on_initialize,
            ),
            kidnap_n=k.n_fixes if k.enabled else 0, kidnap_min_sources=k.min_sources,
            kidnap_window_ns=round(k.window_s * S_NS),
            kidnap_n_one_source=k.n_fixes_one_source if k.enabled else 0,
            kidnap_one_source_min_jump_m=k.one_source_min_jump_m,
            suspect_min_gated=config.suspect.min_gated,
            suspect_clear_after=config.suspect.clear_after,
            suspect_spread=CorrectionCap(  # a bound on the spread, not a published cap
                config.suspect.max_spread_m, math.radians(config.suspect.max_spread_deg)
            ),
            max_iterations=config.filter.max_iterations,
            relinearize_tol=config.filter.relinearize_tol,
            history_size=config.filter.history_size, max_events=config.filter.max_events,
            calibration=calibration, speed_limit=_speed_limit(config),
        )  # fmt: skip

    # ----- outputs ---------------------------------------------------------------------------
    @property
    def initialized(self) -> bool:
        """True once the state exists (after ``k`` consistent fixes or :meth:`initialize`)."""
        return self._X is not None

    @property
    def reacquiring(self) -> bool:
        """True after a gap until ``k`` consistent fixes re-acquire the state."""
        return self._gap

    @property
    def stamp_ns(self) -> int:
        """Stamp the state was last predicted to (ns)."""
        return self._stamp

    @property
    def T_map_odom(self) -> SE3:
        """The estimate (not the capped published correction, see :meth:`correction_at`)."""
        return self._lift(self._require())

    @property
    def covariance(self) -> FloatArray:
        """``(6, 6)`` right-tangent covariance of :attr:`T_map_odom`, ``[x, y, z, rx, ry, rz]``
        (planar: zero rows and columns for z, rx, ry)."""
        self._require()
        return self._embed(self._P[: self.dof, : self.dof])

    @property
    def odometry_calibration(self) -> tuple[FloatArray, FloatArray] | None:
        """The estimated odometry calibration ``[scale, lateral, yaw_per_m (rad/m), yaw_scale]``
        and its 1-sigma (see :mod:`tagloc.localize.motion`), or None when not estimated."""
        if self._calib is None:
            return None
        sigma = np.sqrt(np.diag(self._P)[self.dof :])
        return self._c.copy(), sigma

    @property
    def corrections(self) -> tuple[CorrectionUpdate, ...]:
        """Published ``map -> odom`` corrections (stamps non-decreasing), oldest first."""
        return self._out.history

    @property
    def suspect_sources(self) -> tuple[str, ...]:
        """Sources flagged suspect (e.g. ``("tag:17",)`` for a moved tag), sorted."""
        return self._sources.suspects

    @property
    def last_batch(self) -> tuple[tuple[TagFix, EventKind], ...]:
        """The fixes the latest batch decision used, each with its final decision: the
        consistent set of a (re)initialization, or the held fixes applied after a gap.
        :attr:`batch_serial` counts batches, so a caller sees when a new one happened."""
        return self._batch

    @property
    def source_stats(self) -> SourceMonitor:
        """Per-source counts and innovation statistics (``stats[source].mean_nis``)."""
        return self._sources

    def correction_at(self, stamp_ns: int) -> SE3:
        """The published ``T_map_odom`` in force at ``stamp_ns`` (the latest at or before it).

        Raises
        ------
        LocalizeError
            Before the first (kept) published correction.
        """
        return self._out.correction_at(stamp_ns)

    def pose_at(self, stamp_ns: int, *, published: bool = False) -> PoseWithCovariance:
        """``T_map_base = T_map_odom @ T_odom_base(stamp_ns)`` with covariance.

        The state predicted to ``stamp_ns`` (either way in time) over the odometry path from
        its stamp: ``T_map_base = (X (+) M c) @ A``, ``cov = Ad(A^-1) P' Ad(A^-1)^T`` with
        ``P'`` the pose block of ``F P F^T + Q`` (``F = [[I, M], [0, I]]``, ``Q`` the random
        walk between the two stamps; without calibration ``P + Q``). ``published=True``
        composes the published (capped) correction, drifted the same way, instead of the
        estimate (same covariance).

        Raises
        ------
        LocalizeError
            Before initialization.
        TransformLookupError
            If the odometry at ``stamp_ns`` (or on the path to it) is not buffered.
        """
        X = self._require()
        A3 = self._lookup(stamp_ns)
        motion = self._path(self._stamp, stamp_ns, self._A, A3)
        P = self._predicted(self._P, motion)[: self.dof, : self.dof]
        if published and self._out.current is not None:
            X = self._out.current
        X = self._drifted(X, motion)
        J = A3.inverse().adjoint()
        cov = J @ self._embed(P) @ J.T
        return PoseWithCovariance(
            stamp_ns, self.map_frame, self.base_frame, self._lift(X) @ A3, 0.5 * (cov + cov.T)
        )

    def T_map_base_at(self, stamp_ns: int) -> SE3:
        """``T_map_base`` at ``stamp_ns`` from the estimate, without its covariance (what a
        fix source needs as a prior; cheaper than :meth:`pose_at`).

        Raises
        ------
        LocalizeError
            Before initialization.
        TransformLookupError
            If the odometry at ``stamp_ns`` is not buffered.
        """
        X = self._require()
        A3 = self._lookup(stamp_ns)
        if self._nc and stamp_ns != self._stamp:
            X = self._drifted(X, self._path(self._stamp, stamp_ns, self._A, A3))
        return self._lift(X) @ A3

    # ----- inputs ----------------------------------------------------------------------------
    def initialize(self, stamp_ns: int, T_map_odom: SE3, cov: FloatArray) -> FilterEvent:
        """Set an explicit prior (e.g. a saved pose); planar mode keeps its x, y, yaw.

        Raises
        ------
        LocalizeError
            On a bad covariance; ``TransformLookupError`` without odometry at ``stamp_ns``.
        """
        cov6 = check_covariance(cov, 6, "initialize: cov")
        A = self._lookup(stamp_ns)
        if self.planar:
            X: Pose = T_map_odom.to_se2()
            J = planar_projection_jacobian(T_map_odom)
            P = J @ cov6 @ J.T
        else:
            X, P = T_map_odom, cov6
        self._reset_state(stamp_ns, A, X, P)
        self._publish(stamp_ns, snap=True)
        return self._event(stamp_ns, EventKind.INITIALIZED, detail="explicit prior")

    def predict(self, stamp_ns: int) -> None:
        """Advance the state to ``stamp_ns``; call it at every odometry sample.

        The path is integrated in steps of ``motion_step``: a stamp less than one step after
        the state's returns almost at once (so calling this at the odometry rate costs little),
        as does any call before initialization. With odometry calibration, the published
        correction drifts with the state. Every call also ends one odometry step of the cap:
        what was published since the previous call (updates, drift) is clipped to within the
        cap of the correction published then, so between two calls the published
        ``map -> base`` moves by at most the cap ((re)initializations excepted). Without calls,
        the cap applies per publication stamp (:meth:`_publish`).

        Raises
        ------
        TransformLookupError
            If the odometry at ``stamp_ns`` is not buffered.
        """
        if self._X is None:
            return
        if stamp_ns - self._stamp >= self._noise.step_ns:
            self._advance(stamp_ns, self._lookup(stamp_ns))
        self._out.end_step(stamp_ns, lambda: self._lookup(stamp_ns))  # judged at the robot

    def add_process_noise(self, Q: FloatArray) -> None:
        """Add ``Q`` ((6, 6), symmetric positive semi-definite, ``[x, y, z, rx, ry, rz]``) to the
        covariance of ``T_map_odom`` now: odometry error the motion model does not know of (the
        growth of the odometry's own pose covariance, in the odometry frame: an error ``d`` of
        ``T_odom_base`` on the left is ``-d`` of the correction on the right, so its covariance
        adds as it is). Planar: its x, y, yaw block. Before initialization: nothing.

        Raises
        ------
        LocalizeError
            If ``Q`` is not (6, 6), finite and symmetric.
        """
        if self._X is None:
            return
        Q6 = np.asarray(Q, dtype=np.float64)
        if Q6.shape != (6, 6) or not np.isfinite(Q6).all() or not np.allclose(Q6, Q6.T):
            raise LocalizeError("add_process_noise: Q must be a finite symmetric (6, 6) matrix")
        block = Q6[np.ix_(PLANAR_AXES, PLANAR_AXES)] if self.planar else Q6
        self._P[: self.dof, : self.dof] += block
        self.revision += 1

    def update(self, fix: TagFix) -> FilterEvent:
        """Decide on one fix and apply it if it passes; return the decision event.

        Steps: (1) quality gates: a fix with a high reprojection error never reaches the state
        or the published correction; (2) the odometry at the fix's own stamp; (3) no state yet:
        buffer until ``k`` mutually consistent fixes, initialize from them; (4) predict to the
        stamp; (5) a suspect source (moved tag) is rejected; (6) after a gap, buffer until
        ``k`` consistent fixes; (7) chi-square gate (a gated fix feeds the kidnap test and the
        source's statistics); (8) iterated EKF update and the capped publication.

        Returns
        -------
        FilterEvent
            The decision on this fix (``ACCEPTED``, ``GATED_*``, ``PENDING_CONSISTENCY``, ...);
            any filter-level events it caused follow it in :attr:`events`.
        """
        limit = self._quality.check(fix.quality)
        if limit is not None:
            kind, _, bound, detail = limit
            return self._event(fix.stamp_ns, kind, fix.source, None, bound, detail)
        try:
            A3 = self._lookup(fix.stamp_ns)
        except TransformLookupError as exc:
            return self._event(fix.stamp_ns, EventKind.NO_ODOMETRY, fix.source, detail=str(exc))
        cand = self._candidate(fix, A3)
        if self._X is None:
            return self._buffer_candidate(cand, initial=True)
        if fix.stamp_ns > self._stamp:
            self._advance(fix.stamp_ns, A3)
        if self._sources.is_suspect(fix.source):
            return self._reject_suspect(cand)
        if self._gap or self._gap_started(fix.stamp_ns):
            return self._buffer_candidate(cand, initial=False)
        return self._decide(cand)

    def update_partial(self, fix: PartialFix) -> FilterEvent:
        """Decide on a fix that measures only the directions ``fix.basis`` and apply it if it
        passes (:mod:`tagloc.localize.projected_update`): the chi-square gate on ``k`` dof,
        then the iterated update that never moves the estimate along an unmeasured direction.

        Such a fix cannot start the state (``UNUSED_NO_STATE`` before it exists), does not
        wait for consistent fixes after a gap and feeds neither the kidnap nor the suspect
        books (those are the tag fixes'). One that measures every direction of the filter
        (``k = dof`` after the planar projection) and is accepted counts as a fix for the gap
        rule (it ends a gap: fixes held for re-acquisition are discarded).
        """
        try:
            A3 = self._lookup(fix.stamp_ns)
        except TransformLookupError as exc:
            return self._event(fix.stamp_ns, EventKind.NO_ODOMETRY, fix.source, detail=str(exc))
        if self._X is None:
            return self._event(fix.stamp_ns, EventKind.UNUSED_NO_STATE, fix.source)
        if fix.stamp_ns > self._stamp:
            self._advance(fix.stamp_ns, A3)
        if self.planar:
            basis, R = planar_constraint(fix.basis, fix.cov)
            cand = Candidate(fix, A3, A3.to_se2(), fix.T_map_base.to_se2(), R, basis)
        else:
            cand = Candidate(fix, A3, A3, fix.T_map_base, fix.cov, fix.basis)
        k = cand.R.shape[0]
        if k == 0:
            return self._event(fix.stamp_ns, EventKind.GATED_QUALITY, fix.source,
                               detail="no measured direction in the plane")  # fmt: skip
        innov = self._innovation(cand, self._back(cand))
        threshold = chi2_threshold(self._quantile, k)
        if innov.d2 > threshold:
            return self._event(fix.stamp_ns, EventKind.GATED_CHI2, fix.source, innov.d2, threshold)
        self._X, self._c, self._P = self._iekf(cand, innov)
        self.revision += 1
        self._updated_ns = max(self._updated_ns, fix.stamp_ns)
        if k == self.dof:
            if self._gap:
                self._gap = False
                for old in self._candidates.clear():
                    self._event(old.stamp_ns, EventKind.DISCARDED_CANDIDATE, old.fix.source)
            self._ref_stamp = max(self._ref_stamp, fix.stamp_ns)
            self._ref_odometer = self._odometer_m
        event = self._event(fix.stamp_ns, EventKind.ACCEPTED, fix.source, innov.d2, threshold)
        self._publish(fix.stamp_ns, snap=False)
        return event

    # ----- policies --------------------------------------------------------------------------
    def _decide(self, cand: Candidate) -> FilterEvent:
        """Chi-square gate against the state, then the update (or the kidnap / suspect books)."""
        fix = cand.fix
        innov = self._innovation(cand, self._back(cand))
        d2 = innov.d2
        if d2 > self.threshold:
            event = self._event(fix.stamp_ns, EventKind.GATED_CHI2, fix.source, d2)
            last = self._last_gated.get(fix.source)
            self._last_gated[fix.source] = cand
            # the previous gated fix of the source counts only if recent (a moved tag repeats
            # itself within seconds; comparing with one from minutes ago says nothing)
            consistent = (
                last is not None
                and cand.stamp_ns - last.stamp_ns <= self._suspect_window_ns
                and not self._suspect_spread.exceeds(  # the two seen at the robot's pose
                    (last.T_map_odom @ cand.A).inverse() @ cand.z  # type: ignore[operator]
                )
                and pair_d2(last, cand, self._pair_noise(last, cand)) <= self.threshold
            )
            if self._sources.on_gated(fix.source, d2, consistent):
                stats = self._sources.stats[fix.source]
                self._event(
                    fix.stamp_ns, EventKind.SUSPECT_SOURCE, fix.source, d2,
                    detail=f"{stats.streak_gated} fixes gated in a row while other sources "
                    "were accepted: moved or mis-surveyed?",
                )  # fmt: skip
                self._kidnap.remove_source(fix.source)
                if self._kidnap_one is not None:
                    self._kidnap_one.remove_source(fix.source)
            elif self._kidnap_on:
                self._kidnap.expire(fix.stamp_ns)
                found = self._kidnap.add(cand)
                if found is None and self._kidnap_one is not None and self._far(cand):
                    self._kidnap_one.expire(fix.stamp_ns)
                    found = self._kidnap_one.add(cand)
                if found is not None:
                    self._reinitialize(found, EventKind.REINITIALIZED_KIDNAP)
            return event
        self._X, self._c, self._P = self._iekf(cand, innov)
        self.revision += 1
        self._updated_ns = max(self._updated_ns, fix.stamp_ns)
        self._sources.on_accepted(fix.source, d2)
        self._kidnap.clear()
        if self._kidnap_one is not None:
            self._kidnap_one.clear()
        self._ref_stamp = max(self._ref_stamp, fix.stamp_ns)
        self._ref_odometer = self._odometer_m
        event = self._event(fix.stamp_ns, EventKind.ACCEPTED, fix.source, d2)
        self._publish(fix.stamp_ns, snap=False)
        return event

    def _far(self, cand: Candidate) -> bool:
        """Whether a fix puts the base at least ``kidnap_one_source_min_jump_m`` from the
        state's estimate: only such a fix may re-localize from one tag alone (a kidnap moves
        the robot metres; a tag moved or mis-surveyed by less is flagged suspect instead)."""
        X = self._require()
        T = (X @ cand.A).inverse() @ cand.z  # type: ignore[operator]
        return float(np.linalg.norm(T.translation)) >= self._kidnap_one_min_m

    def _reject_suspect(self, cand: Candidate) -> FilterEvent:
        """A fix of a suspect source: not applied; passing the gate counts toward clearing."""
        fix = cand.fix
        d2 = self._innovation(cand, None).d2
        event = self._event(fix.stamp_ns, EventKind.REJECTED_SUSPECT, fix.source, d2)
        if self._sources.on_suspect_fix(fix.source, d2 <= self.threshold):
            self._event(fix.stamp_ns, EventKind.SOURCE_CLEARED, fix.source, d2)
        return event

    def _gap_started(self, stamp_ns: int) -> bool:
        travelled = self._odometer_m - self._ref_odometer
        if stamp_ns - self._ref_stamp <= self._gap_ns and travelled <= self._gap_m:
            return False
        self._gap = True
        self._event(
            stamp_ns, EventKind.GAP,
            detail=f"no accepted fix for {(stamp_ns - self._ref_stamp) / S_NS:.1f} s, "
            f"{travelled:.1f} m: waiting for consistent fixes",
        )  # fmt: skip
        return True

    def _buffer_candidate(self, cand: Candidate, *, initial: bool) -> FilterEvent:
        """Hold a fix until ``k`` mutually consistent ones; then initialize or apply them."""
        for old in self._candidates.expire(cand.stamp_ns):
            self._event(old.stamp_ns, EventKind.DISCARDED_CANDIDATE, old.fix.source)
        event = self._event(
            cand.stamp_ns, EventKind.PENDING_CONSISTENCY, cand.fix.source,
            detail=f"{len(self._candidates) + 1} buffered",
        )  # fmt: skip
        found = self._candidates.add(cand)
        if found is None:
            return event
        if initial:
            self._reinitialize(found, EventKind.INITIALIZED)
            return event
        for old in self._candidates.clear():
            self._event(old.stamp_ns, EventKind.DISCARDED_CANDIDATE, old.fix.source)
        self._gap = False
        self._ref_stamp, self._ref_odometer = found[-1].stamp_ns, self._odometer_m
        if self._kidnap_on and all(self._gated_now(m) for m in found):
            # Re-acquisition after a gap: k consistent fixes that all disagree with the stale
            # state re-initialize it (the start-up rule), instead of waiting for the kidnap
            # test's second source: the state is unconfirmed, the k fixes agree.
            self._reinitialize(found, EventKind.REINITIALIZED_KIDNAP)
            return event
        self._set_batch([(m.fix, self._decide(m).kind) for m in found])
        return event

    def _set_batch(self, batch: list[tuple[TagFix | PartialFix, EventKind]]) -> None:
        self._batch = tuple((f, k) for f, k in batch if isinstance(f, TagFix))  # tag fixes only
        self.batch_serial += 1

    def _gated_now(self, cand: Candidate) -> bool:
        """Whether ``cand`` fails the chi-square gate against the current state."""
        return self._innovation(cand, self._back(cand)).d2 > self.threshold

    def _reinitialize(self, found: list[Candidate], kind: EventKind) -> None:
        """Restart the state from consistent fixes (oldest first): the first sets ``X`` and
        ``P``, the others are applied as updates."""
        first = found[0]
        self._reset_state(first.stamp_ns, first.odom, first.T_map_odom, first.cov)
        for cand in found[1:]:
            if cand.stamp_ns > self._stamp:
                self._advance(cand.stamp_ns, cand.odom)
            self._X, self._c, self._P = self._iekf(cand, self._innovation(cand, None))
            self.revision += 1
        self._ref_stamp, self._ref_odometer = self._stamp, self._odometer_m
        for cand in found:
            self._sources.on_accepted(cand.fix.source, None)
        self._sources.reset_streaks()
        for old in self._candidates.clear():
            self._event(old.stamp_ns, EventKind.DISCARDED_CANDIDATE, old.fix.source)
        self._kidnap.clear()
        if self._kidnap_one is not None:
            self._kidnap_one.clear()
        self._set_batch([(c.fix, kind) for c in found])
        sources = "+".join(sorted({c.fix.source for c in found}))
        t = self._lift(self._require()).translation
        self._event(
            self._stamp, kind, sources,
            detail=f"from {len(found)} consistent fixes; T_map_odom t = {np.round(t, 3)}",
        )  # fmt: skip
        snap = self._cap.snap_on_initialize or self._out.current is None
        self._publish(self._stamp, snap=snap)

    def _reset_state(self, stamp_ns: int, odom: SE3, X: Pose, P: FloatArray) -> None:
        """A new pose state (``P``: its (dof, dof) covariance); the odometry calibration is kept
        (it belongs to the odometry, not to the pose), its correlation with the pose dropped."""
        full = np.zeros((self._n, self._n))
        full[: self.dof, : self.dof] = P
        full[self.dof :, self.dof :] = self._P[self.dof :, self.dof :]
        self._X, self._P, self._stamp, self._A = X, full, stamp_ns, odom
        self._updated_ns = stamp_ns
        self.revision += 1
        self._gap = False
        self._ref_stamp, self._ref_odometer = stamp_ns, self._odometer_m

    # ----- estimator -------------------------------------------------------------------------
    def _require(self) -> Pose:
        if self._X is None:
            raise LocalizeError(
                "the map -> odom filter is not initialized: it needs k consistent fixes "
                "(or initialize())"
            )
        return self._X

    def _lookup(self, stamp_ns: int) -> SE3:
        """``T_odom_base`` at ``stamp_ns``; the last one is reused while the buffer is unchanged
        (a frame's prior and its fixes look up the same stamp)."""
        key = (stamp_ns, self._buffer.revision)
        if self._looked_up is not None and self._looked_up[0] == key:
            return self._looked_up[1]
        odom = self._buffer.lookup(self.odom_frame, self.base_frame, stamp_ns)
        self._looked_up = (key, odom)
        return odom

    def _lift(self, X: Pose) -> SE3:
        return X.to_se3() if isinstance(X, SE2) else X

    def _embed(self, P: FloatArray) -> FloatArray:
        if not self.planar:
            return P.copy()
        out = np.zeros((6, 6))
        out[np.ix_(PLANAR_AXES, PLANAR_AXES)] = P
        return out

    def _candidate(self, fix: TagFix, odom: SE3) -> Candidate:
        """The fix as the filter uses it, and the correction ``z @ A^-1`` it implies."""
        A: Pose
        z: Pose
        if self.planar:
            z, R = fix.to_planar()
            A = odom.to_se2()
        else:
            z, R, A = fix.T_map_base, np.asarray(fix.cov), odom
        return Candidate(fix, odom, A, z, R)

    def _pair_noise(self, a: Candidate, b: Candidate) -> FloatArray:
        """Random-walk covariance of the odometry path between two fixes."""
        return self._path(a.stamp_ns, b.stamp_ns, a.odom, b.odom, drift=False).Q

    def _path(
        self, t_from: int, t_to: int, A_from: SE3, A_to: SE3, *, drift: bool = True
    ) -> PathMotion:
        """:class:`PathMotion` of the odometry path from ``t_from`` to ``t_to`` (either order:
        the drift ``M`` is negated for a path back in time; ``Q`` is the walk between them).
        ``M`` is computed only with calibration and ``drift`` (else ``(d, 0)``). The last
        result is reused for the same stamps, end poses and buffer revision."""
        drift = drift and self._nc > 0
        key = (t_from, t_to, self._buffer.revision, drift)
        last = self._last_path
        if last is not None and last[0] == key and last[1] is A_from and last[2] is A_to:
            return last[3]
        motion = self._integrate(t_from, t_to, A_from, A_to, drift)
        self._last_path = (key, A_from, A_to, motion)
        return motion

    def _integrate(self, t_from: int, t_to: int, A_from: SE3, A_to: SE3, drift: bool) -> PathMotion:
        """:meth:`_path` without the reuse."""
        (lo, A_lo), (hi, A_hi) = sorted(((t_from, A_from), (t_to, A_to)), key=lambda p: p[0])
        R_lo, t_lo = A_lo.rotation.matrix, A_lo.translation
        R_hi, t_hi = A_hi.rotation.matrix, A_hi.translation
        n = math.ceil((hi - lo) / self._noise.step_ns)
        motion = None
        if n > 1:
            inner = lo + np.round(np.arange(1, n) * ((hi - lo) / n)).astype(np.int64)
            try:
                mid = self._buffer.lookup_many(self.odom_frame, self.base_frame, inner)
            except TransformLookupError as exc:
                logger.warning("odometry path %d..%d ns not buffered (%s): chord used", lo, hi, exc)
            else:
                stamps = np.concatenate([[lo], inner, [hi]])
                R = np.concatenate([R_lo[None], mid.rotation.matrix, R_hi[None]])
                t = np.concatenate([t_lo[None], mid.translation, t_hi[None]])
                motion = self._noise.path(stamps, R, t, self.planar, drift)
        if motion is None:
            motion = self._noise.increment(hi - lo, R_lo, t_lo, R_hi, t_hi, self.planar, drift)
        if t_to < t_from and drift:
            motion = PathMotion(motion.Q, motion.distance_m, -motion.M)
        return motion

    def _back(self, cand: Candidate) -> PathMotion | None:
        """The path from the state's stamp back to a late fix's (None if not late)."""
        if cand.stamp_ns >= self._stamp:
            return None
        return self._path(self._stamp, cand.stamp_ns, self._A, cand.odom)

    def _full_noise(self, motion: PathMotion) -> FloatArray:
        """Process noise of the whole state over ``motion``: the pose walk and the
        calibration's."""
        if not self._nc:
            return motion.Q
        assert self._calib is not None
        Q = np.zeros((self._n, self._n))
        Q[: self.dof, : self.dof] = motion.Q
        Q[self.dof :, self.dof :] = np.diag(self._calib.var_per_m * motion.distance_m)
        return Q

    def _predicted(self, P: FloatArray, motion: PathMotion) -> FloatArray:
        """``F P F^T + Q`` with ``F = [[I, M], [0, I]]`` (the calibration drives the pose)."""
        if self._nc:
            F = np.eye(self._n)
            F[: self.dof, self.dof :] = motion.M
            P = F @ P @ F.T
        out: FloatArray = P + self._full_noise(motion)
        return out

    def _drifted(self, X: Pose, motion: PathMotion) -> Pose:
        """``X (+) M c``: the correction moved by the calibrated odometry over ``motion``."""
        if not self._nc:
            return X
        return X.plus(motion.M @ self._c)

    def _advance(self, stamp_ns: int, odom: SE3) -> None:
        """Predict over the odometry path from the state's stamp: ``X <- X (+) M c``,
        ``P <- F P F^T + Q``; the published correction drifts with ``X``."""
        motion = self._path(self._stamp, stamp_ns, self._A, odom)
        self._P = self._predicted(self._P, motion)
        if self._nc:
            self._X = self._drifted(self._require(), motion)
            if self._out.current is not None:
                # the published correction drifts too (recorded by predict() or the
                # publication that follows, not once per update)
                self._out.drift(self._drifted(self._out.current, motion))
        self._stamp, self._A = stamp_ns, odom
        self._odometer_m += motion.distance_m
        self.revision += 1

    def _innovation(self, cand: Candidate, back: PathMotion | None) -> _Innovation:
        """Linearize a fix at the (augmented) state. A fix at the state's stamp has
        ``H = [H_x, 0]`` over pose and calibration. A fix older than the state (``back``: the
        path from the state's stamp to the fix's) is compared with the state moved back to its
        stamp, ``X (+) M c`` (``M`` of ``back``; ``H`` of :meth:`_linearize`, which sees ``c``).
        If the state was only predicted since, the gain uses the prior at the fix's stamp
        carried forward, ``P - Q_back`` (``Q_back``: pose and calibration walk of ``back``;
        exact for this linear model: the same as updating on time, then predicting); if a
        newer fix was applied meanwhile, the pose walk is added to the fix's noise instead,
        ``R + H_x Q_x H_x^T`` (conservative)."""
        X, P = self._require(), self._P
        M = back.M if back is not None and self._nc else None
        nu, H = self._linearize(cand, X, self._c, M)
        P_fix, R = P, cand.R
        if cand.basis is not None:  # a partial fix: only its measured directions
            nu, H = cand.basis.T @ nu, cand.basis.T @ H
        if back is not None:
            Q_back = self._full_noise(back)
            Hx = H[:, : self.dof]
            if self._updated_ns <= cand.stamp_ns:
                P_fix = P - Q_back
                try:  # a differently sampled path could overshoot: then the conservative way
                    np.linalg.cholesky(P_fix)
                except np.linalg.LinAlgError:
                    P_fix, R = P, R + Hx @ back.Q @ Hx.T
            else:
                R = R + Hx @ back.Q @ Hx.T
        S_inv = np.linalg.inv(H @ P_fix @ H.T + R).astype(np.float64, copy=False)
        return _Innovation(nu, H, S_inv, R, P_fix, M, float(nu @ S_inv @ nu))

    def _linearize(
        self, cand: Candidate, X: Pose, c: FloatArray, M: FloatArray | None
    ) -> tuple[FloatArray, FloatArray]:
        """Innovation ``nu = z (-) (X (+) u) @ A``, ``u = M c``, and its Jacobian ``H`` (d, n):
        ``nu(X (+) dx, c + dc) ~ nu - H [dx, dc]``, with ``H = [H_f Ad(Exp(-u)), H_f Jr(u) M]``
        and ``H_f = Jl^-1(nu) Ad(A^-1)`` (``Jl^-1(nu) = Jr^-1(-nu)``), the Jacobian at the
        state moved to the fix's stamp. ``M = None``: a fix at the state's stamp (``u = 0``,
        ``H = [H_f, 0]``); ignored without calibration (``H = H_f``)."""
        X_fix = X  # the state moved to the fix's stamp
        if M is not None and self._nc:
            E, Jr_u = type(X).exp(M @ c, jacobians=True)
            X_fix = X @ E  # type: ignore[operator]
        nu = cand.z.minus(X_fix @ cand.A)  # type: ignore[operator, arg-type]
        H_f = _jr_inv(-nu) @ cand.Ad_A_inv
        if not self._nc:
            return nu, H_f
        if M is None:
            H = np.zeros((self.dof, self._n))
            H[:, : self.dof] = H_f
            return nu, H
        return nu, np.hstack([H_f @ E.inverse().adjoint(), H_f @ Jr_u @ M])

    def _iekf(self, cand: Candidate, innov: _Innovation) -> tuple[Pose, FloatArray, FloatArray]:
        """Iterated error-state update (module docstring) of the pose and the calibration;
        returns the new ``X``, ``c`` and ``P``. Relinearizes while the step seen at the base,
        ``|H dx|``, exceeds the tolerance."""
        X0, c0, P0, R, M = self._require(), self._c, innov.P_fix, innov.R, innov.M
        dof, n = self.dof, self._n
        X, c, Pi, m = X0, c0, P0, None
        nu, H, S_inv = innov.nu, innov.H, innov.S_inv
        J = np.eye(n)
        Pr = None if cand.basis is None else projector(cand.Ad_A_inv, cand.basis)
        for i in range(self._max_iter):
            if i:  # relinearize at X: prior mean and covariance moved into X's tangent
                e = X.minus(X0)  # type: ignore[arg-type]
                J[:dof, :dof] = _jr(e)
                m = -np.concatenate([J[:dof, :dof] @ e, c - c0])
                Pi = J @ P0 @ J.T
                nu, H = self._linearize(cand, X, c, M)
                if cand.basis is not None:
                    nu, H = cand.basis.T @ nu, cand.basis.T @ H
                S_inv = np.linalg.inv(H @ Pi @ H.T + R).astype(np.float64, copy=False)
            K = Pi @ H.T @ S_inv
            if Pr is not None:  # Schmidt gain: no step along unmeasured directions
                K[:dof] = Pr @ K[:dof]
            dx = K @ nu if m is None else m + K @ (nu - H @ m)
            X_from, X_new, c_new = X, X.plus(dx[:dof]), c + dx[dof:]
            if float(np.abs(H @ dx).max()) <= self._tol:
                break
            X, c = X_new, c_new
        if Pr is not None:  # the total step, exactly within the measured directions
            X_new = project_step(X0, X_new, Pr)
            dx[:dof] = X_new.minus(X_from)  # type: ignore[arg-type]
        IKH = np.eye(n) - K @ H
        Jd = np.eye(n)
        Jd[:dof, :dof] = _jr(dx[:dof])
        P = Jd @ (IKH @ Pi @ IKH.T + K @ R @ K.T) @ Jd.T  # Joseph form, then the reset
        # Plus the walk since the fix's stamp when the gain used P - Q_back (the walk's
        # covariance, Ad(A) Q Ad(A)^T, does not depend on X: no reset for it).
        if P0 is not self._P:
            P = P + (self._P - P0)
        if self._calib is not None and (np.abs(c_new) > self._calib.max_abs).any():
            c_new = np.clip(c_new, -self._calib.max_abs, self._calib.max_abs)
        return X_new, c_new, 0.5 * (P + P.T)

    def _publish(self, stamp_ns: int, *, snap: bool) -> None:
        """Publish the estimate (:class:`~tagloc.localize.publisher.CorrectionPublisher`: moved
        toward at most the cap per publication stamp and per odometry step, or snapped)."""
        self._out.publish(self._require(), stamp_ns, self._A, snap=snap)

    def _capped(self, stamp_ns: int, detail: str) -> None:
        self._event(stamp_ns, EventKind.CAPPED, detail=detail)

    def _event(
        self, stamp_ns: int, kind: EventKind, source: str = "", d2: float | None = None,
        threshold: float | None = None, detail: str = "",
    ) -> FilterEvent:  # fmt: skip
        if d2 is not None and threshold is None:
            threshold = self.threshold
        return self.events.append(FilterEvent(stamp_ns, kind, source, d2, threshold, detail))


def _speed_limit(config: LocalizerConfig) -> tuple[float, float] | None:
    """``cap.max_speed_m_s`` and ``cap.max_rate_deg_s`` as (m/s, rad/s), None if neither set."""
    v, w = config.cap.max_speed_m_s, config.cap.max_rate_deg_s
    if v is None and w is None:
        return None
    return (math.inf if v is None else v, math.inf if w is None else math.radians(w))
