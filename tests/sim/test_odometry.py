"""Odometry drift: exact without errors, reproducible by seed, statistics match the parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from tagloc.sim import (
    DriftParameters,
    LeggedOdometryConfig,
    WheelOdometryConfig,
    load_default_world,
    simulate_odometry,
)
from tagloc.sim.odometry import (
    corrupt_motion,
    integrate_motion,
    relative_motion,
    simulate_odometry_xy_yaw,
)
from tagloc.sim.trajectory import generate_trajectory, plan_from_config, plan_route

FloatArray = NDArray[np.float64]
LINE_M = 100.0


@pytest.fixture(scope="module")
def office_xy_yaw() -> FloatArray:
    world = load_default_world()
    plan = plan_from_config(world.route, world.checkpoints_xy())
    return generate_trajectory(plan, world.robot.odom_rate_hz).xy_yaw_map_base


@pytest.fixture(scope="module")
def line_xy_yaw() -> FloatArray:
    """A straight 100 m drive along +x at 50 Hz (the models do not depend on the rate)."""
    plan = plan_route(
        np.array([[0.0, 0.0], [LINE_M, 0.0]]),
        [0.0, 0.0],
        speed=1.0,
        accel_max=0.5,
        yaw_rate_max=1.0,
        yaw_accel_max=1.0,
    )
    return generate_trajectory(plan, 50.0).xy_yaw_map_base


def test_relative_and_integrate_are_inverse(office_xy_yaw: FloatArray) -> None:
    again = integrate_motion(office_xy_yaw[0], relative_motion(office_xy_yaw))
    np.testing.assert_allclose(again, office_xy_yaw, atol=1e-9)


def test_zero_parameters_reproduce_ground_truth(office_xy_yaw: FloatArray) -> None:
    fields = set(LeggedOdometryConfig.model_fields) - {"model", "seed", "imu"}
    wheel_fields = fields & set(WheelOdometryConfig.model_fields)
    for config in (
        LeggedOdometryConfig(model="legged", **dict.fromkeys(fields, 0.0)),
        WheelOdometryConfig(model="wheel", **dict.fromkeys(wheel_fields, 0.0)),
    ):
        T_odom_base = simulate_odometry(config, office_xy_yaw, seed=3)
        truth = office_xy_yaw
        np.testing.assert_allclose(T_odom_base.translation[:, :2], truth[:, :2], atol=1e-9)
        yaw = T_odom_base.rotation.as_rotvec()[:, 2]
        np.testing.assert_allclose(np.angle(np.exp(1j * (yaw - truth[:, 2]))), 0.0, atol=1e-9)


def test_seeded_runs_reproduce_and_differ(office_xy_yaw: FloatArray) -> None:
    config = LeggedOdometryConfig(model="legged", seed=5)
    a = simulate_odometry(config, office_xy_yaw)
    b = simulate_odometry(config, office_xy_yaw, seed=5)
    c = simulate_odometry(config, office_xy_yaw, seed=6)
    np.testing.assert_array_equal(a.translation, b.translation)
    assert np.abs(a.translation - c.translation).max() > 0.5
    # odom == map at the start; drift accumulates to metres by the end of the default drive
    np.testing.assert_allclose(a.translation[0, :2], office_xy_yaw[0, :2], atol=0)
    assert np.linalg.norm(a.translation[-1, :2] - office_xy_yaw[-1, :2]) > 1.0


def test_systematic_errors_are_exact_without_noise(line_xy_yaw: FloatArray) -> None:
    """Yaw bias b (rad/m) bends the line into an arc of radius 1/b; scale stretches it."""
    bias, scale = math.radians(0.5), 0.03
    params = DriftParameters(scale_error=scale, yaw_bias_per_m=bias)
    odom = simulate_odometry_xy_yaw(line_xy_yaw, params, np.random.default_rng(0))
    length = LINE_M * (1 + scale)
    assert odom[-1, 2] == pytest.approx(bias * LINE_M, rel=1e-9)
    radius = length / (bias * LINE_M)  # heading grows by bias per true metre = per 1+s measured
    expected = [radius * math.sin(bias * LINE_M), radius * (1 - math.cos(bias * LINE_M))]
    # each step translates before it turns, so the discrete path lags the arc by half a step of
    # heading: about bias * step / 2 * length (9 mm here)
    step = np.linalg.norm(np.diff(line_xy_yaw[:, :2], axis=0), axis=1).max()
    np.testing.assert_allclose(odom[-1, :2], expected, atol=bias * step * length)


def _measured_increments(xy_yaw: FloatArray, params: DriftParameters, seeds: range) -> FloatArray:
    """(S, 3): per run, sum of measured [dx, dy, dyaw] along the path."""
    truth = relative_motion(xy_yaw)
    return np.array([corrupt_motion(truth, params, np.random.default_rng(s)).sum(0) for s in seeds])


@pytest.mark.parametrize(
    "config",
    [WheelOdometryConfig(model="wheel"), LeggedOdometryConfig(model="legged")],
    ids=["wheel", "legged"],
)
def test_drift_statistics_match_the_parameters(
    line_xy_yaw: FloatArray, config: WheelOdometryConfig
) -> None:
    """Over 200 seeded 100 m runs: mean scale error, yaw drift and lateral drift within 4 sigma."""
    params = DriftParameters.from_config(config)
    runs = 200
    sums = _measured_increments(line_xy_yaw, params, range(runs))
    slip_var_xy = params.slip_rate_per_m * LINE_M * params.slip_sigma_xy_m**2
    slip_var_yaw = params.slip_rate_per_m * LINE_M * params.slip_sigma_yaw**2
    sigma_xy = math.sqrt(params.sigma_xy_per_sqrt_m**2 * LINE_M + slip_var_xy)
    sigma_yaw = math.sqrt(params.sigma_yaw_per_sqrt_m**2 * LINE_M + slip_var_yaw)
    tol = 4 / math.sqrt(runs)
    scale = sums[:, 0] / LINE_M - 1
    assert abs(scale.mean() - params.scale_error) <= tol * sigma_xy / LINE_M
    lateral = sums[:, 1] / LINE_M
    assert abs(lateral.mean() - params.lateral_drift) <= tol * sigma_xy / LINE_M
    yaw_per_m = sums[:, 2] / LINE_M
    assert abs(yaw_per_m.mean() - params.yaw_bias_per_m) <= tol * sigma_yaw / LINE_M
    # the spread matches the random walk (+ slips): std within 20 % of the prediction
    assert sums[:, 0].std() == pytest.approx(sigma_xy, rel=0.2)
    assert sums[:, 2].std() == pytest.approx(sigma_yaw, rel=0.2)


def test_slips_follow_a_poisson_rate(line_xy_yaw: FloatArray) -> None:
    params = DriftParameters(
        slip_rate_per_m=0.05, slip_sigma_xy_m=0.05, slip_sigma_yaw=math.radians(3.0)
    )
    runs = 300
    sums = _measured_increments(line_xy_yaw, params, range(runs))
    truth = relative_motion(line_xy_yaw).sum(0)
    err = sums - truth
    jumped = np.abs(err[:, 2]) > 0
    expected_clean = math.exp(-params.slip_rate_per_m * LINE_M)  # P(no slip in 100 m)
    assert (~jumped).mean() == pytest.approx(
        expected_clean, abs=4 * math.sqrt(expected_clean * (1 - expected_clean) / runs)
    )
    var_yaw = params.slip_rate_per_m * LINE_M * params.slip_sigma_yaw**2
    assert err[:, 2].std() == pytest.approx(math.sqrt(var_yaw), rel=0.2)


def test_turn_scale_error_applies_per_radian() -> None:
    """Turning in place: yaw error = yaw_scale_error * angle; no translation error."""
    points = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0], [1.0, 0.0]])
    xy_yaw = generate_trajectory(
        plan_route(
            points, [0.0] * 4, speed=1.0, accel_max=1.0, yaw_rate_max=1.0, yaw_accel_max=1.0
        ),
        100.0,
    )
    truth = xy_yaw.xy_yaw_map_base
    params = DriftParameters(yaw_scale_error=0.1)
    odom = simulate_odometry_xy_yaw(truth, params, np.random.default_rng(0))
    turned = np.abs(np.diff(truth[:, 2])).sum()
    assert turned == pytest.approx(2 * math.pi)
    # the two reversals turn opposite ways, so the scale errors cancel at the end ...
    assert odom[-1, 2] - truth[-1, 2] == pytest.approx(0.0, abs=1e-9)
    # ... but not after the first one
    first = int(np.argmax(np.abs(truth[:, 2]) > math.pi - 1e-9))
    assert odom[first, 2] - truth[first, 2] == pytest.approx(0.1 * math.pi, rel=1e-6)
    assert params.model_copy(update={"yaw_scale_error": 0.0}) == DriftParameters()


def test_legged_drifts_more_than_wheel(office_xy_yaw: FloatArray) -> None:
    def median_end_error(config: WheelOdometryConfig | LeggedOdometryConfig) -> float:
        ends = [
            simulate_odometry(config, office_xy_yaw, seed=s).translation[-1, :2] for s in range(8)
        ]
        return float(np.median(np.linalg.norm(np.array(ends) - office_xy_yaw[-1, :2], axis=1)))

    wheel = median_end_error(WheelOdometryConfig(model="wheel"))
    legged = median_end_error(LeggedOdometryConfig(model="legged"))
    assert 1.0 < wheel < legged < 30.0
