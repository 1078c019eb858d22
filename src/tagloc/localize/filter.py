"""``MapOdomFilter``: the ``map -> odom`` filter, one estimator and one fix policy composed.

- :class:`~tagloc.localize.estimator.MapOdomEstimator` (:mod:`tagloc.localize.estimator`): the
  state ``T_map_odom`` on SE(3) (planar: SE(2)), the odometry calibration, the covariance, the
  odometry path integral (:mod:`tagloc.localize.odometry_path`) and the iterated EKF
  (:mod:`tagloc.localize.iekf`); it applies what it is given.
- :class:`~tagloc.localize.policy.FixPolicy` (:mod:`tagloc.localize.policy`): decides what the
  estimator is given (quality gates, start-up consistency, gaps, the chi-square gate, suspect
  sources and the kidnap test, :mod:`tagloc.localize.recovery`) and publishes the capped
  correction (:mod:`tagloc.localize.publisher`), logging every decision as an event.

:class:`MapOdomFilter` is the interface the node and the tools use: it owns one of each and
delegates (:attr:`MapOdomFilter.estimator`, :attr:`MapOdomFilter.policy`).
"""

from __future__ import annotations

from tagloc._types import FloatArray
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.estimator import MapOdomEstimator
from tagloc.localize.events import EventKind, FilterEvent
from tagloc.localize.fix import (
    CorrectionUpdate,
    LocalizeError,
    PartialFix,
    PoseWithCovariance,
    TagFix,
)
from tagloc.localize.motion import ProcessNoise
from tagloc.localize.policy import FixPolicy

__all__ = ["MapOdomFilter", "ProcessNoise"]


class MapOdomFilter:
    """The ``map -> odom`` filter: fixes in, corrections, poses and events out.

    Parameters
    ----------
    estimator : MapOdomEstimator
    policy : FixPolicy
        Built on ``estimator`` (``policy.estimator is estimator``).

    Attributes
    ----------
    estimator : MapOdomEstimator
    policy : FixPolicy
    map_frame, odom_frame, base_frame : str
    planar : bool
    dof : int
        6, or 3 planar.
    threshold : float
        The chi-square gate of a full fix, ``chi2.ppf(q, dof)``.
    events : EventLog
        Every decision (the node listens to it).
    source_stats : SourceMonitor
        Per-source counts and innovation statistics (``stats[source].mean_nis``).
    """

    def __init__(self, estimator: MapOdomEstimator, policy: FixPolicy) -> None:
        if policy.estimator is not estimator:
            raise LocalizeError("MapOdomFilter: the policy must decide for this estimator")
        self.estimator, self.policy = estimator, policy
        self.map_frame, self.base_frame = estimator.map_frame, estimator.base_frame
        self.odom_frame = estimator.path.odom_frame
        self.planar, self.dof = estimator.planar, estimator.dof
        self.threshold = policy.threshold
        self.events = policy.events
        self.source_stats = policy.recovery.sources

    @classmethod
    def from_config(cls, config: LocalizerConfig, buffer: TransformBuffer) -> MapOdomFilter:
        """Build from ``localizer.yaml``'s model: the estimator from ``frames``,
        ``process_noise``, ``calibration`` and ``filter``, the policy from ``gates``, ``kidnap``,
        ``suspect``, ``cap`` and ``filter``."""
        c = config
        estimator = MapOdomEstimator.from_config(
            buffer, c.frames, c.process_noise, c.calibration, c.filter
        )
        policy = FixPolicy.from_config(estimator, c.gates, c.kidnap, c.suspect, c.cap, c.filter)
        return cls(estimator, policy)

    # ----- outputs ---------------------------------------------------------------------------
    @property
    def initialized(self) -> bool:
        """True once the state exists (after ``k`` consistent fixes or :meth:`initialize`)."""
        return self.estimator.initialized

    @property
    def reacquiring(self) -> bool:
        """True after a gap until ``k`` consistent fixes re-acquire the state."""
        return self.policy.reacquiring

    @property
    def stamp_ns(self) -> int:
        """Stamp the state was last predicted to (ns)."""
        return self.estimator.stamp_ns

    @property
    def revision(self) -> int:
        """Counts the changes of the state (:attr:`MapOdomEstimator.revision
        <tagloc.localize.estimator.MapOdomEstimator.revision>`)."""
        return self.estimator.revision

    @property
    def T_map_odom(self) -> SE3:
        """The estimate (not the capped published correction, see :meth:`correction_at`)."""
        return self.estimator.T_map_odom

    @property
    def covariance(self) -> FloatArray:
        """``(6, 6)`` right-tangent covariance of :attr:`T_map_odom`, ``[x, y, z, rx, ry, rz]``
        (planar: zero rows and columns for z, rx, ry)."""
        return self.estimator.covariance

    @property
    def odometry_calibration(self) -> tuple[FloatArray, FloatArray] | None:
        """The estimated odometry calibration and its 1-sigma, or None when not estimated."""
        return self.estimator.odometry_calibration

    @property
    def corrections(self) -> tuple[CorrectionUpdate, ...]:
        """Published ``map -> odom`` corrections (stamps non-decreasing), oldest first."""
        return self.policy.publisher.history

    @property
    def suspect_sources(self) -> tuple[str, ...]:
        """Sources flagged suspect (e.g. ``("tag:17",)`` for a moved tag), sorted."""
        return self.source_stats.suspects

    @property
    def last_batch(self) -> tuple[tuple[TagFix, EventKind], ...]:
        """The fixes the latest batch decision used, each with its final decision: the
        consistent set of a (re)initialization, or the held fixes applied after a gap.
        :attr:`batch_serial` counts batches, so a caller sees when a new one happened."""
        return self.policy.last_batch

    @property
    def batch_serial(self) -> int:
        """Counts the batch decisions (:attr:`last_batch`)."""
        return self.policy.batch_serial

    def correction_at(self, stamp_ns: int) -> SE3:
        """The published ``T_map_odom`` in force at ``stamp_ns`` (the latest at or before it).
        Raises ``LocalizeError`` before the first (kept) published correction."""
        return self.policy.publisher.correction_at(stamp_ns)

    def pose_at(self, stamp_ns: int, *, published: bool = False) -> PoseWithCovariance:
        """``T_map_base = T_map_odom @ T_odom_base(stamp_ns)`` with covariance
        (:meth:`MapOdomEstimator.pose_at
        <tagloc.localize.estimator.MapOdomEstimator.pose_at>`); ``published=True`` composes
        the published (capped) correction, drifted the same way, instead of the estimate.
        Raises ``LocalizeError`` before initialization, ``TransformLookupError`` without the
        odometry."""
        current = self.policy.publisher.current if published else None
        return self.estimator.pose_at(stamp_ns, current)

    def T_map_base_at(self, stamp_ns: int) -> SE3:
        """``T_map_base`` at ``stamp_ns`` from the estimate, without its covariance (what a
        fix source needs as a prior; cheaper than :meth:`pose_at`). Raises as it."""
        return self.estimator.T_map_base_at(stamp_ns)

    # ----- inputs ----------------------------------------------------------------------------
    def initialize(self, stamp_ns: int, T_map_odom: SE3, cov: FloatArray) -> FilterEvent:
        """Set an explicit prior (e.g. a saved pose; planar mode keeps its x, y, yaw), published
        at once. Raises ``LocalizeError`` on a bad covariance, ``TransformLookupError`` without
        odometry at ``stamp_ns``."""
        return self.policy.initialize(stamp_ns, T_map_odom, cov)

    def predict(self, stamp_ns: int) -> None:
        """Advance the state to ``stamp_ns``; call it at every odometry sample.

        The path is integrated in steps of ``motion_step``: a stamp less than one step after
        the state's returns almost at once (so calling this at the odometry rate costs little),
        as does any call before initialization. With odometry calibration, the published
        correction drifts with the state. Every call also ends one odometry step of the cap:
        what was published since the previous call (updates, drift) is clipped to within the
        cap of the correction published then, so between two calls the published
        ``map -> base`` moves by at most the cap ((re)initializations excepted). Without calls,
        the cap applies per publication stamp.

        Raises
        ------
        TransformLookupError
            If the odometry at ``stamp_ns`` is not buffered.
        """
        self.policy.predict(stamp_ns)

    def add_process_noise(self, Q: FloatArray) -> None:
        """Add ``Q`` ((6, 6), symmetric positive semi-definite, ``[x, y, z, rx, ry, rz]``) to the
        covariance of ``T_map_odom`` now: odometry error the motion model does not know of (the
        growth of the odometry's own pose covariance, in the odometry frame: an error ``d`` of
        ``T_odom_base`` on the left is ``-d`` of the correction on the right, so its covariance
        adds as it is). Planar: its x, y, yaw block. Before initialization: nothing. Raises
        ``LocalizeError`` if ``Q`` is not (6, 6), finite and symmetric."""
        self.estimator.add_process_noise(Q)

    def update(self, fix: TagFix) -> FilterEvent:
        """Decide on one fix and apply it if it passes (:meth:`FixPolicy.decide
        <tagloc.localize.policy.FixPolicy.decide>`); return the decision event
        (``ACCEPTED``, ``GATED_*``, ``PENDING_CONSISTENCY``, ...); any filter-level events it
        caused follow it in :attr:`events`."""
        return self.policy.decide(fix)

    def update_partial(self, fix: PartialFix) -> FilterEvent:
        """Decide on a fix that measures only the directions ``fix.basis`` and apply it if it
        passes (:meth:`FixPolicy.decide_partial
        <tagloc.localize.policy.FixPolicy.decide_partial>`): the chi-square gate on ``k``
        dof, then the update that never moves the estimate along an unmeasured direction."""
        return self.policy.decide_partial(fix)
