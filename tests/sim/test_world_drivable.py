"""A world that passes validation can be driven: coverage, a survey map and scenarios never crash
or blow up on it; what cannot be driven fails at validation with one line."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tagloc.errors import ConfigError, SimulationError
from tagloc.mapping import MappingError
from tagloc.sim import World, simulate_drive
from tagloc.sim.coverage import route_coverage
from tagloc.sim.scenarios import build_scenario
from tagloc.sim.survey import build_map_from_drive


def _world(**route: Any) -> dict[str, Any]:
    return {
        "version": 1,
        "name": "small",
        "walls": [{"start": [0, 0], "end": [10, 0]}],
        "tags": [
            {"id": 0, "size": 0.16, "wall": {"x": 5.0, "y": 0.0, "yaw_deg": 90, "height": 0.5}}
        ],
        "checkpoints": [{"name": "a", "x": 2.0, "y": 2.0}, {"name": "b", "x": 8.0, "y": 2.0}],
        "route": {"speed": 0.5, "waypoints": ["a", "b"], **route},
        "robot": {
            "odometry": {"model": "wheel"},
            "odom_rate_hz": 50,
            "camera": {
                "intrinsics": {"fx": 400.0, "fy": 400.0, "cx": 319.5, "cy": 239.5,
                               "width": 640, "height": 480},
                "rate_hz": 10,
                "T_base_cam": {"position": [0.2, 0.0, 0.4], "rpy_deg": [0.0, 0.0, 0.0]},
            },
        },
    }  # fmt: skip


def test_coverage_refuses_laps_past_the_sample_budget() -> None:
    world = World.model_validate(_world())
    with pytest.raises(SimulationError, match=r"^100000 laps: 2 waypoints x repeat 100000 is more"):
        route_coverage(world, laps=100_000)
    with pytest.raises(SimulationError, match=r"^5000 laps: driving the route .* more than 500000"):
        route_coverage(world, laps=5000)


def test_survey_of_a_world_without_tags_is_one_mapping_error() -> None:
    doc = _world()
    doc["tags"] = []
    drive = simulate_drive(World.model_validate(doc), seed=0)
    with pytest.raises(MappingError, match=r"^the simulated drive of world small detects no tag"):
        build_map_from_drive(drive)


@pytest.mark.parametrize("duration_s", [math.nan, math.inf, -1.0, 0.0])
def test_scenario_refuses_a_duration_that_is_not_positive(duration_s: float) -> None:
    with pytest.raises(SimulationError, match=r"^the duration must be a positive number"):
        build_scenario("default", 0, duration_s)


_coordinate = st.floats(-30.0, 30.0, allow_nan=False)
_point = st.tuples(_coordinate, _coordinate).map(list)
_route = st.fixed_dictionaries(
    {
        "waypoints": st.lists(st.one_of(_point, st.sampled_from(["a", "b"])), min_size=2,
                              max_size=6),
        "speed": st.floats(0.2, 5.0),  # slower routes are valid too, only slow to test
        "accel_max": st.floats(0.01, 20.0),
        "yaw_rate_max": st.floats(0.01, 10.0),
        "yaw_accel_max": st.floats(0.01, 100.0),
        "corner_radius": st.floats(0.0, 100.0),
        "dwell": st.floats(0.0, 5.0),
        "repeat": st.integers(1, 3),
    }
)  # fmt: skip


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(route=_route)
def test_every_valid_route_drives_to_finite_poses(route: dict[str, Any]) -> None:
    doc = _world(**route)
    try:
        world = World.model_validate(doc)
    except ValueError as exc:  # the pydantic error of a route refused by validation
        assert "route" in str(exc)
        return
    drive = simulate_drive(world, seed=0)
    assert np.all(np.isfinite(drive.T_map_base.translation))
    assert np.all(np.isfinite(drive.T_odom_base.translation))
    assert np.all(np.diff(drive.stamps_ns) > 0)
    report = route_coverage(world, stride=5)
    assert 0.0 <= report.covered_fraction <= 1.0


def test_validation_errors_of_a_route_are_config_errors() -> None:
    with pytest.raises(ConfigError, match=r"^w\.yaml: route\.waypoints: the route needs at least"):
        World.from_yaml_text(yaml.safe_dump(_world(waypoints=["a", "a"])), "w.yaml")
