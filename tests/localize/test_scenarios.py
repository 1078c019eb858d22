"""Acceptance scenarios of the localizer against the simulator's ground truth.

Default tests run shortened drives (the first 45-90 s of the ~700 s route, seeds fixed); the
full-length runs are ``@pytest.mark.slow`` (``pytest --runslow``). Numbers measured when the
tolerances were set are in the comments.
"""

from __future__ import annotations

import itertools
import math
from functools import partial

import numpy as np
import pytest

from tagloc.eval.scenarios import calibrated_config, run_scenario, scenario_config
from tagloc.localize import LocalizerNode, RunResult, driver
from tagloc.localize.outputs import RunRecorder
from tagloc.localize.run import LocalizationRun
from tagloc.sim.scenarios import SCENARIOS, ScenarioSource, build_scenario

S = 1_000_000_000
REINIT = ("initialized", "reinitialized_kidnap")


def position_errors(run: LocalizationRun) -> np.ndarray:
    """``|t_fused - t_true|`` per odometry stamp, m."""
    assert run.T_map_base_truth is not None
    d = np.asarray(run.T_map_base.translation) - run.T_map_base_truth.translation
    return np.asarray(np.linalg.norm(d, axis=1))


def rmse(errors: np.ndarray) -> float:
    return math.sqrt(float(np.mean(errors**2)))


def correction_jumps(run: LocalizationRun) -> np.ndarray:
    """Jump of the published ``T_map_base`` between consecutive odometry stamps at the same
    odometry (``(T_map_odom[i-1] A_i)^-1 T_map_odom[i] A_i``), m; 0 across (re)initializations,
    which snap by design."""
    A = run.T_odom_base[1:]
    jump = (run.T_map_odom[:-1] @ A).inverse() @ (run.T_map_odom[1:] @ A)
    out = np.linalg.norm(np.asarray(jump.translation), axis=1)
    snaps = [e.stamp_ns for e in run.events if e.kind in REINIT]
    idx = np.searchsorted(run.stamps_ns, snaps)  # the first row that shows the snap
    out[np.clip(idx - 1, 0, len(out) - 1)] = 0.0
    out[~run.initialized[:-1]] = 0.0
    return np.asarray(out)


@pytest.fixture(scope="module")
def default_pipeline() -> tuple[LocalizationRun, RunResult]:
    scenario = build_scenario("default", seed=0, duration_s=90.0)
    source = ScenarioSource(scenario)
    config = calibrated_config(scenario, scenario_config())
    # every published correction kept, for the cap test (the default keeps the last 1000)
    keep_all = config.filter.model_copy(update={"history_size": 1_000_000})
    config = config.model_copy(update={"filter": keep_all})
    recorder = RunRecorder()
    node = partial(LocalizerNode, scenario.tag_map, config, frame_truth=source.frame_truth)
    result = driver.run(node, source, [recorder])
    return recorder.run(result.node.metadata()), result


@pytest.fixture(scope="module")
def default_run(default_pipeline: tuple[LocalizationRun, RunResult]) -> LocalizationRun:
    return default_pipeline[0]


def test_default_drive_fused_beats_odometry(default_run: LocalizationRun) -> None:
    run = default_run
    fused = position_errors(run)
    assert run.T_map_base_truth is not None
    odom = np.linalg.norm(
        np.asarray(run.T_odom_base.translation) - run.T_map_base_truth.translation, axis=1
    )
    # measured: fused 0.042 m, odometry-only 0.89 m (the first 90 s, ~60 m; the odometry
    # calibration is still converging: the full drive reaches 0.038 m, see the slow test)
    assert rmse(odom) > 0.8
    assert rmse(fused) < 0.06
    # near tags the fused estimate is at the centimetre level
    near = np.array([f.nearest_visible_tag_m < 3.0 and f.n_fixes_accepted > 0 for f in run.frames])
    stamps = np.array([f.stamp_ns for f in run.frames])[near]
    at = np.searchsorted(run.stamps_ns, stamps)
    assert np.median(fused[at]) < 0.02  # measured 0.011 m
    calibration = run.metadata["odometry_calibration"]
    assert isinstance(calibration, dict)
    # the legged odometry over-reads distance by 4 %: the filter has found most of it
    assert -0.07 < calibration["scale"]["value"] < -0.02


def test_correction_never_jumps_more_than_the_cap(
    default_pipeline: tuple[LocalizationRun, RunResult],
) -> None:
    run, result = default_pipeline
    cap = result.node.config.cap.max_translation_m
    updates = result.node.filter.corrections  # every published map -> odom, in order
    assert len(updates) > 1000
    snaps = {e.stamp_ns for e in run.events if e.kind in REINIT}
    worst = 0.0
    for before, after in itertools.pairwise(updates):
        if after.stamp_ns in snaps:
            continue
        A = run.T_odom_base[int(np.searchsorted(run.stamps_ns, after.stamp_ns))]
        jump = (before.T_map_odom @ A).inverse() @ (after.T_map_odom @ A)
        worst = max(worst, float(np.linalg.norm(jump.translation)))
    assert worst <= cap + 1e-6, worst
    # between two odometry stamps too: the fixes of a frame, a batch after a gap and the
    # calibrated drift share one cap per odometry step
    assert correction_jumps(run).max() <= cap + 1e-9


def test_glints_never_give_an_accepted_fix() -> None:
    run = run_scenario("glint", seed=0, duration_s=60.0, lidar=False)
    assert int(run.metadata["glints_injected"]) >= 1000  # type: ignore[call-overload]
    false = [a for a in run.fixes if a.false_detection]
    true = [a for a in run.fixes if a.false_detection is False]
    assert len(false) == run.metadata["glints_injected"]
    assert sum(a.accepted for a in false) == 0
    # true fixes that pass the per-observation gates: the filter accepts >= 98 % (measured 99.3)
    offered = [a for a in true if not a.decision.startswith("rejected:")]
    assert sum(a.accepted for a in offered) >= 0.98 * len(offered)
    # within 3 m of the camera, >= 98 % of all true detections give an accepted fix
    near = [a for a in true if a.range_m <= 3.0]
    assert sum(a.accepted for a in near) >= 0.98 * len(near)
    assert run.metadata["suspect_sources"] == []  # glints do not make real tags look moved


def test_a_moved_tag_is_rejected_and_reported() -> None:
    run = run_scenario("moved_tag", seed=0, duration_s=60.0, lidar=False)
    moved = [a for a in run.fixes if a.source == "tag:5" and not a.decision.startswith("rejected:")]
    assert len(moved) > 20
    assert not any(a.accepted for a in moved)
    assert "tag:5" in run.metadata["suspect_sources"]  # type: ignore[operator]
    assert any(e.kind == "suspect_source" and e.source == "tag:5" for e in run.events)
    others = [a for a in run.fixes if a.source != "tag:5" and a.accepted]
    assert len(others) > 500


def relocalization_delay_s(run: LocalizationRun, tol_m: float = 0.1) -> float:
    """From the first frame after the kidnap with a real detection to the first odometry stamp
    at which the fused position is within ``tol_m`` again (and stays so for 1 s), seconds."""
    (kidnap,) = run.kidnaps_ns
    first = min(f.stamp_ns for f in run.frames if f.stamp_ns >= kidnap and f.n_detections > 0)
    errors = position_errors(run)
    i0 = int(np.searchsorted(run.stamps_ns, kidnap))
    per_s = round(S / np.median(np.diff(run.stamps_ns)))
    for i in range(i0, len(errors) - per_s):
        if np.all(errors[i : i + per_s] < tol_m):
            return (int(run.stamps_ns[i]) - first) / S
    return math.inf


def test_kidnap_relocalizes_within_a_second_of_the_first_sighting() -> None:
    run = run_scenario("kidnap", seed=0, duration_s=50.0, lidar=False)
    (kidnap,) = run.kidnaps_ns
    errors = position_errors(run)
    i = int(np.searchsorted(run.stamps_ns, kidnap))
    assert errors[i + 1] > 10.0  # the truth jumped, the odometry did not
    assert relocalization_delay_s(run) <= 1.0  # measured 0.10 s
    assert any(e.kind == "reinitialized_kidnap" and e.stamp_ns >= kidnap for e in run.events)


def test_kidnap_with_one_tag_in_view_relocalizes_from_it() -> None:
    run = run_scenario("kidnap_one_tag", seed=0, duration_s=50.0, lidar=False)
    (kidnap,) = run.kidnaps_ns
    reinit = [e for e in run.events if e.kind == "reinitialized_kidnap" and e.stamp_ns >= kidnap]
    assert len(reinit) == 1 and reinit[0].source == "tag:17"
    # one far (4.5 m), near-frontal tag: 15 unambiguous sightings, then it converges
    assert relocalization_delay_s(run) <= 3.0  # measured 1.9 s


def test_camera_dropout_and_corridor_recover() -> None:
    run = run_scenario("dropout", seed=1, duration_s=70.0, lidar=False)
    lo, hi = (round(t * S) for t in SCENARIOS["dropout"].dropout_s or (0, 0))
    assert not [f for f in run.frames if lo < f.stamp_ns < hi]
    errors = position_errors(run)
    after = run.stamps_ns > hi + 5 * S
    assert rmse(errors[after]) < 0.15  # re-acquired after 30 s without camera
    corridor = build_scenario("corridor", duration_s=10.0)
    assert {1, 2, 3, 5, 6, 7, 8}.isdisjoint({t.id for t in corridor.tag_map})


#: Full-drive fused ATE bound per scenario (measured, seed 0, 700 s / 377 m): default 0.038 m,
#: glint 0.038, moved_tag 0.038, dropout 0.044 (30 s without camera), corridor 0.16 (20 m of
#: corridor without tags and a foot slip there: the degradation the scenario exists to show).
FULL_ATE_M = {"default": 0.05, "glint": 0.05, "moved_tag": 0.05, "dropout": 0.06, "corridor": 0.25}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FULL_ATE_M))
def test_full_length_scenarios(name: str) -> None:
    from tagloc.eval import evaluate

    run = run_scenario(name, seed=0, lidar=False)
    summary = evaluate(run).summary
    fused, odom = summary.estimators["fused"], summary.estimators["odometry"]
    assert odom.ate_rmse_m > 1.0  # the legged odometry drifts several %
    assert fused.ate_rmse_m <= FULL_ATE_M[name]
    assert fused.false_fixes_accepted == 0
    assert fused.largest_jump_m <= summary.cap_translation_m + 1e-9
    if name in ("default", "glint"):  # (a moved tag alone in view is rightly refused)
        assert fused.reliability is not None and fused.reliability.fraction >= 0.99
    if name == "glint":  # >= 1,000 injected, none accepted, >= 98 % of true ones
        assert int(run.metadata["glints_injected"]) >= 1000  # type: ignore[call-overload]
        assert summary.fixes.true_in_range_acceptance >= 0.98
        assert run.metadata["suspect_sources"] == []
    if name == "moved_tag":
        assert run.metadata["suspect_sources"] == ["tag:5"]
