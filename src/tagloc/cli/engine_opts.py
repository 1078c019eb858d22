"""``--jobs N`` and ``--ray ADDRESS``: where an evaluation's localizer passes run."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Annotated

import typer

from tagloc.cli.options import in_range

if TYPE_CHECKING:
    from tagloc.eval.engine import Engine

JobsOpt = Annotated[
    int,
    typer.Option(help="Localizer passes at once on this machine (processes; 0: one per core).",
                 callback=in_range(ge=0, le=1024)),
]  # fmt: skip
RayOpt = Annotated[
    str | None,
    typer.Option("--ray", help="Run the passes on the Ray cluster at host:port (tagloc[fleet])."),
]


def make_engine(jobs: int, ray: str | None) -> Engine:
    """The engine the options ask for (checked before any work: an unreachable cluster is one
    line)."""
    if ray is not None:
        from tagloc.adapters.ray import RayEngine

        return RayEngine(ray)
    from tagloc.eval.engine import ProcessEngine

    return ProcessEngine(jobs or os.cpu_count() or 1)


def engine_facts(engine: Engine, ray: str | None, passes: int) -> dict[str, object]:
    """How the passes ran, for the summary."""
    return {"kind": "ray" if ray is not None else "processes", "jobs": engine.jobs,
            "address": ray, "passes": passes}  # fmt: skip
