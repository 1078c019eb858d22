"""On-site evaluation without ground truth, checked where the truth is known (the simulator).

- held-out tags: the tag position error predicted from the fused pose agrees with the fused
  pose's TRUE error transported to the tag (simulator truth, same views) within 20 %;
- checkpoints: stops and spreads against a hand-built run whose stops are known;
- acceptance by conditions: counts against a direct tally; image measures against OpenCV.
"""

from __future__ import annotations

import math
from collections import Counter

import cv2
import numpy as np
import pytest

from tagloc.config import ConfigError
from tagloc.eval.onsite import error_stats, fused_pose_at, held_out_tags
from tagloc.eval.onsite_checkpoints import checkpoint_spreads, detect_stops, parse_checkpoints
from tagloc.eval.onsite_conditions import NO_IMAGES, acceptance_by_conditions, image_measures
from tagloc.geometry import SE3
from tagloc.localize.run import FixAttempt, LocalizationRun
from tagloc.tags import TagDetection

S_NS = 1_000_000_000


def _held_out(duration_s: float, n_tags: int):  # type: ignore[no-untyped-def]
    from tagloc.eval.scenarios import calibrated_config, scenario_config
    from tagloc.sim.scenarios import ScenarioSource, build_scenario

    scenario = build_scenario("default", 0, duration_s)
    messages = list(ScenarioSource(scenario))
    seen = Counter(d.tag_id for t, m in messages if t == "/tag_detections" for d in m.detections)
    ids = [i for i, _ in seen.most_common(n_tags)]
    config = calibrated_config(scenario, scenario_config())
    return held_out_tags(lambda: messages, scenario.tag_map, config, tag_ids=ids), ids


def _rms(values: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def _check_prediction(result, tolerance: float) -> None:  # type: ignore[no-untyped-def]
    obs = result.observations
    assert len(obs) >= 50
    predicted = _rms([o.position_err_m for o in obs])
    true = _rms([o.tag_err_true_m for o in obs])
    assert abs(predicted - true) <= tolerance * true, (predicted, true)
    stats = result.to_dict()["overall"]
    assert stats["position_m"]["n"] == len(obs) and "tag_true_m" in stats


def test_held_out_tag_predicts_the_true_error_short() -> None:
    result, ids = _held_out(25.0, 1)
    assert result.tag_ids() == ids and not result.unseen
    assert all(o.range_m <= 4.0 for o in result.observations)
    _check_prediction(result, 0.2)


@pytest.mark.slow
def test_held_out_tags_predict_the_true_error() -> None:
    result, _ = _held_out(100.0, 4)
    _check_prediction(result, 0.2)
    for tag_id in result.tag_ids():  # each tag on its own: same order of magnitude
        s = result.stats(tag_id)
        assert s["position_m"].median < 3.0 * s["tag_true_m"].median + 0.02


def test_error_stats_match_numpy() -> None:
    v = np.random.default_rng(0).exponential(0.05, 200)
    s = error_stats(np.concatenate([v, [np.nan]]))
    assert s.n == 200 and s.median == np.median(v) and s.p95 == np.percentile(v, 95)
    assert math.isnan(error_stats([]).median)


# ----- a hand-built run: odometry with stops, identity correction -------------------------------
def _run_with_stops(
    visits: list[tuple[float, float]], noise_m: float, seed: int
) -> LocalizationRun:
    """Drive between the ``visits`` at 1 m/s (100 Hz), standing 3 s at each, with the fused pose
    off by a seeded ``noise_m`` per visit."""
    rng = np.random.default_rng(seed)
    xy: list[np.ndarray] = []
    here = np.array([0.0, 0.0])
    for x, y in visits:
        goal = np.array([x, y])
        n = max(int(np.linalg.norm(goal - here) * 100), 1)
        xy += [here + (goal - here) * (k + 1) / n for k in range(n)]
        offset = rng.normal(0.0, noise_m, 2)
        xy += [goal + offset] * 300
        here = goal + offset
    p = np.array(xy)
    n = len(p)
    T = SE3.from_rotvec(np.zeros((n, 3)), np.column_stack([p, np.zeros(n)]))
    return LocalizationRun(
        "synthetic", (np.arange(n) * S_NS // 100).astype(np.int64), T, SE3.identity(n),
        np.full((n, 6, 6), np.nan), np.ones(n, dtype=bool),
    )  # fmt: skip


def test_stops_and_their_spread_by_file() -> None:
    visits = [(1.0, 0.0), (5.0, 0.0), (1.0, 0.0), (5.0, 0.0), (1.0, 0.0)]
    run = _run_with_stops(visits, 0.02, seed=1)
    stops = detect_stops(run, min_stop_s=2.0)
    assert len(stops) == 5
    spots = parse_checkpoints(
        "checkpoints:\n  - {name: dock, x: 1.0, y: 0.0, radius: 0.3}\n"
        "  - {name: door, x: 5.0, y: 0.0}\n", "cp.yaml",
    )  # fmt: skip
    spreads = {c.name: c for c in checkpoint_spreads(stops, spots)}
    dock = np.array([[s.x, s.y] for s in stops[0::2]])
    r = np.linalg.norm(dock - dock.mean(0), axis=1)
    assert len(spreads["dock"].visits) == 3
    assert spreads["dock"].rms_m == pytest.approx(np.sqrt(np.mean(r**2)), rel=1e-9)
    assert spreads["dock"].max_m == pytest.approx(r.max(), rel=1e-9)
    # without a file, the same stops cluster into the same two places
    clustered = checkpoint_spreads(stops, None, cluster_radius_m=0.5)
    assert sorted(len(c.visits) for c in clustered) == [2, 3]


def test_a_bad_checkpoint_file_is_one_line() -> None:
    with pytest.raises(ConfigError, match=r"cp.yaml: checkpoints\[0\].radius"):
        parse_checkpoints("checkpoints:\n  - {name: a, x: 1, y: 2, radius: -1}\n", "cp.yaml")
    with pytest.raises(ConfigError, match=r"cp.yaml: checkpoints\[1\].name: duplicate name 'a'"):
        parse_checkpoints("checkpoints: [{name: a, x: 1, y: 2}, {name: a, x: 5, y: 2}]", "cp.yaml")


def test_fused_pose_at_odometry_stamps_is_the_run() -> None:
    run = _run_with_stops([(2.0, 1.0)], 0.0, seed=0)
    T, valid = fused_pose_at(run, run.stamps_ns[::7])
    assert valid.all()
    np.testing.assert_allclose(T.translation, run.T_map_base.translation[::7], atol=1e-12)


# ----- acceptance by conditions ----------------------------------------------------------------
def _attempt(stamp: int, tag: int, range_m: float, angle_deg: float, ok: bool) -> FixAttempt:
    decision = "accepted" if ok else "gated_chi2"
    return FixAttempt(
        stamp, f"tag:{tag}", (tag,), SE3.identity(), np.eye(6), decision, range_m,
        math.radians(angle_deg),
    )  # fmt: skip


def test_acceptance_bins_count_the_attempts() -> None:
    rng = np.random.default_rng(3)
    ranges, angles = rng.uniform(0.5, 7.5, 300), rng.uniform(0.0, 80.0, 300)
    ok = ranges < 3.0 + rng.normal(0, 0.5, 300)
    fixes = [
        _attempt(i, 1, r, a, o) for i, (r, a, o) in enumerate(zip(ranges, angles, ok, strict=True))
    ]
    out = acceptance_by_conditions(fixes)
    assert out["attempts"] == 300 and out["accepted"] == int(ok.sum()) and out["note"] == NO_IMAGES
    for b in out["distance_m"]:
        inside = (ranges >= b["lo"]) & (ranges < b["hi"])
        assert (b["attempts"], b["accepted"]) == (int(inside.sum()), int((inside & ok).sum()))
    assert sum(b["attempts"] for b in out["view_angle_deg"]) == 300
    assert "laplacian_var" not in out and "brightness" not in out


def test_image_measures_match_opencv() -> None:
    rng = np.random.default_rng(4)
    image = (rng.uniform(0, 255, (120, 160))).astype(np.uint8)
    blurred = cv2.GaussianBlur(image, (9, 9), 3.0)
    corners = np.array([[20.0, 30.0], [60.0, 30.0], [60.0, 70.0], [20.0, 70.0]])
    det = TagDetection(7, "tag36h11", corners)
    sharp, soft = image_measures(image, [det])[7], image_measures(blurred, [det])[7]
    box = image[30:71, 20:61].astype(np.float64)
    assert sharp.laplacian_var == pytest.approx(cv2.Laplacian(box, cv2.CV_64F).var(), rel=1e-9)
    assert sharp.brightness == pytest.approx(box.mean(), rel=1e-9)
    assert soft.laplacian_var < 0.2 * sharp.laplacian_var
    measures = {(0, 7): sharp, (1, 7): soft}
    out = acceptance_by_conditions(
        [_attempt(0, 7, 2.0, 10.0, True), _attempt(1, 7, 2.0, 10.0, False)], measures
    )
    assert sum(b["attempts"] for b in out["brightness"]) == 2


def test_held_out_tag_through_every_camera_of_a_rig() -> None:
    """A rig (the default drive's front camera and a back camera, ``tests/rig_stream.py``): the
    held-out tag's views of each camera are predicted through that camera's model and mount, and
    each camera's predicted error agrees with the fused pose's true error transported to the tag
    (simulator truth) as the one camera's does (within 30 %: fewer views per camera)."""
    from rig_stream import BACK, make_rig
    from tagloc.eval.scenarios import calibrated_config, scenario_config
    from tagloc.localize.node import NodeCamera

    source, T_base_back, back, stream = make_rig(40.0)
    front_seen = Counter(d.tag_id for t, m in stream if t == source.t.detections
                         for d in m.detections)  # fmt: skip
    back_seen = Counter(d.tag_id for dets in back.values() for d in dets)
    tag_id = max(set(front_seen) & set(back_seen), key=lambda i: min(front_seen[i], back_seen[i]))
    rig = [NodeCamera("front", source.t.detections, source.camera, source.T_base_cam),
           NodeCamera("back", BACK, source.camera, T_base_back)]  # fmt: skip
    config = calibrated_config(source.scenario, scenario_config())
    result = held_out_tags(lambda: stream, source.scenario.tag_map, config, tag_ids=[tag_id],
                           cameras=rig)  # fmt: skip
    assert result.cameras() == ["front", "back"] or result.cameras() == ["back", "front"]
    for camera in ("front", "back"):
        obs = [o for o in result.observations if o.camera == camera]
        assert len(obs) >= 10, camera
        predicted = _rms([o.position_err_m for o in obs])
        true = _rms([o.tag_err_true_m for o in obs])
        assert abs(predicted - true) <= 0.3 * true + 0.005, (camera, predicted, true)
    per_camera = result.to_dict()["per_camera"]
    assert {c: s["position_m"]["n"] for c, s in per_camera.items()} == {
        c: sum(o.camera == c for o in result.observations) for c in ("front", "back")
    }
