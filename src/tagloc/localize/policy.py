"""``FixPolicy``: what the ``map -> odom`` estimator is given, and what is published.

The estimator (:class:`~tagloc.localize.estimator.MapOdomEstimator`) applies whatever fix it is
handed; the policy decides for each fix (:meth:`FixPolicy.decide`), in order:

1. quality: a fix past the reprojection, ambiguity or range limits never reaches the state or
   the published correction (:class:`~tagloc.localize.gating.QualityLimits`);
2. the odometry at the fix's own stamp (none buffered: ``NO_ODOMETRY``);
3. start-up: fixes are held until ``k`` mutually consistent ones initialize the state;
4. the state is predicted to the fix's stamp;
5. a fix of a suspect source (a moved tag) is rejected; passing the gate counts toward clearing;
6. after a gap (:class:`~tagloc.localize.recovery.GapRule`) fixes are held again until ``k``
   consistent ones, which re-initialize the state if all disagree with it, else are applied;
7. the chi-square gate ``d2 <= chi2.ppf(q, dof)``; a gated fix feeds the suspect and kidnap
   books (:class:`~tagloc.localize.recovery.RecoveryBooks`), which may flag its source or
   re-initialize the state from consistent gated fixes;
8. the update, and the publication clipped to the cap and the speed limit
   (:class:`~tagloc.localize.publisher.CorrectionPublisher`); (re)initializations snap.

A partial fix (:meth:`FixPolicy.decide_partial`) is gated on its own dof and applied; it cannot
start the state and feeds neither book. Every decision is a
:class:`~tagloc.localize.events.FilterEvent` in :attr:`FixPolicy.events`.
"""

from __future__ import annotations

import math

import numpy as np

from tagloc._types import FloatArray
from tagloc.errors import TransformLookupError
from tagloc.geometry import SE3
from tagloc.localize.candidate import Candidate
from tagloc.localize.config import CapConfig, FilterConfig, KidnapConfig, SuspectConfig
from tagloc.localize.config_tags import GatesConfig
from tagloc.localize.estimator import MapOdomEstimator
from tagloc.localize.events import EventKind, EventLog, FilterEvent
from tagloc.localize.fix import PartialFix, TagFix
from tagloc.localize.gating import ConsistencyBuffer, CorrectionCap, QualityLimits, chi2_threshold
from tagloc.localize.publisher import CorrectionPublisher
from tagloc.localize.recovery import GapRule, KidnapRule, RecoveryBooks, SuspectRule
from tagloc.units import S_NS

__all__ = ["FixPolicy"]



class FixPolicy:
    """Decides on fixes for one estimator and publishes its correction (module docstring).

    Parameters
    ----------
    estimator, cap : MapOdomEstimator, CorrectionCap
    quality : QualityLimits
    chi2_quantile : float
        Gate quantile; the threshold is ``chi2.ppf(q, dof)`` (a partial fix: its ``k`` dof).
    k_consistent, consistency_window_ns : int
        Start-up and re-acquisition need ``k`` mutually consistent fixes within the window.
    gap : GapRule
    kidnap, suspect : KidnapRule, SuspectRule
    cap : CorrectionCap
        Per-update cap of the published correction (and whether a (re)initialization snaps).
    history_size, max_events : int
        Published corrections and events kept.
    speed_limit : (float, float), optional
        Speed limit of the published correction, (m/s, rad/s).

    Attributes
    ----------
    estimator : MapOdomEstimator
    threshold : float
        The chi-square gate of a full fix.
    events : EventLog
    publisher : CorrectionPublisher
        The published correction and its history.
    recovery : RecoveryBooks
        The suspect-source and kidnap books (``recovery.sources``: per-source statistics).
    batch_serial : int
        Counts the batch decisions (:attr:`last_batch`).
    """

    def __init__(
        self, estimator: MapOdomEstimator, *, quality: QualityLimits, chi2_quantile: float,
        k_consistent: int, consistency_window_ns: int, gap: GapRule, kidnap: KidnapRule,
        suspect: SuspectRule, cap: CorrectionCap, history_size: int, max_events: int,
        speed_limit: tuple[float, float] | None = None,
    ) -> None:  # fmt: skip
        self.estimator = est = estimator
        self._quality, self._quantile = quality, chi2_quantile
        self.threshold = chi2_threshold(chi2_quantile, est.dof)
        pair_noise = est.path.pair_noise
        self._held = ConsistencyBuffer(k_consistent, consistency_window_ns, self.threshold, 1,
                                       pair_noise)  # fmt: skip
        self.recovery = RecoveryBooks(kidnap, suspect, self.threshold, pair_noise)
        self._kidnap_on = kidnap.n_fixes > 0
        self.cap = cap
        self.events = EventLog(max_events)
        self.publisher = CorrectionPublisher(cap, history_size, est.planar, self._capped,
                                             speed_limit)  # fmt: skip
        self._batch: tuple[tuple[TagFix, EventKind], ...] = ()
        self.batch_serial = 0
        self._gap = gap

    @classmethod
    def from_config(
        cls, estimator: MapOdomEstimator, gates: GatesConfig, kidnap: KidnapConfig,
        suspect: SuspectConfig, cap: CapConfig, filter: FilterConfig,
    ) -> FixPolicy:  # fmt: skip
        """From the sections of ``localizer.yaml`` (seconds become nanoseconds, degrees
        radians; the speed limit None when neither of its bounds is set)."""
        v, w = cap.max_speed_m_s, cap.max_rate_deg_s
        speed = None if v is None and w is None else (
            math.inf if v is None else v, math.inf if w is None else math.radians(w)
        )  # fmt: skip
        return cls(
            estimator,
            quality=QualityLimits(gates.max_reproj_err_px, gates.max_ambiguity_ratio,
                                  gates.max_range_m),
            chi2_quantile=gates.chi2_quantile, k_consistent=gates.k_consistent,
            consistency_window_ns=round(gates.consistency_window_s * S_NS),
            gap=GapRule(round(gates.gap_s * S_NS), gates.gap_m),
            kidnap=KidnapRule.from_config(kidnap), suspect=SuspectRule.from_config(suspect, kidnap),
            cap=CorrectionCap(cap.max_translation_m, math.radians(cap.max_rotation_deg),
                              cap.snap_on_initialize),
            history_size=filter.history_size, max_events=filter.max_events, speed_limit=speed,
        )  # fmt: skip

    @property
    def reacquiring(self) -> bool:
        """True after a gap until ``k`` consistent fixes re-acquire the state."""
        return self._gap.active

    @property
    def last_batch(self) -> tuple[tuple[TagFix, EventKind], ...]:
        """The fixes the latest batch decision used, each with its final decision: the
        consistent set of a (re)initialization, or the held fixes applied after a gap."""
        return self._batch

    # ----- inputs ----------------------------------------------------------------------------
    def initialize(self, stamp_ns: int, T_map_odom: SE3, cov: FloatArray) -> FilterEvent:
        """An explicit prior (:meth:`MapOdomEstimator.initialize
        <tagloc.localize.estimator.MapOdomEstimator.initialize>`), published at once."""
        self.estimator.initialize(stamp_ns, T_map_odom, cov)
        self._gap.restart(stamp_ns, self.estimator.odometer_m)
        self._publish(stamp_ns, snap=True)
        return self._event(stamp_ns, EventKind.INITIALIZED, detail="explicit prior")

    def predict(self, stamp_ns: int) -> None:
        """An odometry sample at ``stamp_ns``: predict once a motion step has passed (the
        published correction drifts with the state) and end one odometry step of the cap."""
        est = self.estimator
        if not est.initialized:
            return
        if stamp_ns - est.stamp_ns >= est.path.noise.step_ns:
            self._advance(stamp_ns, est.path.lookup(stamp_ns))
        self.publisher.end_step(stamp_ns, lambda: est.path.lookup(stamp_ns))  # at the robot

    def decide(self, fix: TagFix) -> FilterEvent:
        """Decide on one fix and apply it if it passes (module docstring, steps 1-8); return
        the decision event (filter-level events it caused follow it in :attr:`events`)."""
        limit = self._quality.check(fix.quality)
        if limit is not None:
            kind, _, bound, detail = limit
            return self._event(fix.stamp_ns, kind, fix.source, None, bound, detail)
        est = self.estimator
        try:
            A3 = est.path.lookup(fix.stamp_ns)
        except TransformLookupError as exc:
            return self._event(fix.stamp_ns, EventKind.NO_ODOMETRY, fix.source, detail=str(exc))
        cand = Candidate.of_fix(fix, A3, est.planar)
        if not est.initialized:
            return self._hold(cand, initial=True)
        if fix.stamp_ns > est.stamp_ns:
            self._advance(fix.stamp_ns, A3)
        if self.recovery.sources.is_suspect(fix.source):
            return self._reject_suspect(cand)
        if not self._gap.active:
            began = self._gap.starts(fix.stamp_ns, est.odometer_m)
            if began is None:
                return self._gate(cand)
            self._event(fix.stamp_ns, EventKind.GAP, detail=began)
        return self._hold(cand, initial=False)

    def decide_partial(self, fix: PartialFix) -> FilterEvent:
        """Decide on a fix that measures only the directions ``fix.basis``: the chi-square gate
        on its ``k`` dof, then :meth:`MapOdomEstimator.update_partial
        <tagloc.localize.estimator.MapOdomEstimator.update_partial>`. It cannot start the
        state (``UNUSED_NO_STATE``), does not wait for consistent fixes after a gap and feeds
        neither book; one that measures every direction (``k = dof`` after the planar
        projection) and is accepted counts for the gap rule (and ends a gap)."""
        est = self.estimator
        try:
            A3 = est.path.lookup(fix.stamp_ns)
        except TransformLookupError as exc:
            return self._event(fix.stamp_ns, EventKind.NO_ODOMETRY, fix.source, detail=str(exc))
        if not est.initialized:
            return self._event(fix.stamp_ns, EventKind.UNUSED_NO_STATE, fix.source)
        if fix.stamp_ns > est.stamp_ns:
            self._advance(fix.stamp_ns, A3)
        cand = Candidate.of_partial(fix, A3, est.planar)
        k = cand.R.shape[0]
        if k == 0:
            return self._event(fix.stamp_ns, EventKind.GATED_QUALITY, fix.source,
                               detail="no measured direction in the plane")  # fmt: skip
        innov = est.innovation(cand)
        threshold = chi2_threshold(self._quantile, k)
        if innov.d2 > threshold:
            return self._event(fix.stamp_ns, EventKind.GATED_CHI2, fix.source, innov.d2, threshold)
        est.update_partial(cand, innov)
        if k == est.dof:
            if self._gap.active:  # a fix of every direction ends a gap
                self._gap.active = False
                self._discard(self._held.clear())
            self._gap.accepted(fix.stamp_ns, est.odometer_m)
        event = self._event(fix.stamp_ns, EventKind.ACCEPTED, fix.source, innov.d2, threshold)
        self._publish(fix.stamp_ns, snap=False)
        return event

    # ----- decisions -------------------------------------------------------------------------
    def _gate(self, cand: Candidate) -> FilterEvent:
        """Chi-square gate against the state, then the update (or the recovery books)."""
        fix, est = cand.fix, self.estimator
        innov = est.innovation(cand)
        d2 = innov.d2
        if d2 > self.threshold:
            event = self._event(fix.stamp_ns, EventKind.GATED_CHI2, fix.source, d2)
            flagged, found = self.recovery.on_gated(cand, d2, est.pose)
            if flagged:
                stats = self.recovery.sources.stats[fix.source]
                self._event(
                    fix.stamp_ns, EventKind.SUSPECT_SOURCE, fix.source, d2,
                    detail=f"{stats.streak_gated} fixes gated in a row while other sources "
                    "were accepted: moved or mis-surveyed?",
                )  # fmt: skip
            elif found is not None:
                self._reinitialize(found, EventKind.REINITIALIZED_KIDNAP)
            return event
        est.update(cand, innov)
        self.recovery.on_accepted(fix.source, d2)
        self._gap.accepted(fix.stamp_ns, est.odometer_m)
        event = self._event(fix.stamp_ns, EventKind.ACCEPTED, fix.source, d2)
        self._publish(fix.stamp_ns, snap=False)
        return event

    def _reject_suspect(self, cand: Candidate) -> FilterEvent:
        """A fix of a suspect source: not applied; passing the gate (against the state as it
        is) counts toward clearing."""
        fix = cand.fix
        d2 = self.estimator.innovation(cand, late=False).d2
        event = self._event(fix.stamp_ns, EventKind.REJECTED_SUSPECT, fix.source, d2)
        if self.recovery.on_suspect_fix(fix.source, d2 <= self.threshold):
            self._event(fix.stamp_ns, EventKind.SOURCE_CLEARED, fix.source, d2)
        return event

    def _hold(self, cand: Candidate, *, initial: bool) -> FilterEvent:
        """Hold a fix until ``k`` mutually consistent ones; then initialize or apply them."""
        self._discard(self._held.expire(cand.stamp_ns))
        event = self._event(
            cand.stamp_ns, EventKind.PENDING_CONSISTENCY, cand.fix.source,
            detail=f"{len(self._held) + 1} buffered",
        )  # fmt: skip
        found = self._held.add(cand)
        if found is None:
            return event
        if initial:
            self._reinitialize(found, EventKind.INITIALIZED)
            return event
        self._discard(self._held.clear())
        self._gap.restart(found[-1].stamp_ns, self.estimator.odometer_m)
        if self._kidnap_on and all(
            self.estimator.innovation(m).d2 > self.threshold for m in found
        ):
            # Re-acquisition after a gap: k consistent fixes that all disagree with the stale
            # state re-initialize it (the start-up rule), instead of waiting for the kidnap
            # test's second source: the state is unconfirmed, the k fixes agree.
            self._reinitialize(found, EventKind.REINITIALIZED_KIDNAP)
            return event
        self._set_batch([(m.fix, self._gate(m).kind) for m in found])
        return event

    def _reinitialize(self, found: list[Candidate], kind: EventKind) -> None:
        """Restart the state from consistent fixes (oldest first): the first sets ``X`` and
        ``P``, the others are applied as updates."""
        est, first = self.estimator, found[0]
        est.reset(first.stamp_ns, first.odom, first.T_map_odom, first.cov)
        self._gap.restart(first.stamp_ns, est.odometer_m)
        for cand in found[1:]:
            if cand.stamp_ns > est.stamp_ns:
                self._advance(cand.stamp_ns, cand.odom)
            est.update(cand, est.innovation(cand, late=False), newest=False)
        self._gap.restart(est.stamp_ns, est.odometer_m)
        self.recovery.on_reinitialized(found)
        self._discard(self._held.clear())
        self._set_batch([(c.fix, kind) for c in found])
        sources = "+".join(sorted({c.fix.source for c in found}))
        t = est.T_map_odom.translation
        self._event(
            est.stamp_ns, kind, sources,
            detail=f"from {len(found)} consistent fixes; T_map_odom t = {np.round(t, 3)}",
        )  # fmt: skip
        snap = self.cap.snap_on_initialize or self.publisher.current is None
        self._publish(est.stamp_ns, snap=snap)

    # ----- helpers ---------------------------------------------------------------------------
    def _advance(self, stamp_ns: int, odom: SE3) -> None:
        """Predict the estimator; the published correction drifts with it (recorded by the
        next publication or odometry step)."""
        est = self.estimator
        motion = est.predict(stamp_ns, odom)
        if self.publisher.current is not None and est.path.calibration is not None:
            self.publisher.drift(est.drifted(self.publisher.current, motion))

    def _set_batch(self, batch: list[tuple[TagFix | PartialFix, EventKind]]) -> None:
        self._batch = tuple((f, k) for f, k in batch if isinstance(f, TagFix))  # tag fixes only
        self.batch_serial += 1

    def _discard(self, held: list[Candidate]) -> None:
        for old in held:
            self._event(old.stamp_ns, EventKind.DISCARDED_CANDIDATE, old.fix.source)

    def _publish(self, stamp_ns: int, *, snap: bool) -> None:
        est = self.estimator
        self.publisher.publish(est.pose, stamp_ns, est.odom, snap=snap)

    def _capped(self, stamp_ns: int, detail: str) -> None:
        self._event(stamp_ns, EventKind.CAPPED, detail=detail)

    def _event(
        self, stamp_ns: int, kind: EventKind, source: str = "", d2: float | None = None,
        threshold: float | None = None, detail: str = "",
    ) -> FilterEvent:  # fmt: skip
        if d2 is not None and threshold is None:
            threshold = self.threshold
        return self.events.append(FilterEvent(stamp_ns, kind, source, d2, threshold, detail))
