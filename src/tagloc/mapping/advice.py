"""Advice for uncertain tags: where another tag or an anchor would help.

A tag's marginal position sigma grows with the odometry travelled between it and the anchors
without a tag sighting in between. So for each tag whose sigma exceeds the threshold, this looks
at the survey path around it:

- the longest *coverage gap* next to the tag: a stretch of the path (by distance travelled, between
  consecutive keyframes with any tag sighting) that starts right after a sighting of the tag or
  ends at one; the tags sighted at its other end name where a new tag belongs ("add a tag between
  X and Y");
- the distance to the nearest anchor ("add an anchor near tag X"; a tag within
  :data:`NEAR_ANCHOR_M` of an anchor is uncertain because of that anchor's own sigma: "add an
  anchor far from anchor A", or measure A better).

Both are given (a gap only when it is at least :data:`MIN_GAP_M` long): a gap means the chain
of tags is weak there; a far anchor means the whole chain is long. Pure computation on arrays.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray

#: Shorter stretches without a sighting are not worth a tag (m of path).
MIN_GAP_M = 2.0
#: A flagged tag closer than this to an anchor is uncertain because of the anchor's own sigma
#: (its orientation, levered over the distance): the advice is another anchor far away.
NEAR_ANCHOR_M = 5.0
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class CoverageGap:
    """A stretch of survey path with no tag sighting, between keyframes ``start`` and ``end``.

    ``length_m`` is the distance travelled; ``t0_s``, ``t1_s`` seconds from the survey start;
    ``tags_before``, ``tags_after`` the tag indices sighted at its ends.
    """

    start: int
    end: int
    length_m: float
    t0_s: float
    t1_s: float
    tags_before: frozenset[int]
    tags_after: frozenset[int]


def coverage_gaps(
    positions: FloatArray, stamps_ns: IntArray, keyframe: IntArray, tag: IntArray, t0_ns: int
) -> list[CoverageGap]:
    """The stretches between consecutive keyframes with a sighting, in path order.

    Parameters
    ----------
    positions : (K, 3) float
        Keyframe positions in ``map``, m.
    stamps_ns : (K,) int
    keyframe, tag : (M,) int
        Keyframe and tag index of every observation.
    t0_ns : int
        The survey start (times in the gaps are seconds from it).
    """
    step = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    travelled = np.concatenate([[0.0], np.cumsum(step)])
    seen: dict[int, set[int]] = {}
    for k, j in zip(keyframe.tolist(), tag.tolist(), strict=True):
        seen.setdefault(k, set()).add(j)
    ks = sorted(seen)
    t0 = int(t0_ns)
    return [
        CoverageGap(
            a,
            b,
            float(travelled[b] - travelled[a]),
            (int(stamps_ns[a]) - t0) * 1e-9,
            (int(stamps_ns[b]) - t0) * 1e-9,
            frozenset(seen[a]),
            frozenset(seen[b]),
        )
        for a, b in itertools.pairwise(ks)
    ]


def uncertainty_advice(
    flagged: Sequence[int],
    gaps: Sequence[CoverageGap],
    tag_positions: Mapping[int, FloatArray],
    anchors: Sequence[int],
    names: Sequence[str],
) -> dict[int, str]:
    """One line of advice per flagged tag index (module docstring).

    ``names[j]`` is how tag ``j`` is called in the advice (its id).
    """
    advice = {}
    for j in flagged:
        near = [
            g for g in gaps if (j in g.tags_before or j in g.tags_after) and g.length_m >= MIN_GAP_M
        ]
        parts = []
        if near:
            gap = max(near, key=lambda g: g.length_m)
            others = (gap.tags_after if j in gap.tags_before else gap.tags_before) - {j}
            where = (
                f"{gap.length_m:.1f} m of path without a tag sighting, "
                f"{gap.t0_s:.0f}-{gap.t1_s:.0f} s"
            )
            if others:
                # the other end's tag nearest to this one
                other = min(
                    others,
                    key=lambda o: float(np.linalg.norm(tag_positions[o] - tag_positions[j])),
                )
                parts.append(f"add a tag between {names[j]} and {names[other]} ({where})")
            else:
                parts.append(f"add a tag along the path next to {names[j]} ({where})")
        if anchors:
            nearest = min(
                anchors, key=lambda a: float(np.linalg.norm(tag_positions[a] - tag_positions[j]))
            )
            dist = float(np.linalg.norm(tag_positions[nearest] - tag_positions[j]))
            if dist < NEAR_ANCHOR_M:
                parts.append(
                    f"or add an anchor far from anchor {names[nearest]} ({dist:.1f} m from tag "
                    f"{names[j]}: that anchor's own sigma sets this tag's; measure it better)"
                )
            else:
                parts.append(
                    f"or add an anchor near tag {names[j]} "
                    f"(nearest anchor {names[nearest]} is {dist:.1f} m away)"
                )
        else:
            parts.append(f"or add an anchor near tag {names[j]}")
        text = "; ".join(parts)
        advice[j] = text.removeprefix("or ")
    return advice
