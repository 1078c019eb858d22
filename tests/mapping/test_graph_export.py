"""The raw graph (every factor with its residual at the solution) and exclusions.

Oracles: GTSAM's own factors (``BetweenFactorPose3``, ``PriorFactorPose3``) evaluated at the
solution for the odometry and anchor residuals, the report's outlier count, and the simulator's
true tag poses for a planted bad edge: detections of tag 13 relabelled as tag 3 for a stretch of
the drive fold tag 3 onto tag 13's wall (measured 9.6 m off); ``tag:3@3-19`` removes them and
tag 3 is back where the clean survey puts it (measured 1.6 cm from it; 8.7 cm from the truth,
within 3 sigma: the legged odometry's drift, not the planted edge).
"""

from __future__ import annotations

import dataclasses
import json

import gtsam
import numpy as np
import pytest

from tagloc.cli.map_cmd import parse_exclusion
from tagloc.geometry import SE3
from tagloc.mapping import BuildReport, MappingError, Survey, build_tag_map
from tagloc.mapping.exclude import exclude_observations, survey_start_ns
from tagloc.mapping.survey import CameraFrame
from tagloc.mapping.survey_scans import SurveyScans
from tagloc.sim import ObservationConfig, World, load_default_world, simulate_drive
from tagloc.sim.survey import sim_build_config, survey_from_drive
from tagloc.tags.tagmap import TagMap


def _short_world() -> World:
    """The office's corridor and room_a (about 40 s of driving)."""
    world = load_default_world()
    route = world.route.model_copy(update={"waypoints": world.route.waypoints[:7], "repeat": 1})
    return world.model_copy(update={"route": route})


@pytest.fixture(scope="module")
def built() -> tuple[Survey, TagMap, BuildReport, World]:
    drive = simulate_drive(_short_world(), seed=1)
    observation = ObservationConfig(seed=2)
    survey = survey_from_drive(drive, observation, camera_stride=3)
    world = drive.world
    anchors = {1: world.T_map_tag(world.find_tag(1))}
    tag_map, report = build_tag_map(survey, anchors, sim_build_config(drive, observation))
    return survey, tag_map, report, world


def test_every_factor_is_exported_with_its_residual(
    built: tuple[Survey, TagMap, BuildReport, World],
) -> None:
    survey, _, report, _ = built
    lines = report.graph_jsonl().splitlines()
    records = [json.loads(line) for line in lines]
    header, rest = records[0], records[1:]
    assert header["type"] == "header" and header["format"] == "tagloc-graph"
    assert header["factors"] == len(rest) and header["t0_ns"] == survey_start_ns(survey)
    kinds = [r["type"] for r in rest]
    assert kinds.count("observation") == report.observations
    assert kinds.count("odometry") == report.keyframes - 1
    assert kinds.count("anchor") == 1 and "gravity" not in kinds
    obs = [r for r in rest if r["type"] == "observation"]
    assert sum(r["outlier"] for r in obs) == report.outliers
    assert all(len(r["residual_px"]) == 4 and len(r["residual_px"][0]) == 2 for r in obs)
    rms = np.sqrt(np.mean([r["rms_px"] ** 2 for r in obs if not r["outlier"]]))
    assert rms == pytest.approx(report.reproj_rms_px, rel=1e-3)


def test_odometry_and_anchor_residuals_match_gtsam(
    built: tuple[Survey, TagMap, BuildReport, World],
) -> None:
    _, tag_map, report, world = built
    records = [json.loads(line) for line in report.graph_jsonl().splitlines()[1:]]
    odo = [r for r in records if r["type"] == "odometry"]
    M = report.T_map_base_optimized.as_matrix()
    # the exported residual is Log(Z^-1 x_{k-1}^-1 x_k): rebuild Z from it and ask GTSAM
    for r in odo[:: max(1, len(odo) // 20)]:
        k = r["keyframe"]
        xi = np.array(r["residual"])
        B = np.linalg.inv(M[k - 1]) @ M[k]
        Z = B @ np.linalg.inv(SE3.exp(xi).as_matrix())
        factor = gtsam.BetweenFactorPose3(1, 2, gtsam.Pose3(Z), gtsam.noiseModel.Unit.Create(6))
        values = gtsam.Values()
        values.insert(1, gtsam.Pose3(M[k - 1]))
        values.insert(2, gtsam.Pose3(M[k]))
        err = factor.unwhitenedError(values)  # [rx, ry, rz, x, y, z]
        np.testing.assert_allclose(np.r_[err[3:], err[:3]], xi, atol=1e-5)
        assert r["translation_m"] == pytest.approx(np.linalg.norm(xi[:3]), abs=1e-6)
    (anchor,) = [r for r in records if r["type"] == "anchor"]
    prior = gtsam.PriorFactorPose3(
        1, gtsam.Pose3(world.T_map_tag(world.find_tag(1)).as_matrix()),
        gtsam.noiseModel.Unit.Create(6),
    )  # fmt: skip
    values = gtsam.Values()
    values.insert(1, gtsam.Pose3(tag_map.T_frame_tag(1).as_matrix()))
    assert anchor["translation_m"] == pytest.approx(
        np.linalg.norm(prior.unwhitenedError(values)[3:]), abs=2e-6
    )


def _relabelled(survey: Survey, from_id: int, to_id: int, t0_s: float, t1_s: float) -> Survey:
    start = survey_start_ns(survey)
    frames = []
    for f in survey.frames:
        t = (f.stamp_ns - start) * 1e-9
        dets = tuple(
            dataclasses.replace(d, tag_id=to_id) if d.tag_id == from_id and t0_s <= t <= t1_s else d
            for d in f.detections
        )
        frames.append(CameraFrame(f.stamp_ns, f.camera, dets))
    return dataclasses.replace(survey, frames=tuple(frames))


def test_excluding_a_planted_bad_edge_repairs_the_map(
    built: tuple[Survey, TagMap, BuildReport, World],
) -> None:
    survey, clean, _, world = built
    config = sim_build_config(simulate_drive(_short_world(), seed=1), ObservationConfig(seed=2))
    anchors = {1: world.T_map_tag(world.find_tag(1))}
    bad = _relabelled(survey, 13, 3, 3.0, 19.0)
    truth = world.T_map_tag(world.find_tag(3)).translation
    wrong, _ = build_tag_map(bad, anchors, config)
    assert np.linalg.norm(wrong.T_frame_tag(3).translation - truth) > 1.0
    repaired, _ = build_tag_map(
        exclude_observations(bad, [parse_exclusion("tag:3@3-19")]), anchors, config
    )
    # as good as the clean survey's map (which has tag 13's detections as tag 13)
    at = repaired.T_frame_tag(3).translation
    assert np.linalg.norm(at - clean.T_frame_tag(3).translation) < 0.02
    sigma = np.sqrt(np.trace(repaired.get(3).covariance_matrix()[:3, :3]))  # type: ignore[union-attr]
    assert np.linalg.norm(at - truth) < 3 * sigma


def test_exclusions_filter_only_what_they_name(
    built: tuple[Survey, TagMap, BuildReport, World],
) -> None:
    survey = built[0]

    def count(s: Survey, tag: int | None = None) -> int:
        return sum(1 for f in s.frames for d in f.detections if tag is None or d.tag_id == tag)

    whole = exclude_observations(survey, [parse_exclusion("tag:13")])
    assert count(whole, 13) == 0 and count(whole) == count(survey) - count(survey, 13)
    assert len(whole.frames) == len(survey.frames)
    assert whole.T_odom_base is survey.T_odom_base
    window = exclude_observations(survey, [parse_exclusion("time:0-10")])
    start = survey_start_ns(survey)
    assert all((f.stamp_ns - start) * 1e-9 > 10 or not f.detections for f in window.frames)
    assert exclude_observations(survey, []) is survey
    scans = SurveyScans(np.array([survey_start_ns(survey)]), (np.zeros((5, 3)),), (None,),
                        SE3.identity())  # fmt: skip
    with_lidar = exclude_observations(
        dataclasses.replace(survey, lidar=scans), [parse_exclusion("tag:13")]
    )
    assert with_lidar.lidar is scans  # the sweeps stay: scan matching, premap and grid
    for text, message in [
        ("tag:x", "expected tag:ID"),
        ("time:5", "expected tag:ID"),
        ("frame:3", "expected tag:ID"),
        ("time:9-3", "ends before it starts"),
        ("tag:13@", "expected tag:ID"),  # not "all of tag 13"
        ("tag:13@5", "expected tag:ID"),
    ]:
        with pytest.raises(MappingError, match=message):
            parse_exclusion(text)
    with pytest.raises(MappingError, match="tag 999 is never detected"):
        exclude_observations(survey, [parse_exclusion("tag:999")])
