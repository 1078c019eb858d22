"""Measured anchors: priors with the survey's sigmas, not rigid constraints.

Oracle: the simulator's true tag poses. A second anchor measured 20 cm off: declared with a tight
sigma (the default) the map puts the tag where the bad measurement says; declared with an honest
0.5 m the survey's own observations place it (measured: 0.001 mm from the bad pose with the
default sigma; 4.0 cm from the truth with the honest one), and its marginal sigma (14 cm)
shrinks below the declared one (87 cm, the norm of 0.5 m per axis).
"""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.geometry import SE3
from tagloc.mapping import build_tag_map
from tagloc.mapping.anchors import Anchor
from tagloc.sim import ObservationConfig, World, load_default_world, simulate_drive
from tagloc.sim.survey import sim_build_config, survey_from_drive
from tagloc.tags.tagmap import TagEntry, TagMap, TagMapError


def _short_world() -> World:
    """The office's corridor and room_a (about 40 s of driving)."""
    world = load_default_world()
    route = world.route.model_copy(update={"waypoints": world.route.waypoints[:7], "repeat": 1})
    return world.model_copy(update={"route": route})


def test_a_badly_measured_anchor_with_an_honest_sigma_is_corrected() -> None:
    drive = simulate_drive(_short_world(), seed=1)
    observation = ObservationConfig(seed=2)
    survey = survey_from_drive(drive, observation, camera_stride=3)
    config = sim_build_config(drive, observation)
    world = drive.world
    good, bad = 1, 13  # corridor, room_a's far wall
    T_good = world.T_map_tag(world.find_tag(good))
    T_bad_true = world.T_map_tag(world.find_tag(bad))
    T_bad = SE3(T_bad_true.rotation, T_bad_true.translation + np.array([0.2, 0.0, 0.0]))
    rigid, _ = build_tag_map(survey, {good: T_good, bad: T_bad}, config)
    honest, report = build_tag_map(survey, {good: T_good, bad: Anchor(T_bad, 0.5, 10.0)}, config)
    at_rigid = rigid.T_frame_tag(bad).translation
    at_honest = honest.T_frame_tag(bad).translation
    assert np.linalg.norm(at_rigid - T_bad.translation) < 2e-3  # held where measured
    assert np.linalg.norm(at_honest - T_bad_true.translation) < 0.06
    qa = {t.tag_id: t for t in report.tags}
    assert qa[bad].anchor and qa[bad].position_sigma_m < 0.5 * np.sqrt(3)
    assert [e.id for e in honest.anchors] == [good, bad]


def test_anchor_sigma_in_tags_yaml() -> None:
    entry = TagEntry.from_pose(
        7, SE3.identity(), 0.16, anchor=True,
        anchor_sigma={"position_m": 0.003, "rotation_deg": 0.5},
    )  # fmt: skip
    text = TagMap.from_entries([entry]).to_yaml_text()
    assert "anchor_sigma: {position_m: 0.003, rotation_deg: 0.5}" in text
    back = TagMap.from_yaml_text(text)
    assert back.to_yaml_text() == text
    assert back.tags[0].anchor_sigma is not None
    assert back.tags[0].anchor_sigma.rotation_deg == 0.5
    no_anchor = text.replace("    anchor: true\n", "")
    with pytest.raises(
        TagMapError, match=r"x.yaml: tags\[0\] \(id 7\): anchor_sigma: only an anchor"
    ):
        TagMap.from_yaml_text(no_anchor, "x.yaml")
    with pytest.raises(TagMapError, match=r"anchor_sigma\.position_m"):
        TagMap.from_yaml_text(text.replace("position_m: 0.003", "position_m: -1"), "x.yaml")


def test_anchor_sigmas_default_to_the_configuration() -> None:
    from tagloc.mapping import MapBuildConfig

    config = MapBuildConfig(anchor_sigma_m=0.01, anchor_sigma_rad=0.02)
    np.testing.assert_allclose(Anchor(SE3.identity()).sigmas(config), [0.01] * 3 + [0.02] * 3)
    sig = Anchor(SE3.identity(), 0.002, 1.0).sigmas(config)
    np.testing.assert_allclose(sig, [0.002] * 3 + [np.radians(1.0)] * 3)
    with pytest.raises(ValueError, match="sigma_position_m"):
        Anchor(SE3.identity(), -1.0)
