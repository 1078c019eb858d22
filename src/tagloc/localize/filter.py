"""``MapOdomFilter``: the ``map -> odom`` correction as an iterated error-state EKF on SE(3).

State and frames
    ``X = T_map_odom`` with covariance ``P`` in its right tangent, ``X_true = X @ Exp(dx)``,
    ``dx ~ N(0, P)``, ordered ``[x, y, z, rx, ry, rz]``. Planar mode estimates ``(x, y, yaw)`` on
    SE(2) (``P`` 3x3, ``[x, y, theta]``): z, roll and pitch of ``T_map_odom`` are pinned at 0 and
    a fix enters as its planar projection (:meth:`TagFix.to_planar
    <tagloc.localize.fix.TagFix.to_planar>`), so its z, roll and pitch are ignored. Odometry
    ``A = T_odom_base(t)`` is read from a :class:`~tagloc.frames.TransformBuffer` into which the
    caller inserts ``odom -> base`` samples.
Prediction: a random walk driven by motion (:class:`ProcessNoise`)
    Drift accrues in the base frame; an error ``n`` of the increment ending at ``A`` moves the
    correction by ``X <- X @ Exp(Ad(A) n)``, so ``P <- P + sum_k Ad(A_k) Q_k Ad(A_k)^T``.
Update: iterated error-state EKF on the manifold (J. Sola, J. Deray, D. Atchuthan, "A micro Lie
theory for state estimation in robotics", 2018, arXiv:1812.01537, the ESKF with right
perturbations; iterated as Gauss-Newton, B. Bell and F. Cathey, IEEE TAC 1993)
    A fix ``z = T_map_base`` at ``t`` with covariance ``R``; ``A`` looked up at the same ``t`` (a
    late fix composes with the odometry of its own time); ``h(X) = X @ A``; innovation
    ``nu = z (-) h(X) = Log(h^-1 z)``. A right perturbation of ``X`` moves ``h`` by
    ``Ad(A^-1)``: ``nu(X (+) dx) ~ nu - H dx`` with ``H = Jl^-1(nu) Ad(A^-1)``;
    ``S = H P H^T + R``; gate ``d2 = nu^T S^-1 nu <= chi2.ppf(q, dof)``. Iterate from
    ``X_0 = X``: prior residual ``e = X_i (-) X_0``, ``m = -Jr(e) e``, ``P_i = Jr(e) P Jr(e)^T``,
    ``K = P_i H^T S^-1``, ``dx = m + K (nu - H m)``, ``X_{i+1} = X_i (+) dx``, while the step
    seen at the base, ``|H dx|``, exceeds ``relinearize_tol``. Then
    ``P <- Jr(dx) [(I-KH) P_i (I-KH)^T + K R K^T] Jr(dx)^T`` (Joseph form, then the reset to the
    tangent at the new ``X``).
Late fixes
    A fix older than the state (by the walk ``Q`` between the two stamps): if the state was only
    predicted since, the gain uses ``P - Q`` and ``Q`` is added back after the update, which for
    a random walk is exactly updating on time and then predicting; if a newer fix was applied
    meanwhile, ``Q`` is added to the fix's noise instead, ``R <- R + H Q H^T`` (conservative).

Policies (start-up, gaps, kidnap, moved tags, the cap) are in :meth:`MapOdomFilter.update`
and :mod:`tagloc.localize.gating`.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc.errors import TransformLookupError
from tagloc.frames import TransformBuffer
from tagloc.geometry import (
    SE2,
    SE3,
    se2_right_jacobian,
    se2_right_jacobian_inv,
    se3_right_jacobian,
    se3_right_jacobian_inv,
)
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.events import EventKind, EventLog, FilterEvent
from tagloc.localize.fix import (
    CorrectionUpdate,
    FloatArray,
    LocalizeError,
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

logger = logging.getLogger(__name__)
S_NS = 1_000_000_000
PLANAR_AXES = [0, 1, 5]  # x, y, rz of [x, y, z, rx, ry, rz]
_SERIES_BELOW = 0.3  # sum |tau_i| under which Jr, Jr^-1 use their series (error < 1e-6)


def _hat(v: FloatArray) -> FloatArray:
    x, y, z = v.tolist()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def _ad(tau: FloatArray) -> FloatArray:
    """Small adjoint ``ad(tau)`` of se(3) ``[rho, phi]`` or se(2) ``[x, y, theta]``."""
    if len(tau) == 3:
        x, y, th = tau.tolist()
        return np.array([[0.0, -th, y], [th, 0.0, -x], [0.0, 0.0, 0.0]])
    a, b, c, d, e, f = tau.tolist()  # [[phi^, rho^], [0, phi^]]
    return np.array([
        [0.0, -f, e, 0.0, -c, b], [f, 0.0, -d, c, 0.0, -a], [-e, d, 0.0, -b, a, 0.0],
        [0.0, 0.0, 0.0, 0.0, -f, e], [0.0, 0.0, 0.0, f, 0.0, -d], [0.0, 0.0, 0.0, -e, d, 0.0],
    ])  # fmt: skip


def _jr(tau: FloatArray) -> FloatArray:
    """Right Jacobian ``Jr(tau) = sum_k (-ad)^k / (k+1)!`` (series to ``ad^4`` when small)."""
    if float(np.abs(tau).sum()) < _SERIES_BELOW:
        a = _ad(tau)
        a2 = a @ a
        return np.eye(len(tau)) - 0.5 * a + a2 / 6.0 - a2 @ a / 24.0 + a2 @ a2 / 120.0
    return se2_right_jacobian(tau) if len(tau) == 3 else se3_right_jacobian(tau)


def _jr_inv(tau: FloatArray) -> FloatArray:
    """``Jr^-1(tau) = I + ad/2 + ad^2/12 - ad^4/720 + ...`` (Bernoulli numbers; series when
    small)."""
    if float(np.abs(tau).sum()) < _SERIES_BELOW:
        a = _ad(tau)
        a2 = a @ a
        return np.eye(len(tau)) + 0.5 * a + a2 / 12.0 - a2 @ a2 / 720.0
    return se2_right_jacobian_inv(tau) if len(tau) == 3 else se3_right_jacobian_inv(tau)


def _adjoints(R: FloatArray, t: FloatArray, planar: bool) -> FloatArray:
    """``Ad(A_k)`` of odometry poses ``R (N, 3, 3)``, ``t (N, 3)``: SE(3) ``(N, 6, 6)`` or, planar,
    SE(2) of their projections ``(N, 3, 3)``."""
    n = len(R)
    if planar:
        yaw = np.arctan2(R[:, 1, 0], R[:, 0, 0])
        c, s = np.cos(yaw), np.sin(yaw)
        out = np.zeros((n, 3, 3))
        out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = c, -s, t[:, 1]
        out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = s, c, -t[:, 0]
        out[:, 2, 2] = 1.0
        return out
    out = np.zeros((n, 6, 6))
    out[:, :3, :3] = out[:, 3:, 3:] = R
    tx = np.zeros((n, 3, 3))
    tx[:, 0, 1], tx[:, 0, 2], tx[:, 1, 2] = -t[:, 2], t[:, 1], -t[:, 0]
    out[:, :3, 3:] = (tx - np.swapaxes(tx, 1, 2)) @ R
    return out


@dataclass(frozen=True, slots=True)
class _Innovation:
    """A fix linearized at the state: ``nu (d,)``, ``H``, ``S^-1``, ``R`` (d, d), the prior
    covariance ``P_fix`` the gain uses (the state's at the fix's stamp), and ``d2``."""

    nu: FloatArray
    H: FloatArray
    S_inv: FloatArray
    R: FloatArray
    P_fix: FloatArray
    d2: float


@dataclass(frozen=True, slots=True)
class ProcessNoise:
    """Random walk of ``T_map_odom`` driven by the odometry's motion.

    Attributes
    ----------
    var_per_m, var_per_rad, var_per_s : (d,) float
        Variance per metre travelled, per radian rotated, per second, of the base-frame axes
        (``[x, y, z, rx, ry, rz]``, or ``[x, y, theta]`` planar).
    step_ns : int
        Sampling step of the odometry path (long intervals are integrated piecewise).
    """

    var_per_m: FloatArray
    var_per_rad: FloatArray
    var_per_s: FloatArray
    step_ns: int

    def covariance(
        self, stamps_ns: npt.NDArray[np.int64], R: FloatArray, t: FloatArray, planar: bool
    ) -> tuple[FloatArray, float]:
        """``sum_k Ad(A_k) Q_k Ad(A_k)^T`` over the increments between odometry samples
        ``A_k = (R[k], t[k])`` at ``stamps_ns (N,)`` (``R (N, 3, 3)``, ``t (N, 3)``), and the
        distance travelled (m)."""
        dR = np.swapaxes(R[:-1], 1, 2) @ R[1:]
        dist = np.linalg.norm(np.diff(t, axis=0), axis=1)
        cos = np.clip(0.5 * (np.trace(dR, axis1=1, axis2=2) - 1.0), -1.0, 1.0)
        dt = np.abs(np.diff(stamps_ns)) / S_NS
        var = (
            np.outer(dist, self.var_per_m)
            + np.outer(np.arccos(cos), self.var_per_rad)
            + np.outer(dt, self.var_per_s)
        )
        Ad = _adjoints(R[1:], t[1:], planar)
        Q = np.einsum("kij,kj,klj->il", Ad, var, Ad)
        return Q, float(dist.sum())

    def increment(
        self, dt_ns: int, R0: FloatArray, t0: FloatArray, R1: FloatArray, t1: FloatArray,
        planar: bool,
    ) -> tuple[FloatArray, float]:  # fmt: skip
        """:meth:`covariance` for one increment ``(R0, t0) -> (R1, t1)`` (the per-fix path)."""
        d = t1 - t0
        dist = math.sqrt(float(d @ d))
        cos = 0.5 * (float(np.vdot(R0, R1)) - 1.0)  # trace(R0^T R1) = sum(R0 * R1)
        angle = math.acos(min(1.0, max(-1.0, cos)))
        var = dist * self.var_per_m + angle * self.var_per_rad + (dt_ns / S_NS) * self.var_per_s
        if planar:
            c, s = R1[0, 0], R1[1, 0]
            n = math.hypot(c, s)
            Ad = np.array([[c / n, -s / n, t1[1]], [s / n, c / n, -t1[0]], [0.0, 0.0, 1.0]])
        else:
            Ad = np.zeros((6, 6))
            Ad[:3, :3] = Ad[3:, 3:] = R1
            Ad[:3, 3:] = _hat(t1) @ R1
        return (Ad * var) @ Ad.T, dist


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
        Or from this many such fixes of one source (0: never from one source).
    suspect_min_gated, suspect_clear_after : int
        See :class:`~tagloc.localize.gating.SourceMonitor`.
    max_iterations : int
    relinearize_tol : float
    history_size, max_events : int
        Published corrections and events kept.
    """

    def __init__(
        self, buffer: TransformBuffer, *, map_frame: str, odom_frame: str, base_frame: str,
        planar: bool, noise: ProcessNoise, chi2_quantile: float, quality: QualityLimits,
        k_consistent: int, consistency_window_ns: int, gap_ns: int, gap_m: float,
        cap: CorrectionCap, kidnap_n: int, kidnap_min_sources: int, kidnap_window_ns: int,
        kidnap_n_one_source: int = 0,
        suspect_min_gated: int, suspect_clear_after: int, max_iterations: int,
        relinearize_tol: float, history_size: int, max_events: int,
    ) -> None:  # fmt: skip
        self._buffer = buffer
        self.map_frame, self.odom_frame, self.base_frame = map_frame, odom_frame, base_frame
        self.planar = planar
        self.dof = 3 if planar else 6
        self._noise, self._quality, self._cap = noise, quality, cap
        self.threshold = chi2_threshold(chi2_quantile, self.dof)
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
        self._sources = SourceMonitor(suspect_min_gated, suspect_clear_after)
        self._last_gated: dict[str, Candidate] = {}  # per source, for the suspect test
        self._batch: tuple[tuple[TagFix, EventKind], ...] = ()
        self.batch_serial = 0
        self.events = EventLog(max_events)
        self._history: deque[CorrectionUpdate] = deque(maxlen=history_size)
        self._X: Pose | None = None
        self._P = np.zeros((self.dof, self.dof))
        self._stamp = self._updated_ns = 0  # predicted to; last fix applied at
        self._A = SE3.identity()  # T_odom_base at the state's stamp
        self._odometer_m = 0.0
        self._published: Pose | None = None
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
            suspect_min_gated=config.suspect.min_gated,
            suspect_clear_after=config.suspect.clear_after,
            max_iterations=config.filter.max_iterations,
            relinearize_tol=config.filter.relinearize_tol,
            history_size=config.filter.history_size, max_events=config.filter.max_events,
        )  # fmt: skip

    # ----- outputs ---------------------------------------------------------------------------
    @property
    def initialized(self) -> bool:
        """True once the state exists (after ``k`` consistent fixes or :meth:`initialize`)."""
        return self._X is not None

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
        return self._embed(self._P)

    @property
    def corrections(self) -> tuple[CorrectionUpdate, ...]:
        """Published ``map -> odom`` corrections (stamps non-decreasing), oldest first."""
        return tuple(self._history)

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
        for correction in reversed(self._history):  # queries are mostly recent
            if correction.stamp_ns <= stamp_ns:
                return correction.T_map_odom
        first = f"the first is at {self._history[0].stamp_ns} ns" if self._history else "none yet"
        raise LocalizeError(f"no map -> odom correction at {stamp_ns} ns ({first})")

    def pose_at(self, stamp_ns: int, *, published: bool = False) -> PoseWithCovariance:
        """``T_map_base = T_map_odom @ T_odom_base(stamp_ns)`` with covariance.

        ``cov = Ad(A^-1) (P + Q) Ad(A^-1)^T`` with ``Q`` the random walk between the state's
        stamp and ``stamp_ns``. ``published=True`` composes the published (capped) correction
        instead of the estimate (same covariance).

        Raises
        ------
        LocalizeError
            Before initialization.
        TransformLookupError
            If the odometry at ``stamp_ns`` (or on the path to it) is not buffered.
        """
        X = self._require()
        A3 = self._lookup(stamp_ns)
        P = self._P + self._noise_between(stamp_ns, self._stamp, A3, self._A)[0]
        if published and self._published is not None:
            X = self._published
        J = A3.inverse().adjoint()
        cov = J @ self._embed(P) @ J.T
        return PoseWithCovariance(
            stamp_ns, self.map_frame, self.base_frame, self._lift(X) @ A3, 0.5 * (cov + cov.T)
        )

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
        """Advance the state to ``stamp_ns``.

        Optional: :meth:`update` and :meth:`pose_at` integrate the odometry path themselves.
        The path is integrated in steps of ``motion_step``: a stamp less than one step after
        the state's returns at once (so calling this at the odometry rate costs little), as
        does any call before initialization.

        Raises
        ------
        TransformLookupError
            If the odometry at ``stamp_ns`` is not buffered.
        """
        if self._X is not None and stamp_ns - self._stamp >= self._noise.step_ns:
            self._advance(stamp_ns, self._lookup(stamp_ns))

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

    # ----- policies --------------------------------------------------------------------------
    def _decide(self, cand: Candidate) -> FilterEvent:
        """Chi-square gate against the state, then the update (or the kidnap / suspect books)."""
        fix = cand.fix
        Q_back = None
        if fix.stamp_ns < self._stamp:  # late: the state moved on since the fix's stamp
            Q_back = self._noise_between(fix.stamp_ns, self._stamp, cand.odom, self._A)[0]
        innov = self._innovation(cand, Q_back)
        d2 = innov.d2
        if d2 > self.threshold:
            event = self._event(fix.stamp_ns, EventKind.GATED_CHI2, fix.source, d2)
            last = self._last_gated.get(fix.source)
            self._last_gated[fix.source] = cand
            consistent = last is not None and (
                pair_d2(last, cand, self._pair_noise(last, cand)) <= self.threshold
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
                if found is None and self._kidnap_one is not None:
                    self._kidnap_one.expire(fix.stamp_ns)
                    found = self._kidnap_one.add(cand)
                if found is not None:
                    self._reinitialize(found, EventKind.REINITIALIZED_KIDNAP)
            return event
        self._X, self._P = self._iekf(cand, innov)
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

    def _set_batch(self, batch: list[tuple[TagFix, EventKind]]) -> None:
        self._batch = tuple(batch)
        self.batch_serial += 1

    def _gated_now(self, cand: Candidate) -> bool:
        """Whether ``cand`` fails the chi-square gate against the current state."""
        Q_back = None
        if cand.stamp_ns < self._stamp:
            Q_back = self._noise_between(cand.stamp_ns, self._stamp, cand.odom, self._A)[0]
        return self._innovation(cand, Q_back).d2 > self.threshold

    def _reinitialize(self, found: list[Candidate], kind: EventKind) -> None:
        """Restart the state from consistent fixes (oldest first): the first sets ``X`` and
        ``P``, the others are applied as updates."""
        first = found[0]
        self._reset_state(first.stamp_ns, first.odom, first.T_map_odom, first.cov)
        for cand in found[1:]:
            if cand.stamp_ns > self._stamp:
                self._advance(cand.stamp_ns, cand.odom)
            self._X, self._P = self._iekf(cand, self._innovation(cand, None))
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
        snap = self._cap.snap_on_initialize or self._published is None
        self._publish(self._stamp, snap=snap)

    def _reset_state(self, stamp_ns: int, odom: SE3, X: Pose, P: FloatArray) -> None:
        self._X, self._P, self._stamp, self._A = X, np.array(P), stamp_ns, odom
        self._updated_ns = stamp_ns
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
        return self._buffer.lookup(self.odom_frame, self.base_frame, stamp_ns)

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
        return self._noise_between(a.stamp_ns, b.stamp_ns, a.odom, b.odom)[0]

    def _noise_between(self, t0: int, t1: int, A0: SE3, A1: SE3) -> tuple[FloatArray, float]:
        """Random-walk covariance and distance over the odometry path between two stamps."""
        (lo, A_lo), (hi, A_hi) = sorted(((t0, A0), (t1, A1)), key=lambda p: p[0])
        R_lo, t_lo = A_lo.rotation.matrix, A_lo.translation
        R_hi, t_hi = A_hi.rotation.matrix, A_hi.translation
        n = math.ceil((hi - lo) / self._noise.step_ns)
        if n <= 1:
            return self._noise.increment(hi - lo, R_lo, t_lo, R_hi, t_hi, self.planar)
        inner = lo + np.round(np.arange(1, n) * ((hi - lo) / n)).astype(np.int64)
        try:
            mid = self._buffer.lookup_many(self.odom_frame, self.base_frame, inner)
        except TransformLookupError as exc:
            logger.warning("odometry path %d..%d ns not buffered (%s): chord used", lo, hi, exc)
            return self._noise.increment(hi - lo, R_lo, t_lo, R_hi, t_hi, self.planar)
        stamps = np.concatenate([[lo], inner, [hi]])
        R = np.concatenate([R_lo[None], mid.rotation.matrix, R_hi[None]])
        t = np.concatenate([t_lo[None], mid.translation, t_hi[None]])
        return self._noise.covariance(stamps, R, t, self.planar)

    def _advance(self, stamp_ns: int, odom: SE3) -> None:
        """Predict: ``P <- P + Q`` over the odometry path from the state's stamp."""
        Q, dist = self._noise_between(self._stamp, stamp_ns, self._A, odom)
        self._P = self._P + Q
        self._stamp, self._A = stamp_ns, odom
        self._odometer_m += dist

    def _innovation(self, cand: Candidate, Q_back: FloatArray | None) -> _Innovation:
        """Linearize a fix at the state. For a fix older than the state (``Q_back``: the random
        walk from its stamp to the state's): if the state was only predicted since, the gain
        uses the covariance at the fix's stamp, ``P - Q_back`` (exact for a random walk: the
        same as updating on time, then predicting); if a newer fix was applied meanwhile, the
        walk is added to the fix's noise instead, ``R + H Q_back H^T`` (conservative)."""
        X, P = self._require(), self._P
        nu = cand.z.minus(X @ cand.A)  # type: ignore[operator, arg-type]
        H = _jr_inv(-nu) @ cand.Ad_A_inv
        P_fix, R = P, cand.R
        if Q_back is not None and self._updated_ns <= cand.stamp_ns:
            P_fix = P - Q_back
            try:  # a differently sampled path could overshoot: then the conservative way
                np.linalg.cholesky(P_fix)
            except np.linalg.LinAlgError:
                P_fix, R = P, R + H @ Q_back @ H.T
        elif Q_back is not None:
            R = R + H @ Q_back @ H.T
        S_inv = np.linalg.inv(H @ P_fix @ H.T + R).astype(np.float64, copy=False)
        return _Innovation(nu, H, S_inv, R, P_fix, float(nu @ S_inv @ nu))

    def _iekf(self, cand: Candidate, innov: _Innovation) -> tuple[Pose, FloatArray]:
        """Iterated error-state update (module docstring); returns the new ``X`` and ``P``.
        Relinearizes while the step seen at the base, ``|H dx|``, exceeds the tolerance."""
        X0, P0, R = self._require(), innov.P_fix, innov.R
        X, Pi, m, nu, H, S_inv = X0, P0, None, innov.nu, innov.H, innov.S_inv
        for i in range(self._max_iter):
            if i:  # relinearize at X: prior mean and covariance moved into X's tangent
                e = X.minus(X0)  # type: ignore[arg-type]
                Je = _jr(e)
                m, Pi = -Je @ e, Je @ P0 @ Je.T
                nu = cand.z.minus(X @ cand.A)  # type: ignore[operator, arg-type]
                H = _jr_inv(-nu) @ cand.Ad_A_inv
                S_inv = np.linalg.inv(H @ Pi @ H.T + R).astype(np.float64, copy=False)
            K = Pi @ H.T @ S_inv
            dx = K @ nu if m is None else m + K @ (nu - H @ m)
            X_new = X.plus(dx)
            if float(np.abs(H @ dx).max()) <= self._tol:
                break
            X = X_new
        IKH = np.eye(self.dof) - K @ H
        Jd = _jr(dx)
        P = Jd @ (IKH @ Pi @ IKH.T + K @ R @ K.T) @ Jd.T  # Joseph form, then the reset
        # Plus the walk since the fix's stamp when the gain used P - Q_back (the walk's
        # covariance, Ad(A) Q Ad(A)^T, does not depend on X: no reset for it).
        P = P + (self._P - P0)
        return X_new, 0.5 * (P + P.T)

    def _publish(self, stamp_ns: int, *, snap: bool) -> None:
        """Publish ``T_map_odom`` moved toward the estimate by at most the cap per update."""
        X = self._require()
        new = X
        if self._published is not None and not snap:
            A = self._A.to_se2() if self.planar else self._A
            X_A = X @ A  # type: ignore[operator]
            jump = (self._published @ A).inverse() @ X_A  # type: ignore[operator]
            step, clipped = self._cap.clip(jump)
            if clipped:  # new @ A = published @ A @ step; built from X (no round-off build-up)
                rest = step.inverse() @ jump  # type: ignore[operator]
                new = X_A @ rest.inverse() @ A.inverse()  # type: ignore[operator]
                angle = float(np.linalg.norm(rest.log()[2 if self.planar else 3 :]))
                self._event(
                    stamp_ns, EventKind.CAPPED,
                    detail=f"remainder {np.linalg.norm(rest.translation):.3f} m, "
                    f"{math.degrees(angle):.2f} deg",
                )  # fmt: skip
        self._published = new
        last = self._history[-1].stamp_ns if self._history else stamp_ns
        self._history.append(CorrectionUpdate(max(stamp_ns, last), self._lift(new)))

    def _event(
        self, stamp_ns: int, kind: EventKind, source: str = "", d2: float | None = None,
        threshold: float | None = None, detail: str = "",
    ) -> FilterEvent:  # fmt: skip
        if d2 is not None and threshold is None:
            threshold = self.threshold
        return self.events.append(FilterEvent(stamp_ns, kind, source, d2, threshold, detail))
