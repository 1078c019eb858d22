"""The frame tree: edges keyed by child, topology checks, lookup plans between frame pairs, and
the messages of lookup errors.


A plan for ``T_target_source`` is the product of factors along the tree path
``target -> ... -> ancestor <- ... <- source``: the inverted edges going up from ``target``, then
the edges going down to ``source``. Runs of consecutive static factors are multiplied once, when
the plan is built, so a lookup only interpolates and composes what changes with time.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass

from tagloc.errors import (
    DisconnectedFramesError,
    ExtrapolationError,
    FrameTreeError,
    UnknownFrameError,
)
from tagloc.frames._edge import DynamicEdge, IntArray
from tagloc.frames._kernels import IDENTITY, Rt, compose, invert
from tagloc.frames._validate import seconds, span


@dataclass(frozen=True, slots=True)
class StaticEdge:
    """``T_parent_child`` valid at every stamp."""

    parent: str
    child: str
    value: Rt


Edge = StaticEdge | DynamicEdge
#: One factor of a plan: a dynamic edge (and whether it enters inverted), or a constant.
Step = tuple[DynamicEdge | None, bool, Rt]


@dataclass(frozen=True, slots=True)
class Plan:
    """How to compute ``T_target_source``: ``steps`` multiplied left to right."""

    target: str
    source: str
    steps: tuple[Step, ...]
    dynamic: tuple[DynamicEdge, ...]


def ancestry(edges: dict[str, Edge], frame: str) -> list[str]:
    """``[frame, parent, grandparent, ..., root]``."""
    chain = [frame]
    edge = edges.get(frame)
    while edge is not None:
        chain.append(edge.parent)
        edge = edges.get(edge.parent)
    return chain


def unknown_frame(frames: Iterable[str], name: object, call: str) -> UnknownFrameError:
    """An error naming ``name``, the known frames and a close match if there is one."""
    known = sorted(frames)
    listed = ", ".join(repr(f) for f in known) if known else "none yet"
    close = difflib.get_close_matches(str(name), known, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return UnknownFrameError(f"unknown frame {name!r} in {call}; known frames: {listed}{hint}")


def check_new_edge(edges: dict[str, Edge], parent: str, child: str) -> None:
    """Raise :class:`FrameTreeError` if ``parent -> child`` would not keep a tree (a forest).

    The caller has handled an existing ``parent -> child`` edge already.
    """
    if parent == child:
        raise FrameTreeError(f"self-edge {parent!r} -> {child!r}: a frame cannot be its own parent")
    existing = edges.get(child)
    if existing is not None:
        raise FrameTreeError(
            f"frame {child!r} already has parent {existing.parent!r}; cannot also attach it to "
            f"{parent!r} (each frame has one parent)"
        )
    chain = ancestry(edges, parent)
    if child in chain:
        path = " -> ".join(repr(f) for f in reversed(chain[: chain.index(child) + 1]))
        raise FrameTreeError(
            f"edge {parent!r} -> {child!r} would close a cycle: {parent!r} is already below "
            f"{child!r} ({path})"
        )


def build_plan(edges: dict[str, Edge], frames: set[str], target: str, source: str) -> Plan:
    """The plan for ``T_target_source``.

    Raises
    ------
    UnknownFrameError
        If either frame is unknown (naming the known frames).
    DisconnectedFramesError
        If the frames are in different trees (naming both roots).
    """
    call = f"lookup({target!r}, {source!r})"
    for name in (target, source):
        if name not in frames:
            raise unknown_frame(frames, name, call)
    up_target, up_source = ancestry(edges, target), ancestry(edges, source)
    if up_target[-1] != up_source[-1]:
        raise DisconnectedFramesError(
            f"{call}: the frames are not connected: {target!r} is in the tree rooted at "
            f"{up_target[-1]!r}, {source!r} in the tree rooted at {up_source[-1]!r}"
        )
    on_target_side = set(up_target)
    ancestor = next(f for f in up_source if f in on_target_side)
    factors: list[tuple[Edge, bool]] = [
        (edges[f], True) for f in up_target[: up_target.index(ancestor)]
    ]
    factors += [(edges[f], False) for f in reversed(up_source[: up_source.index(ancestor)])]
    steps: list[Step] = []
    for edge, inverse in factors:
        if isinstance(edge, DynamicEdge):
            steps.append((edge, inverse, IDENTITY))
            continue
        value = invert(edge.value) if inverse else edge.value
        if steps and steps[-1][0] is None:
            steps[-1] = (None, False, compose(steps[-1][2], value))
        else:
            steps.append((None, False, value))
    dynamic = tuple(step[0] for step in steps if step[0] is not None)
    return Plan(target, source, tuple(steps), dynamic)


def extrapolation_error(plan: Plan, stamps: IntArray, tol: int) -> ExtrapolationError:
    """An error naming every edge of ``plan`` whose range (plus ``tol``) misses one of
    ``stamps``, with that range and how far the stamp is outside it."""
    if len(stamps) == 1:
        head = f"at {span(int(stamps[0]))}"
    else:
        head = f"at {len(stamps)} stamps from {span(int(stamps.min()))} to " + span(
            int(stamps.max())
        )
    lines = []
    for edge in plan.dynamic:
        bad = edge.outside(stamps, tol)
        if not bad.any():
            continue
        if len(stamps) == 1:
            stamp = int(stamps[0])
            gap = stamp - edge.newest if stamp > edge.newest else edge.oldest - stamp
            where = "after the newest" if stamp > edge.newest else "before the oldest"
            miss = f"the stamp is {seconds(gap)} s {where} sample"
        else:
            first = span(int(stamps[bad][0]))
            miss = f"{int(bad.sum())} stamps fall outside, the first at {first}"
        lines.append(
            f"edge {edge.parent!r} -> {edge.child!r} holds {span(edge.oldest)} to "
            f"{span(edge.newest)}; {miss}"
        )
    return ExtrapolationError(
        f"cannot look up T_{plan.target}_{plan.source} {head}: "
        + "; ".join(lines)
        + f" (extrapolation tolerance {span(tol)})"
    )
