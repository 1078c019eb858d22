"""The fix policy alone (``FixPolicy`` on an estimator; ``RecoveryBooks``).

Oracles: the estimator driven by hand through the calls the policy's documentation promises
(a start-up resets from the first consistent fix and updates with the others; fixes held over a
gap are applied oldest first), the construction of the fixes (which source is wrong, and how),
and the event log the policy writes.
"""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize import (
    Candidate,
    EventKind,
    FixPolicy,
    FixQuality,
    KidnapRule,
    LocalizerConfig,
    MapOdomEstimator,
    PartialFix,
    RecoveryBooks,
    SuspectRule,
    TagFix,
)
from tagloc.localize.gating import CorrectionCap

S = 1_000_000_000
COV = np.diag(np.square([0.03, 0.03, 0.05, 0.01, 0.01, 0.01]))
X_TRUE = SE3.exp([1.0, -2.0, 0.0, 0.0, 0.0, 0.4])  # the true T_map_odom
A = SE3.exp([3.0, 1.0, 0.0, 0.0, 0.0, 0.2])  # the robot stands here in odom


def _policy(**sections: dict[str, object]) -> FixPolicy:
    config = LocalizerConfig.model_validate({"calibration": {"enabled": False}, **sections})
    buffer = TransformBuffer()
    buffer.set_static("odom", "base_link", A)
    est = MapOdomEstimator.from_config(
        buffer, config.frames, config.process_noise, config.calibration, config.filter
    )
    c = config
    return FixPolicy.from_config(est, c.gates, c.kidnap, c.suspect, c.cap, c.filter)


def _oracle(policy: FixPolicy) -> MapOdomEstimator:
    """A second estimator with the same configuration and odometry."""
    est = policy.estimator
    return MapOdomEstimator(
        est.path.buffer, map_frame="map", odom_frame="odom", base_frame="base_link",
        planar=est.planar, noise=est.path.noise, max_iterations=3, relinearize_tol=0.05,
    )  # fmt: skip


def _fix(rng: np.random.Generator, t_s: float, source: str, offset: SE3 | None = None,
         reproj: float = 0.4) -> TagFix:  # fmt: skip
    n = rng.multivariate_normal(np.zeros(6), COV)
    z = (X_TRUE if offset is None else offset @ X_TRUE) @ A @ SE3.exp(n)
    return TagFix(round(t_s * S), z, COV, source, FixQuality(reproj))


def _same_state(a: MapOdomEstimator, b: MapOdomEstimator) -> None:
    np.testing.assert_allclose(a.T_map_odom.as_matrix(), b.T_map_odom.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(a.covariance, b.covariance, atol=1e-15)


def test_start_up_resets_from_the_first_consistent_fix_and_updates_with_the_others() -> None:
    rng = np.random.default_rng(0)
    policy = _policy()
    fixes = [_fix(rng, t, f"tag:{i}") for i, t in enumerate((1.0, 1.1, 1.2))]
    assert [policy.decide(f).kind for f in fixes] == [EventKind.PENDING_CONSISTENCY] * 3
    assert policy.estimator.initialized and policy.events.count(EventKind.INITIALIZED) == 1
    oracle = _oracle(policy)
    cands = [Candidate.of_fix(f, A, planar=False) for f in fixes]
    oracle.reset(cands[0].stamp_ns, A, cands[0].T_map_odom, cands[0].cov)
    for cand in cands[1:]:
        oracle.predict(cand.stamp_ns, A)
        oracle.update(cand)
    _same_state(policy.estimator, oracle)
    assert policy.last_batch == tuple((f, EventKind.INITIALIZED) for f in fixes)
    assert policy.batch_serial == 1
    assert policy.publisher.current is policy.estimator.pose  # snapped: published as it is


def test_a_fix_refused_on_quality_never_reaches_the_estimator() -> None:
    policy = _policy()
    policy.initialize(0, X_TRUE, np.eye(6) * 1e-2)
    revision, published = policy.estimator.revision, policy.publisher.history
    event = policy.decide(_fix(np.random.default_rng(1), 0.5, "tag:1", reproj=5.0))
    assert event.kind is EventKind.GATED_REPROJ and event.threshold == 2.0
    assert policy.estimator.revision == revision and policy.publisher.history == published


def test_after_a_gap_fixes_wait_for_k_consistent_ones_then_apply_oldest_first() -> None:
    rng = np.random.default_rng(2)
    policy = _policy()
    policy.initialize(0, X_TRUE, np.eye(6) * 1e-2)
    fixes = [_fix(rng, t, f"tag:{i}") for i, t in enumerate((11.0, 11.1, 11.2))]  # gap_s = 10
    assert policy.decide(fixes[0]).kind is EventKind.PENDING_CONSISTENCY
    assert policy.reacquiring and policy.events.count(EventKind.GAP) == 1
    assert policy.decide(fixes[1]).kind is EventKind.PENDING_CONSISTENCY
    assert policy.decide(fixes[2]).kind is EventKind.PENDING_CONSISTENCY
    assert not policy.reacquiring
    assert policy.last_batch == tuple((f, EventKind.ACCEPTED) for f in fixes)
    oracle = _oracle(policy)
    oracle.initialize(0, X_TRUE, np.eye(6) * 1e-2)
    oracle.predict(fixes[2].stamp_ns)  # the state follows the held fixes' stamps
    for fix in fixes:  # the first two are late by then
        oracle.update(Candidate.of_fix(fix, A, planar=False))
    _same_state(policy.estimator, oracle)


def test_a_partial_fix_cannot_start_the_state_but_a_full_rank_one_ends_a_gap() -> None:
    policy = _policy()
    partial = PartialFix(11 * S, X_TRUE @ A, np.eye(6), COV, "lidar")
    assert policy.decide_partial(partial).kind is EventKind.UNUSED_NO_STATE
    policy.initialize(0, X_TRUE, np.eye(6) * 1e-2)
    policy.decide(_fix(np.random.default_rng(3), 11.0, "tag:1"))  # starts the gap
    assert policy.reacquiring
    assert policy.decide_partial(partial).kind is EventKind.ACCEPTED
    assert not policy.reacquiring and policy.events.count(EventKind.DISCARDED_CANDIDATE) == 1


# ----- the recovery books -------------------------------------------------------------------
def _books(n_fixes: int = 4, min_sources: int = 2, one_source: int = 0) -> RecoveryBooks:
    kidnap = KidnapRule(n_fixes, min_sources, 5 * S, one_source, 1.0)
    suspect = SuspectRule(3, 10, CorrectionCap(0.3, np.radians(5.0)), 5 * S)
    return RecoveryBooks(kidnap, suspect, 22.46, lambda a, b: np.zeros((6, 6)))


def _cand(rng: np.random.Generator, t_s: float, source: str, offset: SE3 | None = None):  # type: ignore[no-untyped-def]
    return Candidate.of_fix(_fix(rng, t_s, source, offset), A, planar=False)


MOVED = SE3.exp([0.0, 0.6, 0.0, 0.0, 0.0, 0.0])  # a tag moved 0.6 m: wrong the same way


def test_a_source_gated_the_same_way_while_others_are_accepted_is_flagged() -> None:
    rng = np.random.default_rng(4)
    books = _books(n_fixes=0)
    flags = []
    for k in range(3):
        flags.append(books.on_gated(_cand(rng, 1 + 0.1 * k, "tag:2", MOVED), 50.0, X_TRUE)[0])
        books.on_accepted("tag:1", 5.0)  # meanwhile another source is accepted
    assert flags == [False, False, True] and books.sources.suspects == ("tag:2",)
    # cleared after 10 fixes that pass the gate (and not before)
    assert [books.on_suspect_fix("tag:2", True) for _ in range(10)] == [False] * 9 + [True]
    assert books.sources.suspects == ()


def test_glints_wrong_at_random_never_make_a_source_suspect() -> None:
    rng = np.random.default_rng(5)
    books = _books(n_fixes=0)
    for k in range(12):  # each 1 m elsewhere: not the same way twice
        glint = SE3.exp([1.0 * (k % 2 * 2 - 1) * (k + 1), 0.0, 0.0, 0.0, 0.0, 0.0])
        assert books.on_gated(_cand(rng, 1 + 0.1 * k, "tag:2", glint), 50.0, X_TRUE) == (
            False, None
        )  # fmt: skip
        books.on_accepted("tag:1", 5.0)
    assert books.sources.suspects == ()


@pytest.mark.parametrize("one_source", [0, 5])
def test_a_kidnap_needs_consistent_gated_fixes_of_two_sources_or_many_far_of_one(
    one_source: int,
) -> None:
    rng = np.random.default_rng(6)
    books = _books(one_source=one_source)
    away = SE3.exp([4.0, 3.0, 0.0, 0.0, 0.0, 1.0])  # the robot was carried 5 m away
    found = [books.on_gated(_cand(rng, 1 + 0.1 * k, "tag:1", away), 99.0, X_TRUE)[1]
             for k in range(5)]  # fmt: skip
    assert found[:4] == [None] * 4
    assert (found[4] is not None) == (one_source == 5)  # one source: only by the one-tag rule
    books = _books(one_source=one_source)
    found = [books.on_gated(_cand(rng, 1 + 0.1 * k, f"tag:{k % 2}", away), 99.0, X_TRUE)[1]
             for k in range(4)]  # fmt: skip
    assert found[:3] == [None] * 3 and found[3] is not None
    assert [c.stamp_ns for c in found[3]] == sorted(c.stamp_ns for c in found[3])
    assert {c.fix.source for c in found[3]} == {"tag:0", "tag:1"}
