"""The tag-sensor sweep's checks, with verdicts its sample size supports.

A sweep of a few views a cell (``tagloc eval tags --quick``: 4) measures each statistic with
an uncertainty the targets' margins do not dwarf, so every check states an interval at
:data:`CONFIDENCE` along with its point value and decides three ways:

- **pass**: the point value meets the target;
- **FAIL**: the whole interval misses it (the sweep shows the sensor does not meet it);
- **inconclusive** (``passed`` None with a value): the point value misses but the interval
  reaches the target: more views (``--trials``, the full sweep) decide.

The intervals: a median's from the order statistics of the cell's views (distribution-free);
acceptance's the Clopper-Pearson interval of a binomial; the mean NEES per dof the wider of the
chi-square interval of an honest covariance (``6 n`` dof) and the t interval of the values
(heavy tails widen it). Accepted ambiguity flips are counted: one is a failure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from tagloc.eval.summary_types import Check
from tagloc.eval.tag_sweep_config import TagSweepConfig
from tagloc.eval.tag_sweep_stats import POSE_DOF, TagSweepRow, pooled_nees_per_dof

__all__ = ["CONFIDENCE", "median_interval", "sweep_checks", "verdict"]

#: Two-sided confidence of the intervals the verdicts use.
CONFIDENCE = 0.99


def verdict(meets: bool, surely_misses: bool) -> bool | None:
    """pass / FAIL / inconclusive (None) from the point value and the interval."""
    if meets:
        return True
    return False if surely_misses else None


def median_interval(values: Sequence[float], confidence: float = CONFIDENCE) -> tuple[float, float]:
    """A distribution-free interval for the median: order statistics ``x(l) <= x(u)`` covering
    it with at least ``confidence`` when the sample allows (else the sample's range, or
    ``(-inf, inf)`` without values)."""
    from scipy.stats import binom

    x = np.sort(np.asarray([v for v in values if math.isfinite(v)], dtype=np.float64))
    n = len(x)
    if n == 0:
        return -math.inf, math.inf
    # the largest l with P(Binom(n, 1/2) < l) <= (1 - confidence) / 2 (at least 1); u = n + 1 - l
    lo = 1
    while lo < (n + 1) // 2 and binom.cdf(lo, n, 0.5) <= (1.0 - confidence) / 2.0:
        lo += 1
    return float(x[lo - 1]), float(x[n - lo])


def _proportion_interval(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Clopper-Pearson interval of ``k`` successes in ``n``."""
    from scipy.stats import beta

    a = (1.0 - confidence) / 2.0
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1.0 - a, k + 1, n - k))
    return lo, hi


def _nees_interval(values: Sequence[float], confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Interval of the mean NEES / dof (module docstring)."""
    from scipy.stats import chi2, t

    v = np.asarray([x for x in values if math.isfinite(x)], dtype=np.float64) / POSE_DOF
    n = len(v)
    if n == 0:
        return -math.inf, math.inf
    a, dof, m = (1.0 - confidence) / 2.0, POSE_DOF * n, float(v.mean())
    lo, hi = m * dof / chi2.ppf(1.0 - a, dof), m * dof / chi2.ppf(a, dof)
    if n > 1:
        half = float(t.ppf(1.0 - a, n - 1)) * float(v.std(ddof=1)) / math.sqrt(n)
        lo, hi = min(lo, m - half), max(hi, m + half)
    return float(lo), float(hi)


def _worst_median(
    name: str, rows: Sequence[TagSweepRow], limit: float, unit: str, *, rotation: bool = False
) -> Check:
    """The worst cell's median at most ``limit``: FAIL when some cell's interval is above."""
    cells = [(r.rotation_error_median_deg, r.rotation_errors_deg) if rotation
             else (r.position_error_median_m, r.position_errors_m)
             for r in rows if r.n_accepted]  # fmt: skip
    points = [p for p, _ in cells if math.isfinite(p)]
    if not points:
        return Check(name, math.nan, f"<= {limit:g} {unit}", None)
    worst = max(points)
    surely = any(median_interval(samples)[0] > limit for _, samples in cells)
    return Check(name, worst, f"<= {limit:g} {unit}", verdict(worst <= limit, surely))


def sweep_checks(config: TagSweepConfig, rows: Sequence[TagSweepRow]) -> list[Check]:
    """The targets on a sweep's rows (value NaN and ``passed`` None where the sweep has
    no cell to judge, e.g. no 2 m distance; None with a value: inconclusive).

    - position error median at 2 m and at 4 m: the worst cell (every angle with an accepted
      view) of the reference condition;
    - rotation error median at 2 m for views ``rotation_min_angle_deg`` or more off face-on;
    - accepted ambiguity flips, whole sweep;
    - mean NEES / dof of every accepted estimate of the sweep, within the band;
    - acceptance pooled over the reference condition's views within ``acceptance_max_distance_m``
      at ``acceptance_angles_deg``.
    """
    t = config.targets
    blur, noise = config.reference_condition
    ref = [r for r in rows if r.blur_px == blur and r.noise_dn == noise]

    def at(distance: float, min_angle: float = 0.0) -> list[TagSweepRow]:
        return [r for r in ref if math.isclose(r.distance_m, distance) and r.angle_deg >= min_angle]

    flips = sum(r.flips for r in rows)
    checks = [
        _worst_median("position error median at 2 m (worst angle)", at(2.0),
                      t.position_median_2m_m, "m"),
        _worst_median("position error median at 4 m (worst angle)", at(4.0),
                      t.position_median_4m_m, "m"),
        _worst_median(
            f"rotation error median at 2 m, >= {t.rotation_min_angle_deg:g} deg (worst angle)",
            at(2.0, t.rotation_min_angle_deg), t.rotation_median_2m_deg, "deg", rotation=True,
        ),
        Check("accepted ambiguity flips (all cells)", flips, f"<= {t.max_flips}",
              flips <= t.max_flips),
    ]  # fmt: skip
    low, high = t.nees_per_dof_band
    nees = pooled_nees_per_dof(rows)
    lo, hi = _nees_interval([x for r in rows for x in r.nees_values])
    checks.append(Check(
        "NEES / dof of accepted estimates (all cells)", nees, f"in [{low:g}, {high:g}]",
        None if math.isnan(nees) else verdict(low <= nees <= high, hi < low or lo > high),
    ))  # fmt: skip
    lo_deg, hi_deg = t.acceptance_angles_deg
    band = [r for r in ref if r.distance_m <= t.acceptance_max_distance_m
            and lo_deg <= r.angle_deg <= hi_deg]  # fmt: skip
    n, k = sum(r.n_views for r in band), sum(r.n_accepted for r in band)
    acceptance = k / n if n else math.nan
    checks.append(Check(
        f"acceptance within {t.acceptance_max_distance_m:g} m at {lo_deg:g}-{hi_deg:g} deg "
        "(pooled)", acceptance, f">= {t.acceptance_min:g}",
        None if not n else verdict(acceptance >= t.acceptance_min,
                                   _proportion_interval(k, n)[1] < t.acceptance_min),
    ))  # fmt: skip
    return checks
