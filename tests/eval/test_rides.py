"""The timeline of a run's elevator rides and the drive picture per floor, against the
simulator's ride schedule and truth (a flat world's picture keeps its one panel).

The run: the ``elevator`` scenario's first 155 s (two rides, 0 -> 1 and 1 -> 2, the building
publishing its doors), without lidar. The oracle is the simulator's schedule
(:class:`~tagloc.sim.ride.RideTimes`: the robot at the landing, in the cab, the cab's departure
and arrival, the robot back at the landing), the shaft's dwell and door times, and its truth.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from tagloc.eval.plots import world_figure
from tagloc.eval.report import write_report
from tagloc.eval.report_plots import pyplot
from tagloc.eval.rides import RideRow, ride_rows
from tagloc.eval.scenarios import localize_scenario
from tagloc.geometry import SE3
from tagloc.io import write_tum
from tagloc.localize.events import EventKind
from tagloc.localize.run import LocalizationRun
from tagloc.sim.ride import RidePlan
from tagloc.sim.route import Waypoint
from tagloc.sim.scenarios import Scenario, build_scenario
from tagloc.sim.world import load_builtin_world, load_default_world
from tagloc.supervise import CabState

S = 1_000_000_000
TOL_S = 0.02  # odometry rows every 10 ms


@pytest.fixture(scope="module")
def ride_run() -> tuple[Scenario, LocalizationRun]:
    scenario = build_scenario("elevator", seed=0, duration_s=155.0)
    return scenario, localize_scenario(scenario, lidar=False)


def _within(value: float, low: float, high: float) -> bool:
    return low - TOL_S <= value <= high + TOL_S


def test_one_row_per_ride_with_the_schedules_floors_and_times(
    ride_run: tuple[Scenario, LocalizationRun],
) -> None:
    scenario, run = ride_run
    plan = scenario.drive.plan
    assert isinstance(plan, RidePlan)
    shaft = scenario.world.elevators[0]
    offset_s = (run.stamps_ns[0] - scenario.drive.t0_ns) / S  # row times -> route times
    end_s = (run.stamps_ns[-1] - scenario.drive.t0_ns) / S
    schedule = [r for r in plan.rides if r.exit_s < end_s]
    rows = ride_rows(run)
    assert len(schedule) == 2 and len(rows) == 2
    for row, ride in zip(rows, schedule, strict=True):
        b, c, o, x = (v + offset_s for v in (row.boarding_s, row.doors_closed_s,
                                              row.doors_open_s, row.exit_s))  # fmt: skip
        assert (row.from_floor, row.to_floor) == (ride.from_floor, ride.to_floor)
        # boarding: after reaching the landing, before standing in the cab's centre
        assert _within(b, ride.call_s, ride.enter_s), (b, ride)
        # doors closed (door topic): while the door closes, dwell_s after the robot walked in
        assert _within(c, ride.enter_s + shaft.dwell_s, ride.depart_s), (c, ride)
        # doors open: while the door opens on arrival
        assert _within(o, ride.arrive_s, ride.arrive_s + shaft.door_open_s), (o, ride)
        # out: once the door is open, before the robot is back at the landing
        assert _within(x, ride.arrive_s + shaft.door_open_s, ride.exit_s), (x, ride)
        # declared: the new floor, after the doors opened, at the floor_changed event
        assert row.declared_floor == ride.to_floor and row.floor_right
        changed = [(e.stamp_ns - run.stamps_ns[0]) / S for e in run.events
                   if e.kind is EventKind.FLOOR_CHANGED and f"-> {ride.to_floor}:" in e.detail
                   and e.stamp_ns >= run.stamps_ns[0] + row.doors_open_s * S]  # fmt: skip
        assert changed and abs(changed[0] - row.declared_s) <= 1e-6
        assert _within(row.declared_s + offset_s, o, ride.exit_s)


def test_the_rows_errors_against_the_simulators_truth(
    ride_run: tuple[Scenario, LocalizationRun],
) -> None:
    scenario, run = ride_run
    rows = ride_rows(run)
    for row in rows:
        # in the cab: the published pose relative to the cab vs T_map_cab(t)^-1 T_map_base(t)
        lo, hi = (run.stamps_ns[0] + round(t * S) for t in (row.doors_closed_s, row.doors_open_s))
        inside = [c for c in run.cab if lo <= c.stamp_ns < hi and c.state is CabState.IN_CAB]
        assert len(inside) > 300  # 100 Hz over the trip
        err = []
        for c in inside:
            T_map_base = scenario.drive.ground_truth_at(np.array([c.stamp_ns])).T_map_base
            T_cab_base = scenario.drive.T_map_cab(c.stamp_ns).inverse() @ T_map_base
            err.append(np.linalg.norm(T_cab_base.translation[0] - c.T_cab_base.translation))
        assert row.cab_rms_m == pytest.approx(float(np.sqrt(np.mean(np.square(err)))), rel=1e-9)
        assert row.cab_rms_m <= 0.02
        assert 0.0 <= row.exit_error_m <= 0.5
    # the worst exit is the ride check's
    worst = next(v for name, v, *_ in run.metadata["ride_checks"] if name.startswith("exits: pose"))  # type: ignore[attr-defined]
    assert max(r.exit_error_m for r in rows) == pytest.approx(worst, rel=1e-12)


def test_summary_json_and_the_report_hold_the_timeline(
    ride_run: tuple[Scenario, LocalizationRun], tmp_path: Path
) -> None:
    _, run = ride_run
    write_report(run, tmp_path, write_trajectory=write_tum)
    data = json.loads((tmp_path / "summary.json").read_text())
    rows = ride_rows(run)
    assert [RideRow(**r) for r in data["rides"]] == rows
    page = (tmp_path / "report.html").read_text()
    section = page[page.index("<h2>Rides</h2>"):]
    section = section[: section.index("</table>")]
    assert section.count("<tr") == 1 + len(rows)
    for r in rows:
        assert f"{r.from_floor} -&gt; {r.to_floor}" in section


def test_a_run_without_truth_keeps_the_nodes_times(
    ride_run: tuple[Scenario, LocalizationRun],
) -> None:
    """Rows from the run's moves and floors alone (a run read back without truth): the same
    times and declared floors, the truth's fields NaN / None."""
    _, run = ride_run
    bare = dataclasses.replace(run, metadata={k: v for k, v in run.metadata.items()
                                              if k != "rides"})  # fmt: skip
    judged, rows = ride_rows(run), ride_rows(bare)
    assert len(rows) == len(judged)
    for row, ref in zip(rows, judged, strict=True):
        assert row.from_floor is None and row.floor_right is None
        assert math.isnan(row.exit_error_m) and math.isnan(row.cab_rms_m)
        assert (row.boarding_s, row.doors_closed_s, row.doors_open_s, row.exit_s,
                row.declared_floor, row.declared_s) == (ref.boarding_s, ref.doors_closed_s,
                ref.doors_open_s, ref.exit_s, ref.declared_floor, ref.declared_s)  # fmt: skip


def _line(ax: object, label: str) -> np.ndarray:
    """The points of the line labelled ``label`` on ``ax`` (NaN: not drawn), (N, 2)."""
    (line,) = [ln for ln in ax.get_lines() if ln.get_label() == label]  # type: ignore[attr-defined]
    return np.asarray(line.get_xydata(), dtype=float)


@pytest.mark.parametrize("rows", [9000, None])  # 90 s: floors 0 and 1; 155 s: 0, 1 and 2
def test_the_drive_picture_has_one_panel_per_floor_visited(
    ride_run: tuple[Scenario, LocalizationRun], rows: int | None
) -> None:
    scenario, run = ride_run
    plan = scenario.drive.plan
    assert isinstance(plan, RidePlan) and run.T_map_base_truth is not None
    keep = slice(0, rows)
    truth, fused = run.T_map_base_truth[keep], run.T_map_base[keep]
    t_s = (np.asarray(run.stamps_ns)[keep] - scenario.drive.t0_ns) / S
    on = np.array(plan.floor_at(t_s), dtype=object)  # the schedule's floor (None: riding)
    fig = world_figure(scenario.world, {"ground truth": truth, "fused": fused})
    try:
        axes = [ax for ax in fig.axes if ax.get_title()]
        visited = [f for f in ("0", "1", "2") if np.any(on == f)]
        assert len(visited) == (2 if rows else 3)
        assert [ax.get_title() for ax in axes] == [f"floor {f}" for f in visited]
        xy_truth = np.asarray(truth.translation)[:, :2]
        for ax, floor in zip(axes, visited, strict=True):
            line = _line(ax, "ground truth")
            drawn = np.isfinite(line).all(axis=1)
            # every sample the schedule puts on this floor is drawn here, where it is, and none
            # of the other floors' (samples at a trip's ends, z within 5 cm of the floor, may be)
            assert drawn[on == floor].all()
            np.testing.assert_array_equal(line[drawn], xy_truth[drawn])
            assert not drawn[np.array([f not in (floor, None) for f in on])].any()
            np.testing.assert_array_equal(np.isfinite(_line(ax, "fused")).all(axis=1), drawn)
            ids = {t.get_text() for t in ax.texts}
            floor_tags = next(f for f in scenario.world.floors if f.name == floor).tags
            assert {str(t.id) for t in floor_tags} <= ids
            other_tags = {str(t.id) for f in scenario.world.floors if f.name != floor
                          for t in f.tags}  # fmt: skip
            assert not ids & other_tags
    finally:
        pyplot().close(fig)


def test_a_flat_world_keeps_its_one_panel() -> None:
    world = load_default_world()
    xy = np.array([[1.0, 1.0, 0.0], [2.0, 1.5, 0.0], [3.0, 2.0, 0.0]])
    path = SE3.from_rotvec(np.zeros((3, 3)), xy)
    fig = world_figure(world, {"ground truth": path})
    try:
        assert len(fig.axes) == 1 and fig.axes[0].get_title() == world.name
        np.testing.assert_array_equal(_line(fig.axes[0], "ground truth"), xy[:, :2])
    finally:
        pyplot().close(fig)


def test_a_floor_the_cab_only_passes_has_no_panel() -> None:
    """A ride from floor 0 to floor 2 passes floor 1 (its z crosses 3.5 m in the moving cab):
    the truth's picture has the panels of floors 0 and 2, where the schedule puts it."""
    world = load_builtin_world("tower")
    waypoints = (Waypoint(at="f0_lobby"),
                 Waypoint.model_validate({"ride": {"elevator": "lift", "to": "2"}}),
                 Waypoint(at="f2_lobby"))  # fmt: skip
    route = world.route.model_copy(update={"waypoints": waypoints, "repeat": 1})
    drive = build_scenario("default", world=world.model_copy(update={"route": route})).drive
    assert isinstance(drive.plan, RidePlan)
    on = drive.plan.floor_at((drive.stamps_ns - drive.t0_ns) / S)
    assert "1" not in on and {"0", "2"} <= set(on)
    z = np.asarray(drive.T_map_base.translation)[:, 2]
    assert np.any(np.abs(z - 3.5) < 0.005)  # the cab's samples pass floor 1's height
    fig = world_figure(world, {"ground truth": drive.T_map_base})
    try:
        assert [ax.get_title() for ax in fig.axes] == ["floor 0", "floor 2"]
        for ax, floor in zip(fig.axes, ("0", "2"), strict=True):
            drawn = np.isfinite(_line(ax, "ground truth")).all(axis=1)
            assert drawn[np.array(on, dtype=object) == floor].all()
    finally:
        pyplot().close(fig)
