"""Evaluation: trajectory error metrics (ATE with Umeyama alignment, RPE by distance and time;
equal to evo's on the same trajectories), the reliability protocol, the naive baseline beside the
filter, drift summaries, plots and the HTML / ``summary.json`` report; the localizer run on
simulated scenarios (:mod:`tagloc.eval.scenarios`)."""

from tagloc.eval.alignment import Alignment, umeyama_alignment
from tagloc.eval.association import associate_stamps
from tagloc.eval.errors import EvaluationError
from tagloc.eval.metrics import TrajectoryError, absolute_trajectory_error, endpoint_drift
from tagloc.eval.protocol import EvalConfig, KidnapRecovery, Reliability
from tagloc.eval.report import export_tum, write_report
from tagloc.eval.rpe import RelativeError, relative_pose_error, relative_pose_error_per_time
from tagloc.eval.summary import evaluate, summary_to_dict
from tagloc.eval.summary_types import EstimatorScore, EvalSummary, Evaluation

__all__ = [
    "Alignment",
    "EstimatorScore",
    "EvalConfig",
    "EvalSummary",
    "Evaluation",
    "EvaluationError",
    "KidnapRecovery",
    "RelativeError",
    "Reliability",
    "TrajectoryError",
    "absolute_trajectory_error",
    "associate_stamps",
    "endpoint_drift",
    "evaluate",
    "export_tum",
    "relative_pose_error",
    "relative_pose_error_per_time",
    "summary_to_dict",
    "umeyama_alignment",
    "write_report",
]
