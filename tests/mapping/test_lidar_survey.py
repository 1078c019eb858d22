"""The lidar-aided survey on simulated drives: scan matching against the simulator's truth.

Short: the office with a 60 m route through two rooms and back (:func:`room_loop_world`).
Slow (``--runslow``): the built-in office survey (the demo's) and a loop corridor with a tag
every 12 m and 0.3 deg/m of odometry yaw drift.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from survey_worlds import room_loop_world, sparse_tag_world

from tagloc.eval.occupancy import occupancy_iou
from tagloc.geometry import SE3
from tagloc.mapping import MappingError, Survey, build_tag_map
from tagloc.mapping.lidar_survey import prepare_lidar
from tagloc.mapping.observations import collect_observations
from tagloc.mapping.products import build_products
from tagloc.mapping.report import BuildReport
from tagloc.mapping.scan_factors import relative_errors
from tagloc.mapping.stream_survey import survey_from_messages
from tagloc.messages import OdometryMsg, PointCloudMsg, TagDetectionsMsg, TransformMsg
from tagloc.sim import Drive, ObservationConfig, load_default_world, simulate_drive
from tagloc.sim.survey import MapErrors, map_errors, sim_build_config, survey_and_anchors
from tagloc.sim.trajectory import se3_from_xy_yaw
from tagloc.sim.world import load_builtin_world
from tagloc.tags.tagmap import TagMap


@cache
def _drive(world_name: str, seed: int) -> Drive:
    worlds = {"rooms": room_loop_world, "office": load_default_world, "sparse": sparse_tag_world}
    world = worlds[world_name]() if world_name in worlds else load_builtin_world(world_name)
    return simulate_drive(world, seed=seed)


@cache
def _survey(world_name: str, seed: int, lidar: bool, stride: int = 3) -> tuple[Survey, dict]:
    return survey_and_anchors(_drive(world_name, seed), ObservationConfig(seed=seed), None,
                              stride, lidar)  # fmt: skip


@cache
def _built(world_name: str, seed: int, lidar: bool) -> tuple[TagMap, BuildReport, MapErrors]:
    drive = _drive(world_name, seed)
    survey, anchors = _survey(world_name, seed, lidar)
    config = sim_build_config(drive, ObservationConfig(seed=seed), gravity_aligned=lidar)
    tag_map, report = build_tag_map(survey, anchors, config)
    return tag_map, report, map_errors(tag_map, drive.world)


def _truth(drive: Drive, stamps_ns: np.ndarray) -> np.ndarray:
    xy_yaw = np.asarray(drive.ground_truth_at(stamps_ns).xy_yaw_map_base)
    return np.asarray(se3_from_xy_yaw(xy_yaw).as_matrix())


def test_short_survey_with_lidar_beats_tags_only() -> None:
    _, report, with_lidar = _built("rooms", 3, True)
    _, _, tags_only = _built("rooms", 3, False)
    m = report.scan_matching
    assert m["keyframes"] > 40 and m["sequential"] >= m["keyframes"] - 3 and m["loops"] > 5
    # measured (seed 3): tags only 8.0 cm, with lidar 3.2 cm
    assert with_lidar.position_rms_m < 0.5 * tags_only.position_rms_m
    assert with_lidar.position_rms_m < 0.045
    # the report states the scales it found: the registrations agree with the map's scale
    scale = report.scale
    assert scale["scan_matching_sigma"] > 0.0
    assert abs(scale["scan_matching"]) < max(4.0 * scale["scan_matching_sigma"], 0.003), scale
    assert any(line.startswith("scale: odometry corrected by") and "scan matching" in line
               for line in report.summary_lines())  # fmt: skip


def test_the_exported_graph_holds_every_scan_match_with_its_residual() -> None:
    _, report, _ = _built("rooms", 3, True)
    scans = [f for f in report.factors if f["type"] == "scan_match"]
    m = report.scan_matching
    assert len(scans) == m["sequential"] + m["loops"]
    assert sum(f["loop"] for f in scans) == m["loops"]
    assert all(f["keyframe_a"] != f["keyframe_b"] for f in scans)
    # at the solution the registrations agree with the optimized keyframes to a few cm
    assert np.median([f["translation_m"] for f in scans]) < 0.03
    assert report.factors[0]["factors"] == len(report.factors) - 1


def test_registrations_are_unbiased_and_their_covariance_honest() -> None:
    """Normalized errors of the consecutive registrations against the simulator's truth."""
    drive = _drive("rooms", 3)
    survey, _ = _survey("rooms", 3, True)
    config = sim_build_config(drive, ObservationConfig(seed=3))
    obs = collect_observations(survey, config.pnp_noise, config.max_range_m)
    prepared = prepare_lidar(survey, obs, config.lidar)
    assert prepared is not None
    obs, scans = prepared
    M_true = _truth(drive, obs.keyframe_stamps_ns)
    factors = scans.sequential(obs.T_odom_base.as_matrix().reshape(-1, 4, 4))
    # errors against the truth, normalized by each factor's own standard deviations
    from tagloc.mapping.initialize import inverse_h as inv
    from tagloc.mapping.odometry_factors import log_batch as log

    err = log(inv(factors.M_a_b) @ inv(M_true[factors.a]) @ M_true[factors.b])
    info = np.einsum("nji,njk->nik", factors.sqrt_information, factors.sqrt_information)
    sigma = np.sqrt(np.diagonal(np.linalg.inv(info), axis1=1, axis2=2))
    normalized = np.sqrt(np.mean((err / sigma) ** 2, axis=0))
    # yaw (what bends a map): calibrated, ~1; translation: held loosely on purpose (the 2 cm
    # floor), so conservative; roll, pitch, z: not over-confident beyond a factor 2
    assert 0.5 < normalized[5] < 2.0, normalized
    assert (normalized[:2] < 1.0).all(), normalized
    assert (normalized < 2.0).all(), normalized
    assert np.sum(relative_errors(M_true, factors) ** 2, axis=1).mean() / 6.0 < 2.0
    # and far better than the legged odometry between the same keyframes
    M_odo = obs.T_odom_base.as_matrix().reshape(-1, 4, 4)
    from tagloc.mapping.initialize import inverse_h
    from tagloc.mapping.odometry_factors import log_batch

    def yaw_rms(M: np.ndarray) -> float:
        Z_true = inverse_h(M_true[factors.a]) @ M_true[factors.b]
        Z = inverse_h(M[factors.a]) @ M[factors.b]
        return float(np.sqrt(np.mean(log_batch(inverse_h(Z) @ Z_true)[:, 5] ** 2)))

    scan_yaw = float(np.sqrt(np.mean(
        log_batch(inverse_h(factors.M_a_b) @ inverse_h(M_true[factors.a]) @ M_true[factors.b])[:, 5]
        ** 2)))  # fmt: skip
    assert scan_yaw < 0.5 * yaw_rms(M_odo)


def test_products_are_in_the_tags_frame_and_match_the_walls() -> None:
    drive = _drive("rooms", 3)
    survey, _ = _survey("rooms", 3, True)
    _, report, _ = _built("rooms", 3, True)
    products = build_products(survey, report)
    score = occupancy_iou(products.grid, drive.world)
    assert score.iou > 0.85 and score.precision > 0.9  # measured 0.896, 0.967
    # premap: the points at wall height lie on the true walls (within 5 cm for 90 %)
    walls = [w for w in drive.world.walls_in_map() if w.material == "wall"]
    a = np.array([w.start for w in walls], dtype=float)
    b = np.array([w.end for w in walls], dtype=float)
    p = products.premap_map[(products.premap_map[:, 2] > 0.3) & (products.premap_map[:, 2] < 2.0)]
    d = b - a
    t = np.clip(np.einsum("pwk,wk->pw", p[:, None, :2] - a, d) / np.sum(d * d, axis=1), 0, 1)
    dist = np.linalg.norm(p[:, None, :2] - (a + t[..., None] * d), axis=2).min(axis=1)
    assert np.quantile(dist, 0.9) < 0.05


def test_products_need_a_lidar_build() -> None:
    survey, _ = _survey("rooms", 3, True)
    _, report, _ = _built("rooms", 3, False)
    with pytest.raises(MappingError, match="without lidar"):
        build_products(survey, report)


def test_survey_from_messages_keeps_sweeps_by_travel_and_reads_the_mount() -> None:
    T_base_lidar = SE3.from_rotvec([0.0, 0.0, 0.1], [0.1, 0.0, 0.45])
    items: list[tuple[str, object]] = [
        ("/tf_static", TransformMsg(0, "base_link", "lidar", T_base_lidar, static=True))
    ]
    points = np.ones((10, 3), dtype=np.float32)
    for k in range(50):  # 0.1 m per 100 ms, a sweep every 100 ms
        stamp = k * 100_000_000
        pose = SE3.from_rotvec([0.0, 0.0, 0.0], [0.1 * k, 0.0, 0.0])
        items.append(("/odom", OdometryMsg(stamp, "odom", "base_link", pose, np.eye(6) * 1e-4)))
        items.append(("/lidar/points", PointCloudMsg(stamp + 1, "lidar", points)))
    items.append(("/tags", TagDetectionsMsg(1000, "cam0", ())))
    camera = {"cam0": load_default_world().robot.camera.camera_model()}
    T_base_cam = {"cam0": SE3.identity()}
    survey = survey_from_messages(items, {"/tags": "cam0"}, "/odom", camera, T_base_cam,
                                  lidar_topic="/lidar/points")  # fmt: skip
    assert survey.lidar is not None
    assert survey.lidar.T_base_lidar.allclose(T_base_lidar)
    assert len(survey.lidar) == 10  # every 0.5 m of 4.9 m
    missing = [item for item in items if item[0] != "/tf_static"]
    with pytest.raises(MappingError, match="no static transform base_link -> lidar"):
        survey_from_messages(missing, {"/tags": "cam0"}, "/odom", camera, T_base_cam,
                             lidar_topic="/lidar/points")  # fmt: skip


@pytest.mark.slow
def test_office_survey_with_lidar() -> None:
    """The demo's survey (seed 1, one anchor, gravity priors): the grid on the walls; tags
    measured 1.85 cm RMS (tags only 8.6 cm; scan-to-scan 2.4 cm; the 1.5 cm aim is not reached),
    grid IoU 0.899 (scan-to-scan 0.941; the 0.9 aim is missed by a hair)."""
    _, report, errors = _built("office", 1, True)
    _, _, tags_only = _built("office", 1, False)
    assert errors.position_rms_m < 0.022 and errors.position_rms_m < 0.3 * tags_only.position_rms_m
    survey, _ = _survey("office", 1, True)
    products = build_products(survey, report)
    assert occupancy_iou(products.grid, _drive("office", 1).world).iou >= 0.88


@pytest.mark.slow
def test_sparse_tags_with_yaw_drift() -> None:
    """A tag every 12 m, 0.3 deg/m of odometry yaw drift, one anchor, gravity priors. Measured:
    tags only 229 cm RMS; with lidar scan-to-scan 19.6 cm (4.4 cm after a rigid alignment),
    scan-to-map 10.9 cm (2.3 cm aligned; seed 2: 4.6 and 2.1 cm). What is left is mostly a few
    mrad of heading about the one anchor (its tag's rotation, poorly observed face-on), which
    no registration fixes; the 3 cm aim is not reached."""
    _, _, errors = _built("sparse", 1, True)
    _, _, tags_only = _built("sparse", 1, False)
    assert errors.position_rms_m < 0.13 and errors.position_rms_m < 0.1 * tags_only.position_rms_m
    assert errors.aligned_position_rms_m < 0.03


@pytest.mark.slow
def test_sparse_building_survey() -> None:
    """The built-in sparse building (two 60 m corridors joined at both ends, a tag every 12 m,
    glass, a mirrored lift lobby; 0.3 deg/m of yaw drift; one anchor). Measured (seed 1):
    26.8 cm tag RMS, 5.3 cm after a rigid alignment: the heading about the one anchor again, and
    the 3 cm aim is far off."""
    _, report, errors = _built("sparse_building", 1, True)
    assert report.scan_matching["loops"] > 10
    assert errors.position_rms_m < 0.32
    assert errors.aligned_position_rms_m < 0.065
