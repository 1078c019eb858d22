"""Cost of building a tag map: the real dupont drive end to end, and a large synthetic graph.

Run: ``.venv/bin/python benchmarks/bench_mapping.py``

1. dupont (``../shared/data/dupont``, skipped if absent): bag reading (decompressed once into a
   cache; the cached read is what is timed), PnP, pose rounds (GTSAM Levenberg-Marquardt),
   corner refinement (:mod:`tagloc.mapping.refine`: numpy linearization, GTSAM sparse solves,
   tilt test), covariances, report; and the left-only and right-only maps compared. Target
   < 10 s end to end.
2. Synthetic graph: 10,000 keyframes on a planar random walk, 200 tags, 1-2 PnP pose factors per
   keyframe with known covariance. ``tagloc`` = :func:`tagloc.mapping.graph.solve_graph` (build
   the GTSAM graph from arrays, optimize, read back, per-factor errors); ``gtsam`` = GTSAM's own
   ``LevenbergMarquardtOptimizer.optimize()`` on the same graph and initial values. The
   difference is the wrapper's overhead. Target < 3 s.
"""

from __future__ import annotations

import time
from pathlib import Path

import gtsam
import numpy as np

from tagloc.geometry import SE3, inverse_h
from tagloc.mapping import MapBuildConfig
from tagloc.mapping.graph import (
    GraphInput,
    build_graph,
    lm_params,
    marginal_covariances,
    solve_graph,
)

DUPONT = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "dupont"


def bench_dupont() -> list[tuple[str, float, str]]:
    from tagloc.io import BagSource, load_kalibr_cameras
    from tagloc.mapping import build_tag_map
    from tagloc.mapping.stream_survey import parse_camera_poses, parse_tagslam, survey_from_tagslam
    from tagloc.mapping.survey import only_cameras

    bag = DUPONT / "tag_detections.bag.bz2"
    if not bag.is_file():
        return [("dupont", float("nan"), f"skipped: {bag} not found")]
    list(BagSource(bag, corner_order="bl_br_tr_tl", default_family="tag36h11"))  # warm the cache
    start = time.perf_counter()
    items = list(BagSource(bag, corner_order="bl_br_tr_tl", default_family="tag36h11"))
    read_s = time.perf_counter() - start
    rig = parse_tagslam((DUPONT / "tagslam.yaml").read_text(), "tagslam.yaml")
    survey = survey_from_tagslam(  # as `tagloc map build --tagslam`
        items,
        {"/fla/ovc_node/left/tags": "cam0", "/fla/ovc_node/right/tags": "cam1"},
        "/fla/vio/odom",
        load_kalibr_cameras(DUPONT / "cameras.yaml"),
        parse_camera_poses((DUPONT / "camera_poses.yaml").read_text(), "camera_poses.yaml"),
        rig,
        source="dupont",
    )
    tag_map, report = build_tag_map(survey, rig.anchors)
    total_s = time.perf_counter() - start
    t = report.timings_s
    per_cam = ", ".join(f"{k} {v:.2f} px" for k, v in report.reproj_rms_px_per_camera.items())
    left, _ = build_tag_map(only_cameras(survey, ["cam0"]), rig.anchors)
    right, _ = build_tag_map(only_cameras(survey, ["cam1"]), rig.anchors)
    gaps = np.array(
        [
            np.linalg.norm(left.T_frame_tag(e.id).translation - right.T_frame_tag(e.id).translation)
            for e in left
            if right.get(e.id) is not None and not e.anchor
        ]
    )
    return [
        ("dupont: read bag (cached)", read_s, f"{len(items)} messages"),
        ("dupont: PnP", t["observations"], f"{report.observations} observations"),
        ("dupont: pose rounds (GTSAM LM)", t["pose_rounds"], "initialize from drifted VIO"),
        (
            "dupont: corner refinement",
            t["corner_refinement"],
            "Gauss-Newton rounds, linearized in numpy + tilt test",
        ),
        (
            "dupont: both, inside GTSAM",
            t["optimize"],
            f"LM + sparse solves ({report.iterations} iterations and rounds)",
        ),
        ("dupont: covariances + report", t["covariance"] + t["report"], ""),
        (
            "dupont: end to end",
            total_s,
            f"{len(tag_map)} tags; reproj {per_cam}; target < 10 s",
        ),
        (
            "dupont: left vs right maps",
            float("nan"),
            f"{len(gaps)} tags: median {1000 * np.median(gaps):.0f} mm, "
            f"max {1000 * gaps.max():.0f} mm",
        ),
    ]


def synthetic_graph(n_kf: int, n_tags: int, seed: int = 0) -> GraphInput:
    """A planar random-walk survey past ``n_tags`` wall tags, observed with 2 cm / 1 deg noise."""
    rng = np.random.default_rng(seed)
    yaw = np.cumsum(rng.normal(0.0, 0.05, n_kf))
    xy = np.cumsum(0.1 * np.column_stack([np.cos(yaw), np.sin(yaw)]), axis=0)
    M_map_base = SE3.from_rotvec(
        np.column_stack([np.zeros((n_kf, 2)), yaw]), np.column_stack([xy, np.zeros(n_kf)])
    ).as_matrix()
    along = np.linspace(0, n_kf - 1, n_tags).astype(int)
    M_map_tag = (
        M_map_base[along]
        @ SE3.from_rotvec(
            np.tile([0.0, -np.pi / 2, 0.0], (n_tags, 1)), np.tile([2.0, 0.0, 1.0], (n_tags, 1))
        ).as_matrix()
    )
    nearest = np.searchsorted((along[:-1] + along[1:]) / 2, np.arange(n_kf))
    keyframe = np.concatenate([np.arange(n_kf), np.arange(0, n_kf, 2)])
    tag = np.concatenate([nearest, np.minimum(nearest[::2] + 1, n_tags - 1)])
    sigmas = np.array([0.02, 0.02, 0.02, 0.017, 0.017, 0.017])
    noise = SE3.exp(rng.normal(size=(len(tag), 6)) * sigmas).as_matrix()
    M_base_tag = inverse_h(M_map_base[keyframe]) @ M_map_tag[tag] @ noise
    odo_noise = SE3.exp(rng.normal(size=(n_kf, 6)) * [0.005, 0.005, 0, 0, 0, 0.003]).as_matrix()
    M_odom_base = np.empty_like(M_map_base)
    M_odom_base[0] = M_map_base[0]
    steps = inverse_h(M_map_base[:-1]) @ M_map_base[1:] @ odo_noise[1:]
    for k in range(1, n_kf):
        M_odom_base[k] = M_odom_base[k - 1] @ steps[k - 1]
    return GraphInput(
        M_odom_base=M_odom_base,
        keyframe=keyframe,
        tag=tag,
        M_base_tag=M_base_tag,
        cov_base_tag=np.broadcast_to(np.diag(sigmas**2), (len(tag), 6, 6)).copy(),
        M_map_anchor={0: M_map_tag[0]},
        M_map_base_init=M_odom_base,
        M_map_tag_init={
            j: M_odom_base[along[j]] @ inverse_h(M_map_base[along[j]]) @ M_map_tag[j]
            for j in range(n_tags)
        },
    )


def bench_synthetic(n_kf: int = 10_000, n_tags: int = 200) -> list[tuple[str, float, str]]:
    config = MapBuildConfig()
    data = synthetic_graph(n_kf, n_tags)
    start = time.perf_counter()
    solution = solve_graph(data, config)
    wrapper_s = time.perf_counter() - start
    start = time.perf_counter()
    solution = marginal_covariances(solution)
    marginals_s = time.perf_counter() - start
    graph, values = build_graph(data, config)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, lm_params(config))
    start = time.perf_counter()
    optimizer.optimize()
    bare_s = time.perf_counter() - start
    what = f"{n_kf} keyframes, {n_tags} tags, {graph.size()} factors"
    return [
        ("synthetic: tagloc solve_graph", wrapper_s, f"{what}; target < 3 s"),
        ("synthetic: gtsam optimize alone", bare_s, f"{optimizer.iterations()} iterations"),
        ("synthetic: wrapper overhead", wrapper_s - solution.optimize_s, "build + read back"),
        ("synthetic: marginals (200 tags)", marginals_s, ""),
    ]


def main() -> None:
    rows = bench_synthetic() + bench_dupont()
    width = max(len(name) for name, _, _ in rows)
    print(f"{'case':<{width}}  {'seconds':>8}  notes")
    for name, seconds, note in rows:
        shown = "       -" if np.isnan(seconds) else f"{seconds:8.3f}"
        print(f"{name:<{width}}  {shown}  {note}")


if __name__ == "__main__":
    main()
