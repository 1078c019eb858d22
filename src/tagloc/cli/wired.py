"""A node to build and the stream that feeds it: what ``tagloc localize`` wires and runs."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

    from tagloc.localize.config import LocalizerConfig
    from tagloc.localize.driver import NodeFactory
    from tagloc.messages import Message
    from tagloc.tags import TagMap


@dataclass(frozen=True, slots=True)
class WiredNode:
    """The node to build (its configuration fixed) and the stream that feeds it."""

    config: LocalizerConfig
    node: NodeFactory
    stream: Iterable[tuple[str, Message]]
    name: str
    #: What the camera check found (before any fix), for summary.json.
    camera_check: dict[str, object] | None = None
    #: The map and premap the node localizes against (for the view).
    tag_map: TagMap | None = None
    premap: np.ndarray | None = None
    #: Inputs left out before the node, by reason (counted in summary.json's ``skipped``).
    skipped: dict[str, int] = field(default_factory=dict)
    #: The rig's cameras by name (empty: one camera on the node's topics); the extrinsic check
    #: judges the first.
    cameras: tuple[str, ...] = ()
