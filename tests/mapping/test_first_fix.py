"""The first fix of the keyframe initialization against the simulator's truth.

In the built-in ``sparse_building`` the robot meets its one anchor face-on at the start of the
drive; over the first second the wrong IPPE branch of every sighting agrees with the others,
and a rotation voted on those sightings put the whole initial trajectory 9 to 31 deg off
(lidar-aided, seeds 1 to 3), far outside the basin of the optimization (seed 2 ended 27 deg
off, 14.7 m tag RMS). The consensus over 10 m of travel, both branches of each sighting, starts
within 11 mrad on these seeds with the scan-matched odometry. Here tags only (no lidar, fast):
the raw odometry's 0.3 deg/m of yaw bias stays in the 10 m, measured 1.0, 0.8 and 3.5 deg off
(before: 9.3, 24.5 and 28.9 deg). The oracle: the simulated drive's true pose at the first
placed keyframe; tolerance 5 deg.
"""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.mapping.initialize import initialize_keyframes
from tagloc.mapping.observations import collect_observations
from tagloc.sim import ObservationConfig, simulate_drive
from tagloc.sim.survey import sim_build_config, survey_and_anchors
from tagloc.sim.trajectory import se3_from_xy_yaw
from tagloc.sim.world import load_builtin_world
from tagloc.tags.tagmap import DEFAULT_FAMILY


def _first_yaw_error_rad(seed: int) -> float:
    world = load_builtin_world("sparse_building")
    drive = simulate_drive(world, seed=seed)
    observations = ObservationConfig(seed=seed)
    survey, anchors = survey_and_anchors(drive, observations, None, 3, False)
    config = sim_build_config(drive, observations)
    obs = collect_observations(survey, config.pnp_noise, config.max_range_m)
    index = {key: j for j, key in enumerate(obs.tag_keys)}
    M_anchor = {index[(DEFAULT_FAMILY, i)]: T.as_matrix() for i, T in anchors.items()}
    M = initialize_keyframes(obs, M_anchor, config.max_ambiguity_for_init)
    placed = np.flatnonzero(np.isfinite(M[:, 0, 0]))
    truth = drive.ground_truth_at(obs.keyframe_stamps_ns[placed])
    T_true = se3_from_xy_yaw(np.asarray(truth.xy_yaw_map_base)).as_matrix()
    M0, T0 = M[placed[0]], T_true[0]
    R = T0[:3, :3].T @ M0[:3, :3]
    return float(np.arctan2(R[1, 0], R[0, 0]))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_first_fix_on_a_face_on_anchor_is_near_the_true_heading(seed: int) -> None:
    error = _first_yaw_error_rad(seed)
    print(f"seed {seed}: first fix {np.degrees(error):+.2f} deg off")
    assert abs(error) < np.radians(5.0)
