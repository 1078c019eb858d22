"""Checks of numeric command-line options, run by typer while it parses (before any work).

``typer.Option(callback=in_range(gt=0))`` refuses NaN, infinities and values out of range with
one line naming the option, e.g. ``tagloc: error: --duration nan: expected a finite number > 0``
(an :class:`OptionError`, so exit code 1 and no traceback). Lists (repeatable options) are checked
element by element; ``None`` (an option not given) passes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import typer

from tagloc.errors import TaglocError

#: Largest seed accepted (numpy's 32-bit legacy seeds; every seed in tagloc fits).
MAX_SEED = 2**32 - 1
#: Longest ``--duration`` accepted, s (a simulated drive is minutes long; longer asks are clipped).
MAX_DURATION_S = 1e6


class OptionError(TaglocError, ValueError):
    """A command-line option whose value is out of range; the message names the option."""


def in_range(
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
) -> Callable[[typer.Context, typer.CallbackParam, Any], Any]:
    """A typer callback that accepts finite numbers within the given bounds (pydantic's names).

    Raises
    ------
    OptionError
        From the callback: a NaN, an infinity, or a value outside the bounds.
    """
    bounds = [(">=", ge), (">", gt), ("<=", le), ("<", lt)]
    wanted = " and ".join(f"{op} {_show(b)}" for op, b in bounds if b is not None)
    inside: dict[str, Callable[[float, float], bool]] = {
        ">=": lambda v, b: v >= b, ">": lambda v, b: v > b,
        "<=": lambda v, b: v <= b, "<": lambda v, b: v < b,
    }  # fmt: skip

    def check(ctx: typer.Context, param: typer.CallbackParam, value: Any) -> Any:
        values = value if isinstance(value, Sequence) else [value]
        for v in values:
            if v is None:
                continue
            finite = not isinstance(v, float) or math.isfinite(v)
            if not finite or not all(inside[op](v, b) for op, b in bounds if b is not None):
                kind = "an integer" if isinstance(v, int) else "a finite number"
                raise OptionError(f"{option_name(param)} {_show(v)}: expected {kind} {wanted}")
        return value

    return check


def option_name(param: typer.CallbackParam) -> str:
    """The option's longest spelling (``--camera-stride``), or the argument's name."""
    return max(param.opts, key=len) if param.opts else str(param.name).upper()


def _show(value: float) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


#: Callbacks of the options most commands share.
seed_range = in_range(ge=0, le=MAX_SEED)
duration_range = in_range(gt=0, le=MAX_DURATION_S)
positive_int = in_range(ge=1)

#: The simulated scenarios, for the help of every ``--scenario`` (``tagloc.sim.scenarios`` is too
#: heavy to import for ``--help``; a test holds this list to its ``SCENARIOS``).
SCENARIO_NAMES = (
    "default", "kidnap", "kidnap_one_tag", "glint", "moved_tag", "corridor", "dropout",
    "camera_unplugged", "odometry_stall", "clock_jump_back", "duplicated_messages",
    "glass_corridor", "mirrored_lobby", "crowd", "lidar_unplugged", "long_corridor", "elevator",
    "elevator_imu", "kidnap_floor",
)  # fmt: skip
SCENARIO_HELP = "Simulated scenario: " + ", ".join(SCENARIO_NAMES) + "."
