"""Checks of a tag map's floors that are warnings, not errors (``tagloc map check``).

Loading a map already refuses a tag in an undeclared frame, a ``floor`` missing from the map's
``floors`` table and a ``floor`` on a tag of a moving frame. These are kept as warnings, since a
map can be right with them:

- a tag whose z does not lie on its floor: below the floor's height by more than
  :data:`Z_TOLERANCE_M`, or at or above the next floor's height less that tolerance (on the top
  floor: more than :data:`TOP_FLOOR_SPAN_M` above it);
- a floor of the table without tags (the robot cannot tell it from the others by its tags).
"""

from __future__ import annotations

from tagloc.tags.tagmap import TagMap

__all__ = ["TOP_FLOOR_SPAN_M", "Z_TOLERANCE_M", "floor_warnings"]

#: How far (m) a tag may lie below its floor, or reach up to the next one.
Z_TOLERANCE_M = 0.3
#: Highest a tag may be above the top floor, m.
TOP_FLOOR_SPAN_M = 5.0


def floor_warnings(tag_map: TagMap) -> list[str]:
    """One line per warning (module docstring), ``tags[k] (id N): ...`` or ``floors.NAME: ...``;
    empty for a map without a ``floors`` table."""
    if tag_map.floors is None:
        return []
    heights = sorted(tag_map.floors.values())
    out: list[str] = []
    for k, tag in enumerate(tag_map.tags):
        if tag.floor is None:
            continue
        h = tag_map.floors[tag.floor]
        above = [v for v in heights if v > h]
        top = (above[0] - Z_TOLERANCE_M) if above else h + TOP_FLOOR_SPAN_M
        z = tag.position[2]
        if not h - Z_TOLERANCE_M <= z < top:
            out.append(
                f"tags[{k}] (id {tag.id}): floor: z {z:.2f} m is not on floor {tag.floor} "
                f"({h:g} m; expected {h - Z_TOLERANCE_M:g} m <= z < {top:g} m)"
            )
    used = {tag.floor for tag in tag_map.tags}
    for name in tag_map.floors:
        if name not in used:
            out.append(f"floors.{name}: no tag is on this floor (it cannot be told by its tags)")
    return out
