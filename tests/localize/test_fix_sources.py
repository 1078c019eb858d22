"""Fix sources behind one protocol: the registry builds them, the node decides their fixes.

A third source stands for an AMCL pose from a robot stack (``PoseWithCovarianceMsg`` of the base
in the map): registered, it is built by every node, its fixes are decided by the filter at their
own stamps and handed on once, final; unregistered, nodes do without it. Oracle: the
simulator's ground truth (the poses are the truth plus known noise).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterator
from functools import partial
from typing import Any

import numpy as np
import pytest

from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.geometry import SE3
from tagloc.localize import (
    FixQuality,
    LocalizerConfig,
    LocalizerNode,
    TagFix,
    available_fix_sources,
    record_run,
    register_fix_source,
)
from tagloc.localize.events import FIX_DECISIONS
from tagloc.localize.registry import unregister_fix_source
from tagloc.localize.run import FixAttempt
from tagloc.localize.sources import (
    Arrival,
    FixContext,
    Offer,
    SkipCounter,
    SourceInputs,
    SourceResult,
    Work,
)
from tagloc.messages import GroundTruthMsg, Message, PoseWithCovarianceMsg
from tagloc.sim.scenarios import ScenarioSource, build_scenario
from tagloc.supervise import FixSourceSpec

S = 1_000_000_000
TOPIC = "/amcl_pose"
SIGMA_M = 0.05
COV = np.diag([SIGMA_M**2, SIGMA_M**2, 1e-4, 1e-4, 1e-4, 0.02**2])


class PoseSource:
    """A :class:`~tagloc.localize.sources.FixSource` of external pose estimates."""

    spec = FixSourceSpec("amcl", "lidar", "amcl")
    max_waiting = 10
    overflow_reason = "amcl_no_odometry"
    jump_reason = "amcl_before_clock_jump"

    def __init__(self) -> None:
        self.skipped = SkipCounter()
        self.resets = 0

    def arrive(self, topic: str, msg: Message) -> Arrival | None:
        if topic != TOPIC or not isinstance(msg, PoseWithCovarianceMsg):
            return None
        return Arrival(msg.stamp_ns, work=Work(msg.stamp_ns, msg.stamp_ns, msg))

    def fixes(self, payload: object, context: FixContext) -> SourceResult | None:
        assert isinstance(payload, PoseWithCovarianceMsg)
        fix = TagFix(payload.stamp_ns, payload.T_frame_child, payload.cov, "amcl",
                     FixQuality(0.0, 0))  # fmt: skip
        attempt = FixAttempt(fix.stamp_ns, "amcl", (), fix.T_map_base, fix.cov, "", math.nan,
                             math.nan)  # fmt: skip
        return SourceResult(offers=(Offer(fix, attempt, context.filter.dof),))

    def observe(self, result: SourceResult) -> None:
        return None

    def reset(self) -> None:
        self.resets += 1

    def metadata(self) -> dict[str, Any]:
        return {}


@pytest.fixture()
def amcl() -> Iterator[None]:
    register_fix_source("amcl", lambda config, inputs: PoseSource())
    yield
    unregister_fix_source("amcl")


def _with_poses(source: ScenarioSource) -> Iterator[tuple[str, Message]]:
    """The stream plus a noisy pose of the base in the map once a second (from the truth)."""
    rng = np.random.default_rng(5)
    next_ns = 0
    for topic, msg in source:
        yield topic, msg
        if isinstance(msg, GroundTruthMsg) and msg.stamp_ns >= next_ns:
            next_ns = msg.stamp_ns + S
            noise = np.concatenate([rng.normal(0.0, SIGMA_M, 2), [0.0, 0.0, 0.0, 0.0]])
            T = msg.T_frame_child @ SE3.exp(noise)
            yield TOPIC, PoseWithCovarianceMsg(msg.stamp_ns, "map", T, COV)


def test_a_registered_source_is_built_and_its_fixes_decided_once(amcl: None) -> None:
    source = ScenarioSource(build_scenario("default", seed=2, duration_s=20.0), lidar=False)
    config = calibrated_config(source.scenario, scenario_config())
    assert available_fix_sources() == ("markers", "lidar", "amcl")
    node = partial(LocalizerNode, source.scenario.tag_map, config)
    run = record_run(node, _with_poses(source))
    poses = [a for a in run.fixes if a.source == "amcl"]
    assert len(poses) == 21  # one per second from 0 s to 20 s, each handed on once
    decisions = Counter(a.decision for a in poses)
    assert decisions["accepted"] >= 15, decisions  # true to 5 cm: the gate lets them in
    assert all(a.d2 is not None for a in poses if a.decision == "accepted")
    assert not [e for e in run.events if e.kind in FIX_DECISIONS]  # no second channel
    assert run.T_map_base_truth is not None
    d = np.asarray(run.T_map_base.translation) - run.T_map_base_truth.translation
    assert float(np.sqrt(np.mean(np.sum(d[run.initialized] ** 2, axis=1)))) < 0.1


def test_an_unregistered_source_is_not_built() -> None:
    register_fix_source("amcl", lambda config, inputs: PoseSource())
    unregister_fix_source("amcl")
    assert available_fix_sources() == ("markers", "lidar")
    node = LocalizerNode(build_scenario("default", 0, 5.0).tag_map, LocalizerConfig())
    assert [s.spec.name for s in node.fix_sources] == ["markers"]  # no premap: no lidar


def test_a_source_name_is_registered_once() -> None:
    from tagloc.localize import LocalizeError

    with pytest.raises(LocalizeError, match="already registered"):
        register_fix_source("markers", lambda config, inputs: None)
    with pytest.raises(LocalizeError, match="not registered"):
        unregister_fix_source("amcl")


def test_the_inputs_reach_the_factories() -> None:
    seen: list[SourceInputs] = []

    def factory(config: LocalizerConfig, inputs: SourceInputs) -> None:
        seen.append(inputs)

    register_fix_source("probe", factory)
    try:
        tag_map = build_scenario("default", 0, 5.0).tag_map
        LocalizerNode(tag_map, LocalizerConfig(), frame_truth={})
    finally:
        unregister_fix_source("probe")
    assert len(seen) == 1 and seen[0].tag_map is tag_map and seen[0].premap is None
