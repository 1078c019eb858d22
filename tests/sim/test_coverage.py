"""route_coverage and ``tagloc world coverage``: where the route runs with no tag in view.

Oracles: the simulator's own odometer (``Drive.distance_m``) for the distance driven, and
:func:`simulate_observations` queried afresh at single stamps for "no tag in view".
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest

from cli_runner import run_tagloc
from tagloc.errors import SimulationError
from tagloc.sim import (
    ObservationConfig,
    World,
    load_default_world,
    simulate_drive,
    simulate_observations,
)
from tagloc.sim.coverage import RouteCoverage, gaps_csv, route_coverage
from tagloc.sim.world import Tag

S = 1_000_000_000


def _one_lap(world: World) -> World:
    return world.model_copy(update={"route": world.route.model_copy(update={"repeat": 1})})


@pytest.fixture(scope="module")
def world() -> World:
    return load_default_world()


@pytest.fixture(scope="module")
def report(world: World) -> RouteCoverage:
    return route_coverage(world, stride=1, min_distance_m=0.0, min_rotation_deg=0.0)


def test_distance_driven_matches_the_simulators_odometer(
    world: World, report: RouteCoverage
) -> None:
    drive = simulate_drive(_one_lap(world), seed=0)
    true_length = float(drive.distance_m[-1] - drive.distance_m[0])
    # the route dwells at both ends, so the checked frames span the whole path
    assert report.length_m == pytest.approx(true_length, abs=1e-9)
    assert 0.5 < report.covered_fraction < 1.0


def test_inside_every_gap_no_tag_is_in_view(world: World, report: RouteCoverage) -> None:
    drive = simulate_drive(_one_lap(world), seed=0)
    wide = [g for g in report.gaps if g.end_s - g.start_s >= 0.5]
    assert len(wide) >= 10
    cams = drive.camera_stamps_ns
    mid = cams[np.searchsorted(cams, [drive.t0_ns + (g.start_s + g.end_s) / 2 * S for g in wide])]
    frames = list(simulate_observations(drive, ObservationConfig(), stamps_ns=mid))
    assert all(not f.truth for f in frames)
    # and at a gap's ends tags are in view: the ones it names
    for g in wide:
        for t_s, ids in ((g.start_s, g.tags_before), (g.end_s, g.tags_after)):
            stamp = np.array([drive.t0_ns + round(t_s * S)])
            (frame,) = simulate_observations(drive, ObservationConfig(), stamps_ns=stamp)
            assert tuple(sorted({s.tag_id for s in frame.truth})) == ids


def test_gaps_are_in_route_order_and_filtered_by_size(world: World, report: RouteCoverage) -> None:
    starts = [g.start_s for g in report.gaps]
    assert starts == sorted(starts)
    big = route_coverage(world, stride=1, min_distance_m=2.0, min_rotation_deg=90.0)
    expected = [g for g in report.gaps if g.distance_m >= 2.0 or g.rotation_deg >= 90.0]
    assert [g.start_s for g in big.gaps] == [g.start_s for g in expected]
    assert big.longest() == max(expected, key=lambda g: g.distance_m)


def test_a_world_without_tags_is_one_gap_the_length_of_the_route(world: World) -> None:
    report = route_coverage(world.model_copy(update={"tags": []}))
    assert report.covered_fraction == 0.0
    (gap,) = report.gaps
    assert gap.tags_before == gap.tags_after == ()
    assert gap.distance_m == pytest.approx(report.length_m)


def test_a_tag_on_the_cab_wall_splits_the_turn_in_the_cab(
    world: World, report: RouteCoverage
) -> None:
    def cab_turn(r: RouteCoverage) -> float:  # the robot turns around in the cab at 166-176 s
        return max(g.rotation_deg for g in r.gaps if g.end_s > 166.0 and g.start_s < 176.0)

    assert cab_turn(report) > 120.0  # measured 138 deg with only the back wall's tag in view
    tag = Tag.model_validate(
        {"id": 42, "size": 0.16, "frame": "elevator_cab",
         "wall": {"x": -0.4, "y": -1.0, "yaw_deg": 90, "height": 1.0}}
    )  # fmt: skip
    more = route_coverage(
        world.model_copy(update={"tags": [*world.tags, tag]}),
        stride=1, min_distance_m=0, min_rotation_deg=0,
    )  # fmt: skip
    assert cab_turn(more) < 80.0  # measured 64 deg

    def elsewhere(r: RouteCoverage) -> list[float]:  # the new tag is seen only in the cab
        return [g.start_s for g in r.gaps if g.end_s < 160.0 or g.start_s > 180.0]

    assert elsewhere(more) == elsewhere(report)


def test_csv_holds_every_gap(report: RouteCoverage) -> None:
    rows = list(csv.DictReader(io.StringIO(gaps_csv(report))))
    assert len(rows) == len(report.gaps)
    for row, g in zip(rows, report.gaps, strict=True):
        assert float(row["end_x"]) == pytest.approx(g.end_xy[0], abs=5e-4)
        assert float(row["rotation_deg"]) == pytest.approx(g.rotation_deg, abs=0.05)
        assert tuple(int(i) for i in row["tags_after"].split()) == g.tags_after


def test_bad_arguments_raise(world: World) -> None:
    with pytest.raises(SimulationError, match="laps >= 1"):
        route_coverage(world, laps=0)


def test_cli_prints_the_gaps_and_writes_the_csv(tmp_path: Path) -> None:
    out = tmp_path / "gaps.csv"
    result = run_tagloc("world", "coverage", "--min-distance", "2", "--min-rotation", "90",
                        "--csv", str(out))  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "a tag in view over" in result.stdout
    rows = list(csv.DictReader(out.open()))
    expected = route_coverage(load_default_world(), min_distance_m=2.0, min_rotation_deg=90.0)
    assert len(rows) == len(expected.gaps) >= 3
    assert [float(r["distance_m"]) for r in rows] == pytest.approx(
        [g.distance_m for g in expected.gaps], abs=1e-3
    )


def test_cli_bad_limit_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "gaps.csv"
    result = run_tagloc("world", "coverage", "--max-range", "-1", "--csv", str(out))
    assert result.returncode == 1
    assert len(result.stderr.strip().splitlines()) == 1 and "--max-range" in result.stderr
    assert not out.exists()
