"""Evaluation: trajectory error metrics (ATE, RPE via evo), the reliability protocol, the naive
baseline beside the filter, drift summaries, plots and the HTML / ``summary.json`` report; the
localizer run on simulated scenarios (:mod:`tagloc.eval.scenarios`)."""

from tagloc.eval.metrics import TrajectoryError, absolute_trajectory_error, endpoint_drift
from tagloc.eval.protocol import EvalConfig, KidnapRecovery, Reliability
from tagloc.eval.report import export_tum, write_report
from tagloc.eval.summary import EstimatorScore, EvalSummary, Evaluation, evaluate, summary_to_dict
from tagloc.eval.trajectories import RelativeError, relative_pose_error

__all__ = [
    "EstimatorScore",
    "EvalConfig",
    "EvalSummary",
    "Evaluation",
    "KidnapRecovery",
    "RelativeError",
    "Reliability",
    "TrajectoryError",
    "absolute_trajectory_error",
    "endpoint_drift",
    "evaluate",
    "export_tum",
    "relative_pose_error",
    "summary_to_dict",
    "write_report",
]
