"""GTSAM's failure to solve a graph becomes one line naming the variable (a MappingError)."""

from __future__ import annotations

import gtsam
import pytest

from tagloc.mapping import MappingError
from tagloc.mapping.gtsam_bridge import SolverError, solver_errors


def _tag_without_anchor() -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """A keyframe and a tag tied to each other and to nothing else: the gauge is free."""
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    x, tag = gtsam.symbol("x", 0), gtsam.symbol("l", 1)
    noise = gtsam.noiseModel.Isotropic.Sigma(6, 0.1)
    graph.add(gtsam.BetweenFactorPose3(x, tag, gtsam.Pose3(), noise))
    values.insert(x, gtsam.Pose3())
    values.insert(tag, gtsam.Pose3())
    return graph, values


def test_an_indeterminate_graph_names_the_tag() -> None:
    graph, values = _tag_without_anchor()
    with pytest.raises(SolverError) as info, solver_errors("the test graph"):
        graph.linearize(values).optimize()
    assert isinstance(info.value, MappingError)
    assert info.value.variable == ("l", 1)
    text = str(info.value)
    assert text.startswith("cannot solve the test graph: the system is under-constrained")
    assert "near tag 1;" in text and "\n" not in text
    named = str(info.value.naming(["tag36h11:0", "tag36h11:42"]))
    assert "near tag tag36h11:42;" in named


def test_marginals_of_an_indeterminate_graph_are_one_line() -> None:
    graph, values = _tag_without_anchor()
    with (
        pytest.raises(SolverError, match="cannot solve the covariances"),
        solver_errors("the covariances"),
    ):
        gtsam.Marginals(graph, values)


def test_other_exceptions_pass_through() -> None:
    with pytest.raises(KeyError), solver_errors("the test graph"):
        raise KeyError("not a solver failure")
