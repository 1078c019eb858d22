"""Fix attempts counted by decision and camera, and the hint, against a count by hand."""

from __future__ import annotations

import json
import random

import numpy as np

from tagloc.eval.refusals import WHAT_TO_CHECK, fix_decisions
from tagloc.geometry import SE3
from tagloc.localize.events import APPLIED
from tagloc.localize.run import FixAttempt


def _attempt(decision: str, camera: str) -> FixAttempt:
    return FixAttempt(0, "tag:1", (1,), SE3.identity(), np.eye(6), decision, 2.0, 0.1,
                      camera=camera)  # fmt: skip


def test_counts_match_a_count_by_hand_and_the_hint_names_the_dominant_refusal() -> None:
    rng = random.Random(4)
    choices = ["accepted", "rejected:prior_conflict", "gated_chi2", "initialized"]
    weights = [2, 6, 1, 1]
    attempts = [_attempt(rng.choices(choices, weights)[0], rng.choice(["cam0", "cam1"]))
                for _ in range(500)]  # fmt: skip
    got = fix_decisions(attempts)
    for decision in choices:
        assert got.by_decision.get(decision, 0) == sum(a.decision == decision for a in attempts)
    for cam in got.by_camera:
        mine = [a for a in attempts if a.camera == cam.camera]
        assert cam.n_attempts == len(mine)
        assert cam.n_accepted == sum(a.decision in APPLIED for a in mine)
    refused = got.by_decision["rejected:prior_conflict"]
    assert 2 * refused > len(attempts)  # the draw makes it dominant
    assert got.hint is not None and "prior_conflict" in got.hint
    assert WHAT_TO_CHECK["rejected:prior_conflict"] in got.hint
    assert json.loads(json.dumps(got.to_dict()))["attempts"] == 500


def test_no_hint_when_no_refusal_has_half_the_attempts() -> None:
    attempts = [
        _attempt(d, "") for d in ["accepted"] * 5 + ["gated_chi2"] * 3 + ["rejected:range"] * 2
    ]
    got = fix_decisions(attempts)
    assert got.hint is None and got.n_accepted == 5 and got.acceptance == 0.5
    # exactly half refused by one reason is not "more than half"
    tied = fix_decisions([_attempt("accepted", "")] * 2 + [_attempt("gated_chi2", "")] * 2)
    assert tied.hint is None
