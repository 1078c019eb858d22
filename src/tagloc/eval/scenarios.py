"""Running the localizer on a simulated scenario (:mod:`tagloc.sim.scenarios` builds its stream).

:func:`run_scenario` builds a scenario and localizes it; :func:`localize_scenario` localizes a
built one through the driver (:func:`tagloc.localize.driver.record_run`) into a
:class:`~tagloc.localize.run.LocalizationRun` with the scenario's facts in its ``metadata``
(:func:`scenario_metadata`). :func:`scenario_config` is the scenarios' filter configuration and
:func:`calibrated_config` gives the tag sensor the simulated detector's pixel noise.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial

import numpy as np
import numpy.typing as npt

from tagloc.errors import SimulationError
from tagloc.eval.elevator import RideTruth, cab_truth, elevator_checks
from tagloc.eval.rides import ride_timeline, rows_to_metadata
from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.driver import record_run
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import OutputSink
from tagloc.localize.run import LocalizationRun
from tagloc.sim.scenario import Scenario, scenario_premap
from tagloc.sim.scenario_source import ScenarioSource
from tagloc.sim.scenarios import SCENARIOS, build_scenario
from tagloc.tags.covariance import NoiseModel
from tagloc.units import S_NS

__all__ = [
    "calibrated_config",
    "localize_scenario",
    "ride_truth",
    "run_scenario",
    "scenario_config",
    "scenario_metadata",
]



def run_scenario(
    name: str,
    seed: int = 0,
    duration_s: float | None = None,
    *,
    config: LocalizerConfig | None = None,
    sinks: Sequence[OutputSink] = (),
    lidar: bool | None = None,
) -> LocalizationRun:
    """Simulate scenario ``name`` (:func:`~tagloc.sim.scenarios.build_scenario`) and localize
    it against the surveyed tag map.

    Parameters
    ----------
    name : str
        A key of :data:`~tagloc.sim.scenarios.SCENARIOS`.
    seed : int
        Odometry and observation seed.
    duration_s : float, optional
        Only the first ``duration_s`` s of the ~700 s route.
    config : LocalizerConfig, optional
        The node's configuration (default: :func:`scenario_config`).
    sinks : sequence of OutputSink
        More sinks for the node's outputs, as they happen (beside the run's recorder).
    lidar : bool, optional
        Use the lidar (the node gets the truth premap,
        :func:`~tagloc.sim.scenarios.scenario_premap`); default: when the world's robot has one.
        ``False`` sets ``lidar.enabled: false`` (tags alone).

    Returns
    -------
    LocalizationRun
        With ground truth, ``kidnaps_ns`` and ``metadata`` (scenario, seed, description,
        distance travelled, glints injected).
    """
    scenario = build_scenario(name, seed, duration_s)
    return localize_scenario(scenario, config, sinks=sinks, lidar=lidar)


def localize_scenario(
    scenario: Scenario,
    config: LocalizerConfig | None = None,
    source: ScenarioSource | None = None,
    sinks: Sequence[OutputSink] = (),
    lidar: bool | None = None,
    premap: npt.NDArray[np.float64] | None = None,
) -> LocalizationRun:
    """Localize a built scenario (see :func:`run_scenario`) through the message stream.

    ``source``: the scenario's stream if already built (it does not depend on
    ``scenario.tag_map``, so runs of one drive against different maps can share it);
    ``sinks``: more sinks for the node's outputs as they happen. Unless the configuration sets
    ``tags.noise``, the tag sensor's ``sigma_px`` is the simulated detector's (as one calibrates
    it on a real detector's corners). ``lidar``: as :func:`run_scenario`'s; ``premap``: the
    ``(N, 3)`` points in ``map`` the lidar registers against (default: the world's true premap,
    :func:`~tagloc.sim.scenarios.scenario_premap`; a survey's premap to localize against a built
    map).

    Raises
    ------
    SimulationError
        If ``lidar`` is True and the world's robot has no lidar.
    """
    has_lidar = scenario.world.robot.lidar is not None
    if lidar and not has_lidar:
        raise SimulationError(f"scenario {scenario.name}: the world's robot has no lidar")
    use_lidar = has_lidar if lidar is None else lidar
    if source is None:
        source = ScenarioSource(scenario, lidar=use_lidar)
    elif source.scenario.drive is not scenario.drive:
        raise ValueError("localize_scenario: the source was built from another drive")
    config = calibrated_config(scenario, config if config is not None else scenario_config())
    if not use_lidar:
        config = config.model_copy(
            update={"lidar": config.lidar.model_copy(update={"enabled": False})}
        )
    points = (scenario_premap(scenario) if premap is None else premap) if use_lidar else None
    node = partial(
        LocalizerNode, scenario.tag_map, config, frame_truth=source.frame_truth, premap=points
    )
    run = record_run(node, source, name=f"scenario:{scenario.name}", sinks=sinks)
    run.kidnaps_ns = list(scenario.kidnaps_ns)
    run.metadata.update(scenario_metadata(scenario, source))
    run.metadata["lidar_used"] = use_lidar
    if run.cab or (run.cab_moves and scenario.world.has_floors):
        truth = ride_truth(scenario)
        run.T_cab_base_truth = cab_truth(run, truth)  # the cab's reliability opportunities
        if run.cab_moves and scenario.world.has_floors:  # rides: their checks
            run.metadata["ride_checks"] = [list(c) for c in elevator_checks(run, truth)]
            run.metadata["rides"] = rows_to_metadata(ride_timeline(run, truth))
    return run


def ride_truth(scenario: Scenario) -> RideTruth:
    """The simulator's truth of a scenario's rides (:class:`~tagloc.eval.elevator.RideTruth`)."""
    drive, world = scenario.drive, scenario.world
    shaft_of = {s.frame: s.name for s in world.shafts()}

    def T_cab_base(cab_frame: str, stamps_ns: np.ndarray) -> SE3:
        T_map_base = drive.ground_truth_at(stamps_ns).T_map_base
        T_map_cab = SE3.stack([drive.T_map_cab(int(t), shaft_of[cab_frame]) for t in stamps_ns])
        return T_map_cab.inverse() @ T_map_base

    def floor_at(stamps_ns: np.ndarray) -> list[str | None]:
        return [drive.floor_at(int(t)) for t in stamps_ns]

    tag_floor = {t.id: floor for t, floor in world.all_tags() if floor is not None}
    return RideTruth(T_cab_base, floor_at, tag_floor)


def calibrated_config(scenario: Scenario, config: LocalizerConfig) -> LocalizerConfig:
    """``config`` with the tag sensor's ``sigma_px`` set to the simulated detector's, unless
    the configuration sets ``tags.noise`` itself."""
    if "noise" in config.tags.model_fields_set:
        return config
    noise = NoiseModel(sigma_px=max(scenario.observation.pixel_sigma_px, 0.05))
    tags = config.tags.model_copy(update={"noise": noise})
    return config.model_copy(update={"tags": tags})


def scenario_config() -> LocalizerConfig:
    """The filter configuration of the scenarios: defaults, planar (the simulated robot walks a
    flat floor, so z, roll and pitch of ``T_map_odom`` stay 0 and tag fixes' poorer z, roll and
    pitch are not let into the estimate)."""
    return LocalizerConfig.model_validate({"filter": {"planar": True}})


def scenario_metadata(scenario: Scenario, source: ScenarioSource) -> dict[str, object]:
    """Facts of a scenario for the run's ``metadata``."""
    glints = source.glints_injected  # counted as the stream was read
    return {
        "scenario": scenario.name, "seed": scenario.drive.seed,
        "description": SCENARIOS[scenario.name].description,
        "distance_m": float(scenario.drive.distance_m[-1] - scenario.drive.distance_m[0]),
        "duration_s": float(scenario.drive.stamps_ns[-1] - scenario.drive.stamps_ns[0]) / S_NS,
        "n_camera_frames": source.n_frames, "glints_injected": int(glints),
        "world": scenario.world.name, "faults": [f.describe() for f in scenario.faults],
        "lidar": _lidar_summary(scenario), "people": len(scenario.people),
    }  # fmt: skip


def _lidar_summary(scenario: Scenario) -> str | None:
    lidar = scenario.world.robot.lidar
    if lidar is None:
        return None
    low, high = lidar.vertical_fov_deg
    return (
        f"{lidar.rings} rings x {lidar.columns} columns, {low:g} to {high:g} deg, "
        f"{lidar.horizontal_fov_deg:g} deg, {lidar.rate_hz:g} Hz"
    )
