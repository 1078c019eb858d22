"""Evaluation: trajectory error metrics (ATE, RPE via evo), drift summaries and plots."""

from tagloc.eval.metrics import TrajectoryError, absolute_trajectory_error, endpoint_drift

__all__ = ["TrajectoryError", "absolute_trajectory_error", "endpoint_drift"]
