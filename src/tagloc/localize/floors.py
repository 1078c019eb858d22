"""Buildings of several floors: the filter works in the current floor's frame.

A floor's frame is ``map`` moved up by the floor's height (the tag map's floor table). The
``map -> odom`` filter (:class:`FloorFilter`, a :class:`~tagloc.localize.filter.MapOdomFilter`)
estimates the correction in the floor's frame: every fix enters it lowered by its floor's height
(a tag's own floor; a lidar fix the current floor's), and everything it gives out (the
estimate, the published correction, poses, the priors the fix sources read) is lifted by the
current floor's height (:class:`FloorFrame`). So the filter's state never jumps between floors:
a change of floor (:mod:`tagloc.supervise.floors`, declared by the node as a
``floor_changed`` event) moves the published ``map -> odom`` by exactly the difference of the
floors' heights, outside the cap and the speed limit, which still bound every other change.

With no floor table nothing is lowered or lifted (:func:`floor_table` is empty and the node
builds the plain filter).
"""

from __future__ import annotations

import dataclasses
import re
from collections import OrderedDict
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from tagloc._types import FloatArray
from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.events import EventKind, FilterEvent
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import CorrectionUpdate, PartialFix, PoseWithCovariance, TagFix
from tagloc.tags import TagMap

__all__ = ["FixWeigher", "FloorFilter", "FloorFrame", "floor_table", "tag_ids_of"]

_TAG_IDS = re.compile(r"tags?:([\d,]+)")
#: Lowered fixes remembered to hand the filter's batch decisions back on the fixes given.
_REMEMBERED = 4096


def tag_ids_of(source: str) -> tuple[int, ...]:
    """The tag ids of a fix source (``tag:17``, ``tags:3,17``, ``tag:3+tag:17``; none for
    ``lidar``)."""
    out: list[int] = []
    for part in _TAG_IDS.findall(source):
        out += [int(i) for i in part.split(",") if i]
    return tuple(out)


def floor_table(tag_map: TagMap, family: str) -> tuple[dict[str, float], dict[int, str]]:
    """The floors' heights (name -> m in ``map``) and the floor of each map-frame tag of
    ``family`` that has one (id -> name); both empty for a map without floors."""
    heights = {str(k): float(v) for k, v in (tag_map.floors or {}).items()}
    tags = {t.id: t.floor for t in tag_map if t.family == family and t.floor is not None}
    return heights, {k: str(v) for k, v in tags.items() if v is not None}


@dataclass(slots=True)
class FloorFrame:
    """The current floor's height and each tag's floor (module docstring)."""

    heights_m: dict[str, float]
    tag_floor: dict[int, str]
    #: The current (last known) floor's height in ``map``, m.
    height_m: float = 0.0

    def floor_of(self, source: str) -> str | None:
        """The floor of a fix source's first tag (None: no tag, or a tag without floor)."""
        ids = tag_ids_of(source)
        return self.tag_floor.get(ids[0]) if ids else None

    def lift(self, T_floor_x: SE3, height_m: float | None = None) -> SE3:
        """``T_map_x`` of a pose in the floor's frame (the current floor's by default)."""
        h = self.height_m if height_m is None else height_m
        if h == 0.0:
            return T_floor_x
        up = T_floor_x.translation + np.array([0.0, 0.0, h])
        return SE3(rotation=T_floor_x.rotation, translation=up)

    def lower_height(self, source: str) -> float:
        """The height a fix of ``source`` is lowered by."""
        floor = self.floor_of(source)
        return self.height_m if floor is None else self.heights_m[floor]


class FixWeigher(Protocol):
    """Reweighs the fixes for a while (the landing's after a ride,
    :class:`~tagloc.localize.ride_anchor.LandingSettle`); dropped once ``done``."""

    done: bool

    def weigh(self, fix: TagFix, odometer_m: float) -> TagFix: ...


class FloorFilter(MapOdomFilter):
    """The ``map -> odom`` filter in the current floor's frame (module docstring).

    Parameters
    ----------
    base : MapOdomFilter
        The filter's estimator and policy (as :meth:`MapOdomFilter.from_config` builds them).
    floors : FloorFrame
        Shared with the node, which sets ``floors.height_m`` on a floor change.

    Attributes
    ----------
    weigher : FixWeigher or None
        Set by the node after a ride: every fix passes through it (before it is lowered) until
        it is done.
    """

    def __init__(self, base: MapOdomFilter, floors: FloorFrame) -> None:
        super().__init__(base.estimator, base.policy)
        self.floors = floors
        self.weigher: FixWeigher | None = None
        # id(lowered) -> (lowered, the fix given): the lowered one kept alive, so ids stay unique
        self._given: OrderedDict[int, tuple[TagFix, TagFix]] = OrderedDict()

    @classmethod
    def build(
        cls, config: LocalizerConfig, buffer: TransformBuffer, floors: FloorFrame
    ) -> FloorFilter:
        """The configured filter (:meth:`MapOdomFilter.from_config`) in ``floors``' frame."""
        return cls(MapOdomFilter.from_config(config, buffer), floors)

    # ----- outputs, lifted -------------------------------------------------------------------
    @property
    def T_map_odom(self) -> SE3:
        return self.floors.lift(super().T_map_odom)

    @property
    def corrections(self) -> tuple[CorrectionUpdate, ...]:
        lift = self.floors.lift
        return tuple(CorrectionUpdate(c.stamp_ns, lift(c.T_map_odom)) for c in super().corrections)

    @property
    def last_batch(self) -> tuple[tuple[TagFix, EventKind], ...]:
        return tuple((self._original(f), k) for f, k in super().last_batch)

    def _original(self, fix: TagFix) -> TagFix:
        given = self._given.get(id(fix))
        return given[1] if given is not None and given[0] is fix else fix

    def correction_at(self, stamp_ns: int) -> SE3:
        return self.floors.lift(super().correction_at(stamp_ns))

    def pose_at(self, stamp_ns: int, *, published: bool = False) -> PoseWithCovariance:
        pose = super().pose_at(stamp_ns, published=published)
        return dataclasses.replace(pose, T_map_base=self.floors.lift(pose.T_map_base))

    def T_map_base_at(self, stamp_ns: int) -> SE3:
        return self.floors.lift(super().T_map_base_at(stamp_ns))

    # ----- inputs, lowered -------------------------------------------------------------------
    def initialize(self, stamp_ns: int, T_map_odom: SE3, cov: FloatArray) -> FilterEvent:
        return super().initialize(stamp_ns, self.floors.lift(T_map_odom, -self.floors.height_m),
                                  cov)  # fmt: skip

    def update(self, fix: TagFix) -> FilterEvent:
        given, weigher = fix, self.weigher
        if weigher is not None:
            fix = weigher.weigh(fix, self.estimator.odometer_m)
            if weigher.done:
                self.weigher = None
        h = self.floors.lower_height(fix.source)
        if h == 0.0 and fix is given:
            return super().update(fix)
        lowered = (
            fix
            if h == 0.0
            else dataclasses.replace(fix, T_map_base=self.floors.lift(fix.T_map_base, -h))
        )
        self._given[id(lowered)] = (lowered, given)
        while len(self._given) > _REMEMBERED:
            self._given.popitem(last=False)
        return super().update(lowered)

    def update_partial(self, fix: PartialFix) -> FilterEvent:
        h = self.floors.lower_height(fix.source)
        if h == 0.0:
            return super().update_partial(fix)
        return super().update_partial(
            dataclasses.replace(fix, T_map_base=self.floors.lift(fix.T_map_base, -h))
        )
