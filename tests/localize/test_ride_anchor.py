"""The pose in ``map`` after an elevator ride, against the simulator's truth.

The elevator scenario rides the tower's cab between floors; on each exit the landing's first
tags are metres away and head-on. The pose in ``map`` 1 s after the first landing fix of each
exit must be within 5 cm of the simulator's truth (the cab carries it through the ride, the far
tags no longer drag it). The default run is short (it rides the cab once); the slow one rides it
four times on each of three seeds.
"""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.eval.elevator import EXIT_AFTER_S, exits
from tagloc.eval.scenarios import ride_truth, run_scenario
from tagloc.geometry import SE3
from tagloc.localize.fix import FixQuality, TagFix
from tagloc.localize.ride_anchor import (
    CabPlacement,
    LandingSettle,
    range_covariance,
    tilt_covariance,
)
from tagloc.sim.scenarios import build_scenario
from tagloc.supervise import ElevatorConfig
from tagloc.units import S_NS

EXIT_TOL_M = 0.05


def _exit_errors(seed: int, duration_s: float) -> tuple[list[float], int, int]:
    """Per exit: the pose error in map 1 s after its first landing fix (m); exits whose floor
    is right; exits."""
    run = run_scenario("elevator", seed, duration_s)
    truth = ride_truth(build_scenario("elevator", seed, duration_s))
    assert run.T_map_base_truth is not None
    stamps = np.asarray(run.stamps_ns)
    errors, right, rides = [], 0, exits(run)
    for ride in rides:
        first = min(
            a.stamp_ns for a in run.fixes
            if a.stamp_ns >= ride.opened_ns and a.tag_ids and a.tag_ids[0] in truth.tag_floor
            and not a.decision.startswith("rejected")
        )  # fmt: skip
        k = int(np.searchsorted(stamps, first + round(EXIT_AFTER_S * S_NS)))
        d = run.T_map_base[k].translation - run.T_map_base_truth[k].translation
        errors.append(float(np.linalg.norm(d)))
        j = int(np.searchsorted(stamps, ride.in_map_ns))
        published = next(f for f in run.floors[j:] if f is not None)
        right += published == truth.floor_at(stamps[j : j + 1])[0]
    return errors, right, len(rides)


@pytest.mark.parametrize(
    ("seed", "duration_s", "min_rides"),
    [
        (0, 85.0, 1),
        pytest.param(0, 300.0, 4, marks=pytest.mark.slow),
        pytest.param(1, 300.0, 4, marks=pytest.mark.slow),
        pytest.param(2, 300.0, 4, marks=pytest.mark.slow),
    ],
)
def test_the_pose_in_map_after_each_exit_is_within_5_cm_of_the_truth(
    seed: int, duration_s: float, min_rides: int
) -> None:
    errors, right, rides = _exit_errors(seed, duration_s)
    assert rides >= min_rides
    assert right == rides
    assert max(errors) <= EXIT_TOL_M, [round(100 * e, 1) for e in errors]


def test_the_tilt_covariance_is_the_rotation_of_the_view_about_the_tags_vertical() -> None:
    """Oracle: the base rotated by a small angle about the tag's vertical axis, its right
    perturbation measured with the group's own ``minus``."""
    T_map_base = SE3.from_rotvec([0.0, 0.0, 0.7], [2.0, -1.0, 0.1])
    p_tag = np.array([7.5, 3.0, 1.2])
    e, sigma = 1e-6, 0.05
    R_about = SE3.from_rotvec([0.0, 0.0, e], [0.0, 0.0, 0.0])
    to_tag, from_tag = SE3.from_rotvec(np.zeros(3), p_tag), SE3.from_rotvec(np.zeros(3), -p_tag)
    turned = to_tag @ R_about @ from_tag @ T_map_base
    J = turned.minus(T_map_base) / e
    cov = tilt_covariance(T_map_base, p_tag, sigma)
    np.testing.assert_allclose(cov, sigma**2 * np.outer(J, J), rtol=1e-4, atol=1e-9)
    assert np.linalg.matrix_rank(cov) == 1
    # range times the angle: the base's shift is |v_xy| * e
    v = T_map_base.inverse().act(p_tag)
    assert np.hypot(*J[:2]) == pytest.approx(np.hypot(v[0], v[1]), rel=1e-4)


def test_the_cab_placement_is_the_information_weighted_mean_of_the_rides() -> None:
    """Two measurements of the cab's pose, the second four times as certain: the fused pose is
    1/5 of the way from the second to the first (a scalar Kalman update per direction)."""
    place = CabPlacement()
    a = SE3.from_rotvec([0.0, 0.0, 0.3], [1.0, 2.0, 0.0])
    b = a.plus(np.array([0.05, -0.10, 0.0, 0.0, 0.0, 0.02]))
    place.add(a, np.eye(6) * 4e-4)
    place.add(b, np.eye(6) * 1e-4)
    assert place.T_floor_cab is not None and place.cov is not None
    np.testing.assert_allclose(place.T_floor_cab.minus(a), 0.8 * b.minus(a), atol=1e-6)
    np.testing.assert_allclose(np.diag(place.cov), 0.8e-4, rtol=1e-4)


def test_fixes_of_one_view_count_one_over_n_and_a_near_tag_ends_the_settling() -> None:
    """Far fixes of one tag from one viewpoint: the n-th gets n times (its covariance plus the
    view's turn and range error); a new viewpoint starts over; a fix from within
    ``landing_near_m`` is taken as it is and ends the settling, as does ``landing_settle_m`` of
    travel."""
    config = ElevatorConfig()
    p_tag = np.array([8.0, 0.0, 1.2])
    settle = LandingSettle(config, odometer_m=100.0, tag_positions_map={27: p_tag})
    T_map_base = SE3.from_rotvec(np.zeros(3), [1.0, 0.5, 0.0])
    cov = np.diag([1e-4, 1e-4, 4e-4, 1e-4, 1e-4, 1e-4])

    def fix(range_m: float, stamp_ns: int) -> TagFix:
        return TagFix(stamp_ns, T_map_base, cov, "tag:27", FixQuality(0.2, 1, range_m))

    sigma = config.landing_tilt_sigma_rad
    view = tilt_covariance(T_map_base, p_tag, sigma) + range_covariance(T_map_base, p_tag, sigma)
    for n, odometer_m in [(1, 100.0), (2, 100.2), (3, 100.9), (1, 101.0), (2, 101.5)]:
        out = settle.weigh(fix(7.0, n), odometer_m)
        np.testing.assert_allclose(out.cov, n * (cov + view), rtol=1e-12)
    assert not settle.done
    near = fix(config.landing_near_m - 0.1, 9)
    assert settle.weigh(near, 102.0) is near and settle.done
    walked = LandingSettle(config, odometer_m=0.0, tag_positions_map={27: p_tag})
    far = fix(7.0, 10)
    assert walked.weigh(far, config.landing_settle_m) is far and walked.done


def test_the_range_covariance_lies_along_the_line_of_sight() -> None:
    """The tag straight ahead of the base (its x): only x varies, by (range * sigma)^2."""
    T_map_base = SE3.from_rotvec([0.0, 0.0, np.pi / 2], [1.0, 1.0, 0.0])  # facing +y in map
    p_tag = np.array([1.0, 7.0, 1.2])  # 6 m ahead
    cov = range_covariance(T_map_base, p_tag, 0.1)
    expected = np.zeros((6, 6))
    expected[0, 0] = (6.0 * 0.1) ** 2
    np.testing.assert_allclose(cov, expected, atol=1e-12)
