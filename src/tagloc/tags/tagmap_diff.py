"""What changed between two tag maps: added, removed and moved tags, changed fields and frames.

Tags are matched by ``(family, id)``; a tag that disappears from one family and appears with the
same id in another (and only there) is reported as a ``family`` change of one tag. A tag *moved*
when its position changed by more than ``min_move_m`` or its orientation by more than
``min_rot_deg`` (the angle of ``R_frame_taga^T R_frame_tagb``), both in the tag's ``frame``; a
pose in a different ``frame`` is reported as a ``frame`` change instead. Changes of ``size``,
``note`` and ``anchor`` are reported; ``observations`` and ``covariance`` (which every builder
run rewrites) are not.

:func:`format_tag_map_diff` gives one line per change, sorted (frames first, then by family and
id), e.g. ``~ tag36h11:17 moved 3.0 cm [+3.0, +0.0, +0.0] cm in map, rotated 2.0 deg``.

When both entries carry a covariance (the builder writes one), a move also tells whether it is
beyond the two maps' combined uncertainty: the Mahalanobis norm of the 6-dof change
``Log(T_old^-1 T_new)`` under ``C_old + C_new`` (both right-tangent, ``[x, y, z, rx, ry, rz]``),
against :data:`MOVE_SIGMAS` (the 99 % quantile of a chi-square with 6 degrees of freedom, as a
norm): ``..., 7.2 sigma: beyond their uncertainty`` (the tag really moved, or one map is wrong)
or ``..., 1.1 sigma: within their uncertainty`` (two surveys of the same wall).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from tagloc.tags.tag_entry import TagEntry
from tagloc.tags.tagmap import TagMap

#: Order of the lines of one tag in the formatted diff.
#: A move whose Mahalanobis norm exceeds this is beyond the maps' combined uncertainty
#: (``sqrt(chi2.ppf(0.99, 6))``).
MOVE_SIGMAS = 4.1
_KIND_ORDER = ("removed", "added", "family", "frame", "moved", "size", "anchor", "note")


@dataclass(frozen=True, slots=True)
class TagMove:
    """A tag whose pose in its ``frame`` changed beyond the thresholds.

    Attributes
    ----------
    key : (str, int)
        ``(family, id)`` in the old map.
    frame : str
        The frame both poses are in.
    delta_position : (3,) tuple of float
        ``position_new - position_old`` in ``frame``, metres.
    translation_m : float
        Norm of ``delta_position``, metres.
    rotation_deg : float
        Angle of the relative rotation ``R_old^T R_new``, degrees, in ``[0, 180]``.
    sigmas : float or None
        Mahalanobis norm of the change under both entries' covariances (module docstring); None
        when either has none.
    """

    key: tuple[str, int]
    frame: str
    delta_position: tuple[float, float, float]
    translation_m: float
    rotation_deg: float
    sigmas: float | None = None

    @property
    def beyond_uncertainty(self) -> bool | None:
        """Whether :attr:`sigmas` exceeds :data:`MOVE_SIGMAS` (None without covariances)."""
        return None if self.sigmas is None else self.sigmas > MOVE_SIGMAS


@dataclass(frozen=True, slots=True)
class TagChange:
    """A changed field of a tag present in both maps: ``field`` went from ``old`` to ``new``."""

    key: tuple[str, int]
    field: str
    old: str | float | bool
    new: str | float | bool


@dataclass(frozen=True, slots=True)
class TagMapDiff:
    """Differences from map ``a`` (old) to map ``b`` (new); entries sorted by (family, id)."""

    added: tuple[TagEntry, ...] = ()
    removed: tuple[TagEntry, ...] = ()
    moved: tuple[TagMove, ...] = ()
    changed: tuple[TagChange, ...] = ()
    frames_added: tuple[str, ...] = ()
    frames_removed: tuple[str, ...] = ()

    @property
    def is_empty(self) -> bool:
        """True when the maps are the same (up to the move thresholds)."""
        return not (
            self.added
            or self.removed
            or self.moved
            or self.changed
            or self.frames_added
            or self.frames_removed
        )


def diff_tag_maps(
    a: TagMap, b: TagMap, *, min_move_m: float = 0.005, min_rot_deg: float = 0.5
) -> TagMapDiff:
    """Compare the old map ``a`` with the new map ``b``.

    Parameters
    ----------
    a, b : TagMap
        The old and the new map.
    min_move_m : float
        A position change larger than this (metres) is a move.
    min_rot_deg : float
        An orientation change larger than this (degrees) is a move.

    Returns
    -------
    TagMapDiff
    """
    # 1. match tags by (family, id); pair a lone id that changed family
    removed = {t.key: t for t in a if b.get(t.id, t.family) is None}
    added = {t.key: t for t in b if a.get(t.id, t.family) is None}
    pairs = [(t, b_t) for t in a if (b_t := b.get(t.id, t.family)) is not None]
    for tag_id in {k[1] for k in removed} & {k[1] for k in added}:
        old = [t for k, t in removed.items() if k[1] == tag_id]
        new = [t for k, t in added.items() if k[1] == tag_id]
        if len(old) == 1 and len(new) == 1:
            pairs.append((removed.pop(old[0].key), added.pop(new[0].key)))
    # 2. compare each pair
    moved: list[TagMove] = []
    changed: list[TagChange] = []
    for old_tag, new_tag in pairs:
        move, changes = _compare(old_tag, new_tag, min_move_m, min_rot_deg)
        moved += [move] if move is not None else []
        changed += changes
    return TagMapDiff(
        added=tuple(sorted(added.values(), key=lambda t: t.key)),
        removed=tuple(sorted(removed.values(), key=lambda t: t.key)),
        moved=tuple(sorted(moved, key=lambda m: m.key)),
        changed=tuple(sorted(changed, key=lambda c: (c.key, _KIND_ORDER.index(c.field)))),
        frames_added=tuple(f for f in b.frames if f not in a.frames),
        frames_removed=tuple(f for f in a.frames if f not in b.frames),
    )


def _compare(
    old: TagEntry, new: TagEntry, min_move_m: float, min_rot_deg: float
) -> tuple[TagMove | None, list[TagChange]]:
    changes = [
        TagChange(old.key, name, getattr(old, name), getattr(new, name))
        for name in ("family", "frame", "size", "anchor", "note")
        if getattr(old, name) != getattr(new, name)
    ]
    if old.frame != new.frame:
        return None, changes
    delta = np.subtract(new.position, old.position)
    R_old_new = old.T_frame_tag().rotation.inverse() @ new.T_frame_tag().rotation
    translation_m = float(np.linalg.norm(delta))
    rotation_deg = math.degrees(float(np.linalg.norm(R_old_new.as_rotvec())))
    if translation_m <= min_move_m and rotation_deg <= min_rot_deg:
        return None, changes
    x, y, z = (float(v) for v in delta)
    sigmas = _mahalanobis(old, new)
    return TagMove(old.key, old.frame, (x, y, z), translation_m, rotation_deg, sigmas), changes


def _mahalanobis(old: TagEntry, new: TagEntry) -> float | None:
    C_old, C_new = old.covariance_matrix(), new.covariance_matrix()
    if C_old is None or C_new is None:
        return None
    xi = np.asarray((old.T_frame_tag().inverse() @ new.T_frame_tag()).log(), dtype=np.float64)
    C = C_old + C_new
    # pseudo-inverse: an anchor's covariance may be (numerically) singular
    return float(np.sqrt(max(float(xi @ np.linalg.pinv(C, rcond=1e-12) @ xi), 0.0)))


def format_tag_map_diff(diff: TagMapDiff) -> list[str]:
    """One line per change, sorted: frame lines, then by (family, id) and kind of change.

    ``+`` added, ``-`` removed, ``~`` changed; positions in metres, moves in cm and degrees.
    """
    lines = [f"+ frame {f}" for f in diff.frames_added]
    lines += [f"- frame {f}" for f in diff.frames_removed]
    keyed: list[tuple[tuple[str, int], int, str]] = []
    for tag in diff.removed:
        keyed.append((tag.key, 0, f"- {_name(tag.key)} removed: {_describe(tag)}"))
    for tag in diff.added:
        keyed.append((tag.key, 1, f"+ {_name(tag.key)} added: {_describe(tag)}"))
    for move in diff.moved:
        dx, dy, dz = (f"{100 * v:+.1f}" for v in move.delta_position)
        keyed.append(
            (
                move.key,
                _KIND_ORDER.index("moved"),
                (
                    f"~ {_name(move.key)} moved {100 * move.translation_m:.1f} cm "
                    f"[{dx}, {dy}, {dz}] cm "
                    f"in {move.frame}, rotated {move.rotation_deg:.1f} deg" + _uncertainty(move)
                ),
            )
        )
    for change in diff.changed:
        old, new = _show(change.old, change.field), _show(change.new, change.field)
        unit = " m" if change.field == "size" else ""
        line = f"~ {_name(change.key)} {change.field} {old} -> {new}{unit}"
        keyed.append((change.key, _KIND_ORDER.index(change.field), line))
    return lines + [line for *_, line in sorted(keyed)]


def summarize_tag_map_diff(diff: TagMapDiff) -> str:
    """One line counting the changes: ``3 changes: 1 added, 1 removed, 1 moved (1 beyond their
    uncertainty), 0 changed fields, 0 frames added or removed`` (``no differences`` if none)."""
    if diff.is_empty:
        return "no differences"
    frames = len(diff.frames_added) + len(diff.frames_removed)
    beyond = sum(bool(m.beyond_uncertainty) for m in diff.moved)
    total = len(diff.added) + len(diff.removed) + len(diff.moved) + len(diff.changed) + frames
    moved = f"{len(diff.moved)} moved" + (
        f" ({beyond} beyond their uncertainty)"
        if any(m.sigmas is not None for m in diff.moved)
        else ""
    )
    return (
        f"{total} change{'s' if total != 1 else ''}: {len(diff.added)} added, "
        f"{len(diff.removed)} removed, {moved}, {len(diff.changed)} changed "
        f"field{'s' if len(diff.changed) != 1 else ''}, {frames} frame(s) added or removed"
    )


def _uncertainty(move: TagMove) -> str:
    if move.sigmas is None:
        return ""
    where = "beyond" if move.beyond_uncertainty else "within"
    return f", {move.sigmas:.1f} sigma: {where} their uncertainty"


def _name(key: tuple[str, int]) -> str:
    return f"{key[0]}:{key[1]}"


def _show(value: str | float | bool, field: str) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return repr(round(value, 6))
    return json.dumps(value, ensure_ascii=False) if field == "note" else value


def _describe(tag: TagEntry) -> str:
    x, y, z = tag.position
    note = f", note {json.dumps(tag.note, ensure_ascii=False)}" if tag.note else ""
    size = repr(round(tag.size, 6))
    return f"in {tag.frame} at [{x:.3f}, {y:.3f}, {z:.3f}] m, size {size} m{note}"
