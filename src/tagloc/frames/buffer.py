"""``TransformBuffer``: a tree of frames with time-indexed and static edges (semantics in
:mod:`tagloc.frames`)."""

from __future__ import annotations

import logging
from typing import Any, TypeAlias

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import FrameTreeError, TransformLookupError
from tagloc.frames import _kernels, _validate
from tagloc.frames._edge import DynamicEdge
from tagloc.frames._tree import (
    Edge,
    Plan,
    StaticEdge,
    build_plan,
    check_new_edge,
    extrapolation_error,
    unknown_frame,
)
from tagloc.geometry import SE3, SO3

logger = logging.getLogger(__name__)

DEFAULT_WINDOW_NS = 10_000_000_000
#: A stamp in integer nanoseconds: ``int`` or a numpy integer scalar.
StampNs: TypeAlias = int | np.integer[Any]


class TransformBuffer:
    """Transforms between named frames over time: set edges, look up any connected pair.

    Parameters
    ----------
    window_ns : int
        Per dynamic edge, samples older than its newest stamp minus ``window_ns`` are dropped on
        insert (default 10 s), so memory is bounded by the sample rate times the window.
    extrapolation_tolerance_ns : int
        A lookup up to this far before the oldest or after the newest sample of an edge holds
        that end sample (default 0: only stamps inside the buffered range).

    Raises
    ------
    StampError
        If either parameter is not an integer; ``ValueError`` if ``window_ns <= 0`` or the
        tolerance is negative.

    Notes
    -----
    Not thread safe: guard every call with one lock when several threads share a buffer.
    """

    def __init__(
        self, window_ns: int = DEFAULT_WINDOW_NS, extrapolation_tolerance_ns: int = 0
    ) -> None:
        window = _validate.stamp(window_ns, "window_ns")
        tolerance = _validate.stamp(extrapolation_tolerance_ns, "extrapolation_tolerance_ns")
        if window <= 0 or tolerance < 0:
            raise ValueError(
                f"window_ns must be > 0 and extrapolation_tolerance_ns >= 0, got {window} and "
                f"{tolerance}"
            )
        self._window = window
        self._tolerance = tolerance
        self._edges: dict[str, Edge] = {}  # keyed by child frame
        self._frames: set[str] = set()
        self._plans: dict[tuple[str, str], Plan] = {}
        self._revision = 0

    # ----- properties ------------------------------------------------------------------------
    @property
    def window_ns(self) -> int:
        """Length of the per-edge window of dynamic samples, in nanoseconds."""
        return self._window

    @property
    def extrapolation_tolerance_ns(self) -> int:
        """How far beyond an edge's buffered range a lookup holds the end sample, in ns."""
        return self._tolerance

    @property
    def frames(self) -> tuple[str, ...]:
        """Every frame named by an edge, sorted."""
        return tuple(sorted(self._frames))

    @property
    def revision(self) -> int:
        """Counts the calls that may change the buffer (every insert and static edge): a
        lookup's result stays valid while it is unchanged (for callers that cache lookups)."""
        return self._revision

    @property
    def nbytes(self) -> int:
        """Bytes allocated for dynamic samples over all edges."""
        return sum(e.nbytes for e in self._edges.values() if isinstance(e, DynamicEdge))

    # ----- insertion -------------------------------------------------------------------------
    def set_transform(
        self, parent: str, child: str, stamp_ns: StampNs, T_parent_child: SE3
    ) -> None:
        """Insert the sample ``T_parent_child`` at ``stamp_ns`` on the dynamic edge
        ``parent -> child`` (created on first use).

        Samples may arrive out of order within the window. A sample at a stamp already
        buffered replaces the old one (last writer wins).

        Raises
        ------
        StampError
            If ``stamp_ns`` is not an integer.
        GeometryError
            If ``T_parent_child`` is not one finite :class:`SE3`.
        FrameTreeError
            On a self-edge, a second parent for ``child``, a cycle, or an edge set static before.
        StaleSampleError
            If ``stamp_ns`` is older than the edge's newest stamp minus the window.
        """
        self._revision += 1
        stamp = _validate.stamp(stamp_ns)
        values = _validate.single_pose(T_parent_child, parent, child)
        sample = [*_kernels.quat_from_matrix(values[:9]), *values[9:]]
        edge, new = self._edge_to_fill(parent, child)
        edge.insert(stamp, sample, self._window)
        if new:
            self._attach(edge)

    def set_transforms(
        self, parent: str, child: str, stamps_ns: npt.ArrayLike, T_parent_child: SE3
    ) -> None:
        """Insert ``N`` samples at once (e.g. replaying a log): as ``N`` calls of
        :meth:`set_transform` in the given order, but vectorized. All or nothing.

        Parameters
        ----------
        stamps_ns : (N,) int64
            Any order; equal stamps keep the later sample.
        T_parent_child : SE3, a batch of N

        Raises
        ------
        As :meth:`set_transform`; the :class:`StaleSampleError` names the first stale sample.
        """
        self._revision += 1
        stamps = _validate.stamps(stamps_ns)
        poses = _validate.pose_batch(T_parent_child, len(stamps), parent, child)
        quats = np.reshape(poses.rotation.as_quat(), (-1, 4))
        samples = np.concatenate([quats, np.reshape(poses.translation, (-1, 3))], axis=1)
        edge, new = self._edge_to_fill(parent, child)
        edge.insert_many(stamps, samples, self._window)  # may raise: attach only after
        if new:
            self._attach(edge)

    def set_static(self, parent: str, child: str, T_parent_child: SE3) -> None:
        """Set the static edge ``parent -> child``, valid at every stamp. Setting it again
        replaces the value (e.g. a new calibration).

        Raises
        ------
        GeometryError, FrameTreeError
            As :meth:`set_transform` (here: an edge that is dynamic already).
        """
        self._revision += 1
        values = _validate.single_pose(T_parent_child, parent, child)
        value: _kernels.Rt = tuple(values)  # type: ignore[assignment]
        edge = self._edges.get(child)
        if not (isinstance(edge, StaticEdge) and edge.parent == parent):
            self._check_attach(parent, child, dynamic=False)
        self._attach(StaticEdge(parent, child, value))

    def _edge_to_fill(self, parent: str, child: str) -> tuple[DynamicEdge, bool]:
        """The dynamic edge ``parent -> child``, or a new one (checked, not yet attached: the
        caller attaches it once its samples are in) and True."""
        edge = self._edges.get(child)
        if isinstance(edge, DynamicEdge) and edge.parent == parent:
            return edge, False
        self._check_attach(parent, child, dynamic=True)
        return DynamicEdge(parent, child), True

    def _check_attach(self, parent: str, child: str, *, dynamic: bool) -> None:
        """Raise unless a new edge ``parent -> child`` keeps the frames a tree (a forest)."""
        _validate.frame(parent, "parent")
        _validate.frame(child, "child")
        existing = self._edges.get(child)
        if existing is not None and existing.parent == parent:
            kind, other = ("static", "dynamic") if dynamic else ("dynamic", "static")
            raise FrameTreeError(
                f"edge {parent!r} -> {child!r} is {kind}; cannot use it as {other} "
                f"({'set_transform' if dynamic else 'set_static'})"
            )
        check_new_edge(self._edges, parent, child)

    def _attach(self, edge: Edge) -> None:
        """Add or replace ``edge`` (checked already) and forget the cached paths."""
        if edge.child not in self._edges:
            logger.debug("new edge %r -> %r (%s)", edge.parent, edge.child, type(edge).__name__)
        self._edges[edge.child] = edge
        self._frames.update((edge.parent, edge.child))
        self._plans.clear()

    # ----- lookup ----------------------------------------------------------------------------
    def lookup(self, target: str, source: str, stamp_ns: StampNs) -> SE3:
        """``T_target_source`` at ``stamp_ns``: maps points from ``source`` into ``target``.

        Composes the edges up from ``source`` and ``target`` to their common ancestor; each
        dynamic edge is interpolated at ``stamp_ns`` (slerp on rotation, linear on translation).

        Raises
        ------
        UnknownFrameError
            Naming the unknown frame and the known ones.
        DisconnectedFramesError
            Naming the roots of both trees.
        ExtrapolationError
            Naming each edge whose buffered range (plus tolerance) misses ``stamp_ns``.
        StampError
            If ``stamp_ns`` is not an integer.
        """
        stamp = _validate.stamp(stamp_ns)
        plan = self._plans.get((target, source)) or self._plan(target, source)
        tolerance = self._tolerance
        acc: _kernels.Rt | None = None
        for edge, inverse, const in plan.steps:
            if edge is None:
                factor = const
            else:
                sample = edge.sample(stamp, tolerance)
                if sample is None:
                    raise extrapolation_error(plan, np.array([stamp], dtype=np.int64), tolerance)
                factor = _kernels.rt_from_sample(sample)
                if inverse:
                    factor = _kernels.invert(factor)
            acc = factor if acc is None else _kernels.compose(acc, factor)
        rt = _kernels.IDENTITY if acc is None else acc
        # products of unit-quaternion rotations: valid by construction (the checked
        # constructor's orthonormality test cost more than the lookup itself)
        return SE3.from_trusted(np.array(rt[:9]).reshape(3, 3), rt[9:])

    def lookup_many(self, target: str, source: str, stamps_ns: npt.ArrayLike) -> SE3:
        """``T_target_source`` at each of ``stamps_ns`` (``(N,)`` int64, any order): a batch of
        ``N``, vectorized. Raises as :meth:`lookup` (the message counts the stamps out of range).
        """
        stamps = _validate.stamps(stamps_ns)
        plan = self._plans.get((target, source)) or self._plan(target, source)
        if any(edge.outside(stamps, self._tolerance).any() for edge in plan.dynamic):
            raise extrapolation_error(plan, stamps, self._tolerance)
        R_acc, t_acc = np.eye(3), np.zeros(3)
        for edge, inverse, const in plan.steps:
            if edge is None:
                R, t = np.array(const[:9]).reshape(3, 3), np.array(const[9:])
            else:
                samples = edge.sample_many(stamps)
                R, t = _kernels.matrices_from_quats(samples[:, :4]), samples[:, 4:]
                if inverse:
                    R, t = _kernels.invert_many(R, t)
            R_acc, t_acc = _kernels.compose_many(R_acc, t_acc, R, t)
        n = len(stamps)
        R_batch: FloatArray = np.array(np.broadcast_to(R_acc, (n, 3, 3)))
        t_batch: FloatArray = np.array(np.broadcast_to(t_acc, (n, 3)))
        return SE3(rotation=SO3.from_matrix(R_batch), translation=t_batch)

    def can_transform(self, target: str, source: str, stamp_ns: StampNs) -> bool:
        """True if :meth:`lookup` would succeed (``StampError`` still raises)."""
        stamp = _validate.stamp(stamp_ns)
        try:
            plan = self._plans.get((target, source)) or self._plan(target, source)
        except TransformLookupError:
            return False
        return all(edge.covers(stamp, self._tolerance) for edge in plan.dynamic)

    def _plan(self, target: str, source: str) -> Plan:
        plan = build_plan(self._edges, self._frames, target, source)
        self._plans[(target, source)] = plan
        return plan

    # ----- edge inspection -------------------------------------------------------------------
    def stamp_range(self, parent: str, child: str) -> tuple[int, int]:
        """``(oldest, newest)`` buffered stamps (ns) of the dynamic edge ``parent -> child``.

        Raises
        ------
        UnknownFrameError
            If a frame is unknown.
        TransformLookupError
            If there is no such edge or it is static.
        """
        edge = self._dynamic_edge(parent, child)
        return edge.oldest, edge.newest

    def latest_stamp(self, parent: str, child: str) -> int:
        """Newest buffered stamp (ns) of the dynamic edge ``parent -> child`` (raises as
        :meth:`stamp_range`)."""
        return self._dynamic_edge(parent, child).newest

    def num_samples(self, parent: str, child: str) -> int:
        """Samples buffered on the dynamic edge ``parent -> child`` (raises as
        :meth:`stamp_range`)."""
        return self._dynamic_edge(parent, child).count

    def _dynamic_edge(self, parent: str, child: str) -> DynamicEdge:
        call = f"edge {parent!r} -> {child!r}"
        for name in (parent, child):
            if name not in self._frames:
                raise unknown_frame(self._frames, name, call)
        edge = self._edges.get(child)
        if edge is None or edge.parent != parent:
            actual = "it is a root" if edge is None else f"its parent is {edge.parent!r}"
            raise TransformLookupError(f"no {call}: {actual}")
        if isinstance(edge, StaticEdge):
            raise TransformLookupError(f"{call} is static: valid at every stamp, no samples")
        return edge
