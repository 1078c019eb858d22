"""The blueprints register with dimos through the ``dimos.blueprints`` entry points."""

from __future__ import annotations

from dimos.core.coordination.blueprints import Blueprint
from dimos.robot.external_blueprints import (
    list_external_blueprint_names,
    resolve_external_blueprint_by_name,
)

from tagloc.adapters.dimos.module import TaglocRelocalization


def test_the_blueprints_are_listed_and_the_desk_one_resolves() -> None:
    names = list_external_blueprint_names()
    assert {"tagloc.tagloc-go2", "tagloc.tagloc-go2-lidar", "tagloc.tagloc-desk"} <= set(names)
    desk = resolve_external_blueprint_by_name("tagloc.tagloc-desk")  # what `dimos run` loads
    assert isinstance(desk, Blueprint)
    assert TaglocRelocalization in {atom.module for atom in desk.active_blueprints}
