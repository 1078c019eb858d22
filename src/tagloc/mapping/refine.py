"""The corner refinement: Gauss-Newton on corners, odometry (with its calibration) and anchors.

Starting from the pose-factor solution, each round

1. linearizes every factor at the current estimate, in numpy: the corners of every observation
   (:mod:`tagloc.mapping.corner_graph`, robust kernel as IRLS weights, false detections left
   out), the odometry steps with the calibration vector ``c`` as a variable
   (:mod:`tagloc.mapping.odometry_factors`), priors on the anchors (:class:`Priors`: each with its
   sigmas), gravity priors (:mod:`tagloc.mapping.gravity`), a broad prior on ``c``, and the
   lidar scan-matching factors if any (:mod:`tagloc.mapping.scan_factors`);
2. solves the sparse normal equations with GTSAM (``GaussianFactorGraph.optimize``: COLAMD
   ordering, multifrontal Cholesky);
3. retracts (``T Exp(delta)``) with a backtracking line search on the robust objective, so it
   never increases;

until no tag moves more than :data:`STEP_TOL_M` / :data:`STEP_TOL_RAD`. Each round is the
exact Gauss-Newton model of the corners (converged in 3-6 rounds on the simulated office). The
last linearization gives the marginal covariances (``gtsam.Marginals`` of the linear graph), with
the calibration's uncertainty included.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace

import gtsam
import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.mapping.corner_graph import corner_chi
from tagloc.mapping.flips import flip_stuck_tags
from tagloc.mapping.graph import GraphSolution, L, X
from tagloc.mapping.gtsam_bridge import solver_errors
from tagloc.mapping.initialize import rotation_angle
from tagloc.mapping.refine_problem import CAL, Priors, RefineInputs, RefineProblem, State

__all__ = ["MAX_FLIP_PASSES", "Priors", "RefineInputs", "State", "refine_and_test_tilts",
           "refine_with_corners"]  # fmt: skip

logger = logging.getLogger(__name__)
#: Stop when no tag moves more than this (m) or turns more than this (rad) in a round.
STEP_TOL_M, STEP_TOL_RAD = 1e-4, 1e-4
_LINE_SEARCH_STEPS = 6
#: Corner refinements after which stuck tilts are tested and flipped (then refined again).
MAX_FLIP_PASSES = 2


def _retract(state: State, delta: gtsam.VectorValues, alpha: float, calibrate: bool) -> State:
    """``state`` moved by ``alpha delta`` (``c`` too if ``calibrate``)."""
    n_kf = len(state.M_map_base)
    d_base = np.array([delta.at(X(k)) for k in range(n_kf)])
    M_map_base = state.M_map_base @ SE3.exp(alpha * d_base).as_matrix()
    keys = sorted(state.M_map_tag)
    d_tag = np.array([delta.at(L(j)) for j in keys])
    M_tags = np.array([state.M_map_tag[j] for j in keys]) @ SE3.exp(alpha * d_tag).as_matrix()
    c = state.c + alpha * delta.at(CAL) if calibrate else state.c
    return State(M_map_base, dict(zip(keys, M_tags, strict=True)), c)


def _moved(a: State, b: State) -> tuple[float, float]:
    moved = max(
        float(np.linalg.norm(b.M_map_tag[j][:3, 3] - M[:3, 3])) for j, M in a.M_map_tag.items()
    )
    turned = max(
        float(rotation_angle(b.M_map_tag[j][:3, :3], M[:3, :3])) for j, M in a.M_map_tag.items()
    )
    return moved, turned


def refine_with_corners(inputs: RefineInputs, start: State) -> tuple[GraphSolution, State]:
    """Refine ``start`` (keyframes, tags and the calibration vector) with the corners (module
    docstring); ``c`` stays at ``start.c`` unless ``inputs.config.joint_calibration``.

    Returns
    -------
    (GraphSolution, State)
        ``mahalanobis`` is the corners' whitened norm per observation; ``linear`` the last
        linearization (for :func:`tagloc.mapping.graph.marginal_covariances`).
    """
    problem, config = RefineProblem(inputs), inputs.config
    calibrate = problem.calibrate
    state, cost = start, problem.objective(start)
    cost_initial, rounds, solve_s = cost, 0, 0.0
    linear: tuple[gtsam.GaussianFactorGraph, FloatArray] | None = None  # at ``state``
    while rounds < config.corner_max_iterations:
        rounds += 1
        linear = problem.linearize(state)
        graph = linear[0]
        t = time.perf_counter()
        with solver_errors("the corner refinement"):
            delta = graph.optimize()
        solve_s += time.perf_counter() - t
        alpha, new, new_cost = 1.0, state, cost
        for _ in range(_LINE_SEARCH_STEPS):
            new = _retract(state, delta, alpha, calibrate)
            new_cost = problem.objective(new)
            if new_cost <= cost:
                break
            alpha *= 0.5
        if new_cost > cost:
            break
        moved, turned = _moved(state, new)
        state, cost, linear = new, new_cost, None
        if moved < STEP_TOL_M and turned < STEP_TOL_RAD:
            break
    graph, r = problem.linearize(state) if linear is None else linear
    solution = GraphSolution(
        M_map_base=state.M_map_base,
        M_map_tag=state.M_map_tag,
        cov_map_tag={},
        mahalanobis=corner_chi(r),
        iterations=rounds,
        error_initial=cost_initial,
        error_final=cost,
        optimize_s=solve_s,
        marginals_s=0.0,
        graph=gtsam.NonlinearFactorGraph(),
        values=gtsam.Values(),
        linear=graph,
    )
    return solution, state


def refine_and_test_tilts(
    inputs: RefineInputs, start: State, fixed: set[int]
) -> tuple[GraphSolution, State, list[int]]:
    """Refine, test every tag's tilt (:mod:`tagloc.mapping.flips`), refine again while tags
    flip (at most :data:`MAX_FLIP_PASSES` tests).

    ``fixed``: tags not tested (anchors). Returns the last solution (iterations and solver time
    summed over the passes), its state, and the tags whose tilt is ambiguous.
    """
    obs = inputs.obs
    state, rounds, solve_s = start, 0, 0.0
    ambiguous: list[int] = []
    for pass_ in range(MAX_FLIP_PASSES + 1):
        solution, state = refine_with_corners(inputs, state)
        rounds += solution.iterations
        solve_s += solution.optimize_s
        if pass_ == MAX_FLIP_PASSES:
            break
        M_map_tag, flipped, ambiguous = flip_stuck_tags(
            obs, state.M_map_base, state.M_map_tag, fixed, inputs.cameras, inputs.T_base_cam,
            inputs.config.pnp_noise.sigma_px,
        )  # fmt: skip
        logger.info("tilt test: flipped tags %s", [obs.tag_keys[j][1] for j in flipped])
        if not flipped:
            break
        state = State(state.M_map_base, M_map_tag, state.c)
    return replace(solution, iterations=rounds, optimize_s=solve_s), state, ambiguous
