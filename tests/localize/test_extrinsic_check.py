"""The camera checks: the mounting (hand-eye from fixes) and the camera model (before any fix).

Oracles: a synthetic planar drive whose true ``T_base_cam`` is known (fixes are the true camera
poses with seeded noise); the simulator's true extrinsics and camera (slow tests)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tagloc.geometry import SE3
from tagloc.localize.extrinsic_check import check_extrinsics, check_run_extrinsics
from tagloc.localize.extrinsic_rig import ExtrinsicRecorder
from tagloc.localize.intrinsic_check import check_camera
from tagloc.localize.outputs import Estimate
from tagloc.localize.run import FixAttempt

S_NS = 1_000_000_000
# optical frame 0.25 m ahead, 0.5 m up, pitched 5 deg up (x right, y down, z forward)
_R = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
_PITCH = SE3.from_rotvec([0.0, -math.radians(5.0), 0.0], [0.0, 0.0, 0.0])
T_BASE_CAM_TRUE = SE3.from_matrix(
    np.block([[_R, np.array([[0.25], [0.0], [0.5]])], [np.zeros((1, 3)), np.ones((1, 1))]])
)
T_BASE_CAM_TRUE = (
    SE3.from_rotvec([0.0, 0.0, 0.0], [0.25, 0.0, 0.5])
    @ _PITCH
    @ SE3.from_matrix(np.block([[_R, np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]]))
)
# 1 deg about the camera's (vertical) y axis, 3 cm to the camera's right
MISSET = np.array([0.03, 0.0, 0.0, 0.0, math.radians(1.0), 0.0])


def _error(T_est: SE3, T_true: SE3) -> tuple[float, float]:
    """(rotation deg, horizontal translation m) of ``T_true^-1 T_est``."""
    d = (T_true.inverse() @ T_est).log()
    return math.degrees(float(np.linalg.norm(d[3:]))), float(np.hypot(d[0], d[2]))


def _planar_drive(seed: int, n: int = 9000) -> tuple[np.ndarray, SE3, SE3]:
    """A planar drive at 100 Hz that turns (yaw rate varies) and its true ``T_map_base``;
    odometry = truth (drift is the slow tests' business)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    yaw_rate = 0.6 * np.sin(0.21 * t) + 0.4 * np.sin(0.05 * t + 1.0)
    yaw = np.cumsum(yaw_rate) / 100.0
    speed = 0.5 + 0.3 * np.sin(0.13 * t)
    xy = np.cumsum(np.stack([speed * np.cos(yaw), speed * np.sin(yaw)], 1), 0) / 100.0
    rotvec = np.zeros((n, 3))
    rotvec[:, 2] = yaw
    translation = np.column_stack([xy, np.full(n, 0.0)])
    T_map_base = SE3.from_rotvec(rotvec, translation)
    del rng
    return (t * S_NS).astype(np.int64), T_map_base, T_map_base


def _fixes(
    stamps: np.ndarray, T_map_base: SE3, T_base_cam_used: SE3, seed: int, *,
    true: SE3 = T_BASE_CAM_TRUE, camera: str = "", n_tags: int = 1,
) -> list[FixAttempt]:  # fmt: skip
    """Fixes at 10 Hz as the node forms them: the (noisy) true camera pose, expressed as
    ``T_map_base`` through the extrinsics the node was given (``n_tags``: the tag seen
    changes every 5 s among that many)."""
    rng = np.random.default_rng(seed)
    sig = np.array([0.01, 0.01, 0.01, 0.005, 0.005, 0.005])
    cov = np.diag(sig**2)
    out = []
    for k in range(0, len(stamps), 10):
        T_map_cam = T_map_base[k] @ true @ SE3.exp(rng.normal(0.0, sig))
        tag = 1 + (k // 500) % n_tags
        out.append(FixAttempt(int(stamps[k]), f"tag:{tag}", (tag,),
                              T_map_cam @ T_base_cam_used.inverse(), cov, "accepted", 2.0, 0.3,
                              camera=camera))  # fmt: skip
    return out


def test_a_misset_mounting_is_estimated_and_warned() -> None:
    stamps, T_map_base, T_odom_base = _planar_drive(seed=1)
    used = T_BASE_CAM_TRUE @ SE3.exp(MISSET)
    check = check_extrinsics(_fixes(stamps, T_map_base, used, seed=2), stamps, T_odom_base, used)
    assert check is not None
    rot_deg, trans_m = _error(check.T_base_cam_estimate, T_BASE_CAM_TRUE)
    assert rot_deg < 0.2 and trans_m < 0.01, (rot_deg, trans_m, check.xi)
    assert check.warning is not None and "check T_base_cam" in check.warning
    # planar motion cannot see the camera's height (its y, pointing down)
    assert "y" in check.to_dict()["unobservable"]


def test_a_correct_mounting_is_not_warned() -> None:
    stamps, T_map_base, T_odom_base = _planar_drive(seed=3)
    check = check_extrinsics(
        _fixes(stamps, T_map_base, T_BASE_CAM_TRUE, seed=4), stamps, T_odom_base, T_BASE_CAM_TRUE
    )
    assert check is not None and check.warning is None, check.to_dict()
    assert check.rotation_deg < 0.2 and check.translation_m < 0.01


def test_too_few_fixes_give_no_verdict() -> None:
    stamps, T_map_base, T_odom_base = _planar_drive(seed=5, n=300)
    fixes = _fixes(stamps, T_map_base, T_BASE_CAM_TRUE, seed=6)[:5]
    assert check_extrinsics(fixes, stamps, T_odom_base, T_BASE_CAM_TRUE) is None


def _streamed(
    recorder: ExtrinsicRecorder, stamps: np.ndarray, T_odom_base: SE3, fixes: list[FixAttempt]
) -> None:
    """Feed ``recorder`` as the node does: an estimate per odometry sample, each fix record
    3 s after its stamp (when the held window releases it)."""
    pending = list(fixes)
    for k, stamp in enumerate(stamps.tolist()):
        recorder.write(Estimate(stamp, T_odom_base[k], SE3.identity(), None, True, True,
                                "map", "odom"))  # fmt: skip
        while pending and pending[0].stamp_ns <= stamp - 3 * S_NS:
            recorder.write(pending.pop(0))


def test_the_streaming_recorder_agrees_with_the_whole_run_in_bounded_memory() -> None:
    stamps, T_map_base, T_odom_base = _planar_drive(seed=7)
    used = T_BASE_CAM_TRUE @ SE3.exp(MISSET)
    fixes = _fixes(stamps, T_map_base, used, seed=8)
    recorder = ExtrinsicRecorder(odometry_window=500)  # 5 s of 100 Hz odometry
    _streamed(recorder, stamps, T_odom_base, fixes)
    released = [f for f in fixes if f.stamp_ns <= stamps[-1] - 3 * S_NS]
    oracle = check_extrinsics(released, stamps, T_odom_base, used)
    check = recorder.check(used)
    assert oracle is not None and check is not None
    assert np.allclose(check.xi, oracle.xi, atol=1e-9) and check.n_pairs == oracle.n_pairs
    held = recorder.held  # the odometry kept: the window (to twice it), not the drive
    assert held["fixes"] == sum(f.accepted for f in released) and 500 <= held["odometry"] <= 1000


def test_the_recorder_and_the_fit_are_bounded_and_still_find_the_misset() -> None:
    """Past ``max_fixes`` the recorder keeps whole blocks spread over the drive: what it holds
    after a drive 3 times as long is the same size, and the check on it still finds the
    mis-set (against the synthetic truth, the same tolerances as on every fix)."""
    held = []
    for n in (18_000, 54_000):  # 180 s and 540 s of 100 Hz odometry, 10 Hz fixes
        stamps, T_map_base, T_odom_base = _planar_drive(seed=9, n=n)
        used = T_BASE_CAM_TRUE @ SE3.exp(MISSET)
        recorder = ExtrinsicRecorder(max_fixes=1000, odometry_window=500)
        _streamed(recorder, stamps, T_odom_base, _fixes(stamps, T_map_base, used, seed=10))
        held.append(recorder.held)
        check = recorder.check(used)
        assert check is not None and check.warning is not None, check
        assert check.n_fixes <= 1000
        rot_deg, trans_m = _error(check.T_base_cam_estimate, T_BASE_CAM_TRUE)
        assert rot_deg < 0.2 and trans_m < 0.01, (rot_deg, trans_m, check.xi)
    assert held[0]["fixes"] <= 1000 and held[1]["fixes"] <= 1000
    assert held[1]["numbers"] == held[0]["numbers"], held  # the state does not grow with N
    assert held[1]["thinning"] > held[0]["thinning"] >= 1


# ----- a rig of two cameras --------------------------------------------------------------------
#: A second camera 0.2 m to the first one's right (its x), as on a stereo rig.
T_BASE_CAM1_TRUE = T_BASE_CAM_TRUE @ SE3.from_rotvec([0.0, 0.0, 0.0], [0.2, 0.0, 0.0])


def _rig(used0: SE3, used1: SE3) -> ExtrinsicRecorder:
    """A recorder fed a drive of a two-camera rig seeing 10 tags, both cameras at each stamp."""
    stamps, T_map_base, T_odom_base = _planar_drive(seed=11)
    fixes = sorted(
        _fixes(stamps, T_map_base, used0, 12, camera="cam0", n_tags=10)
        + _fixes(stamps, T_map_base, used1, 13, true=T_BASE_CAM1_TRUE, camera="cam1", n_tags=10),
        key=lambda f: f.stamp_ns,
    )  # fmt: skip
    recorder = ExtrinsicRecorder(odometry_window=500)
    _streamed(recorder, stamps, T_odom_base, fixes)
    return recorder


def test_a_misset_of_one_camera_of_a_rig_warns_for_that_camera_only() -> None:
    used1 = T_BASE_CAM1_TRUE @ SE3.exp(MISSET)
    extrinsics = {"cam0": T_BASE_CAM_TRUE, "cam1": used1}
    verdicts, rig_line = _rig(T_BASE_CAM_TRUE, used1).verdicts(extrinsics)
    assert verdicts["cam0"].warning is None and rig_line is None
    assert verdicts["cam1"].warning is not None and verdicts["cam1"].warning.startswith("cam1: ")
    check = verdicts["cam1"].check
    assert check is not None
    rot_deg, trans_m = _error(check.T_base_cam_estimate, T_BASE_CAM1_TRUE)
    assert rot_deg < 0.2 and trans_m < 0.01, (rot_deg, trans_m)
    # the relative mounting, measured without the odometry, finds the mis-set too
    relative = verdicts["cam1"].relative
    assert relative is not None and not relative.agrees and relative.n_tags == 10
    truth = ((T_BASE_CAM_TRUE.inverse() @ used1).inverse()
             @ (T_BASE_CAM_TRUE.inverse() @ T_BASE_CAM1_TRUE)).log()  # fmt: skip
    assert np.all(np.abs(relative.xi - truth) <= 4.0 * relative.sigma + 1e-4), (relative, truth)


def test_a_correction_every_camera_shares_is_laid_on_the_rig() -> None:
    """The base frame's placement off (1 deg, 3 cm in the base): each camera's own check
    finds it, their relative mounting agrees with the calibration, so no camera is blamed."""
    moved = SE3.from_rotvec([0.0, 0.0, math.radians(1.0)], [0.03, 0.0, 0.0])
    used0, used1 = moved @ T_BASE_CAM_TRUE, moved @ T_BASE_CAM1_TRUE
    verdicts, rig_line = _rig(used0, used1).verdicts({"cam0": used0, "cam1": used1})
    assert rig_line is not None and "cam0, cam1" in rig_line
    for name, true in (("cam0", T_BASE_CAM_TRUE), ("cam1", T_BASE_CAM1_TRUE)):
        v = verdicts[name]
        assert v.warning is None and v.shared and v.check is not None
        assert v.check.warning is not None  # its own check found the correction
        rot_deg, trans_m = _error(v.check.T_base_cam_estimate, true)
        assert rot_deg < 0.2 and trans_m < 0.01, (name, rot_deg, trans_m)
    relative = verdicts["cam1"].relative
    assert relative is not None and relative.agrees


@pytest.mark.slow
def test_a_simulated_rig_with_one_misset_camera_warns_for_that_camera_only() -> None:
    """``test_multi_camera``'s rig (the simulator's front camera, a back camera whose corners
    OpenCV projects), 120 s of the legged drive, the back camera given 1 deg / 3 cm off: the
    back camera is warned, its estimate within 4 of its sigmas of the simulator's mounting on
    every observable axis; the front camera is not warned."""
    from test_multi_camera import BACK, make_rig

    from tagloc.eval.scenarios import calibrated_config, scenario_config
    from tagloc.localize.node import LocalizerNode, NodeCamera

    source, T_base_back, _, stream = make_rig(120.0)
    used = T_base_back @ SE3.exp(MISSET)
    cameras = [NodeCamera("front", source.t.detections, source.camera, source.T_base_cam),
               NodeCamera("back", BACK, source.camera, used)]  # fmt: skip
    recorder = ExtrinsicRecorder()
    config = calibrated_config(source.scenario, scenario_config())
    node = LocalizerNode(source.scenario.tag_map, config, [recorder], cameras=cameras)
    for topic, msg in stream:
        node.feed(topic, msg)
    node.finish()
    verdicts, rig_line = recorder.verdicts(node.T_base_cam_by_camera)
    assert verdicts["front"].warning is None, verdicts["front"].to_dict()
    back = verdicts["back"]
    assert back.warning is not None and rig_line is None, back.to_dict()
    found = back.to_dict()
    assert found is not None
    truth = (used.inverse() @ T_base_back).log()
    for i, axis in enumerate(("x", "y", "z", "rx", "ry", "rz")):
        if axis in found["sigma_cam"]:
            z = abs(found["correction_cam"][axis] - truth[i]) / found["sigma_cam"][axis]
            assert z <= 4.0, (axis, z, found)


def _wheel_scenario(duration_s: float):  # type: ignore[no-untyped-def]
    from tagloc.sim.odometry import WheelOdometryConfig
    from tagloc.sim.scenarios import build_scenario
    from tagloc.sim.world import load_default_world

    world = load_default_world()
    robot = world.robot.model_copy(update={"odometry": WheelOdometryConfig(model="wheel")})
    return build_scenario("default", 0, duration_s, world=world.model_copy(update={"robot": robot}))


@pytest.mark.slow
def test_simulated_misset_mounting_is_estimated() -> None:
    """The simulator's drive (wheel odometry: no sideways drift, which a camera's yaw cannot be
    told apart from), the node given a mounting 1 deg / 3 cm off. The estimate is judged against
    the simulator's mounting with the check's own sigma: every observable axis within 4 sigma
    (measured, seed 0, 240 s: at most 3.0 sigma, on rx; the estimate 0.24 deg / 3 mm from the
    truth, the pitch's sigma 0.46 deg), and most of the mis-set removed."""
    from functools import partial

    from tagloc.eval.scenarios import calibrated_config, scenario_config
    from tagloc.localize import LocalizerNode, record_run
    from tagloc.sim.scenarios import ScenarioSource

    scenario = _wheel_scenario(240.0)
    source = ScenarioSource(scenario)
    used = source.T_base_cam @ SE3.exp(MISSET)
    config = calibrated_config(scenario, scenario_config())
    run = record_run(partial(LocalizerNode, scenario.tag_map, config, T_base_cam=used), source)
    check = check_run_extrinsics(run, used)
    assert check is not None and check.warning is not None
    found = check.to_dict()
    truth = (used.inverse() @ source.T_base_cam).log()  # the correction the check should find
    for i, axis in enumerate(("x", "y", "z", "rx", "ry", "rz")):
        if axis in found["sigma_cam"]:
            z = abs(found["correction_cam"][axis] - truth[i]) / found["sigma_cam"][axis]
            assert z <= 4.0, (axis, z, found)
    rot_deg, trans_m = _error(check.T_base_cam_estimate, source.T_base_cam)
    assert rot_deg < 0.4 and trans_m < 0.01, (rot_deg, trans_m, found)


# ----- the camera model -------------------------------------------------------------------------
def _stream(duration_s: float):  # type: ignore[no-untyped-def]
    from tagloc.sim.scenarios import ScenarioSource, build_scenario

    scenario = build_scenario("default", 0, duration_s)
    source = ScenarioSource(scenario)
    return scenario, source, list(source)


@pytest.fixture(scope="module")
def sim_stream():  # type: ignore[no-untyped-def]
    return _stream(20.0)


def test_the_right_camera_passes_and_a_halved_focal_is_refused(sim_stream) -> None:  # type: ignore[no-untyped-def]
    from tagloc.camera import PinholeRadtan

    scenario, source, messages = sim_stream
    good = source.camera
    assert isinstance(good, PinholeRadtan)
    half = PinholeRadtan(width=good.width, height=good.height, fx=good.fx / 2, fy=good.fy / 2,
                         cx=good.cx, cy=good.cy)  # fmt: skip
    options = {"detections_topic": "/tag_detections", "odom_topic": "/odom"}
    ok = check_camera(messages, good, scenario.tag_map, camera_info_topic="/camera/camera_info",
                      **options)  # fmt: skip
    assert ok.problems == [] and abs(ok.scale - 1.0) < 0.1 and ok.n_pairs >= 5, ok
    # without CameraInfo, the depth scale against the odometry alone refuses it
    bad = check_camera(messages, half, scenario.tag_map, **options)
    assert bad.n_pairs >= 5 and abs(bad.scale - 0.5) < 0.1, bad
    assert len(bad.problems) == 1 and f"{bad.scale:.2f} x the depth" in bad.problems[0]
    # with CameraInfo, the focal lengths disagree
    info = check_camera(messages, half, scenario.tag_map, camera_info_topic="/camera/camera_info",
                        **options)  # fmt: skip
    assert any("fx = 640.0 px" in p for p in info.problems), info


def _sim_check(seed: int, duration_s: float, misset: bool):  # type: ignore[no-untyped-def]
    """The mounting check of the node's run on the default scenario (legged odometry), the
    node given the true mounting or one 1 deg / 3 cm off."""
    from functools import partial

    from tagloc.eval.scenarios import calibrated_config, scenario_config
    from tagloc.localize import LocalizerNode, record_run
    from tagloc.sim.scenarios import ScenarioSource, build_scenario

    scenario = build_scenario("default", seed, duration_s)
    source = ScenarioSource(scenario, lidar=False)
    used = source.T_base_cam @ SE3.exp(MISSET) if misset else source.T_base_cam
    config = calibrated_config(scenario, scenario_config())
    config = config.model_copy(update={"lidar": config.lidar.model_copy(update={"enabled": False})})
    node = partial(LocalizerNode, scenario.tag_map, config, T_base_cam=used,
                   frame_truth=source.frame_truth)  # fmt: skip
    return check_run_extrinsics(record_run(node, source), used)


def test_a_simulated_legged_drive_with_the_right_camera_is_not_warned() -> None:
    check = _sim_check(0, 120.0, misset=False)
    assert check is not None and check.warning is None, check.to_dict()


@pytest.mark.slow
def test_a_simulated_misset_camera_is_warned_on_a_legged_drive() -> None:
    check = _sim_check(0, 120.0, misset=True)
    assert check is not None and check.warning is not None, check.to_dict()


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(1, 10))
def test_ten_simulated_drives_with_the_right_camera_are_not_warned(seed: int) -> None:
    check = _sim_check(seed, 120.0, misset=False)
    assert check is None or check.warning is None, check.to_dict()
