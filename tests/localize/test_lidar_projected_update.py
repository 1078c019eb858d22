"""The filter's update from a fix that measures only some directions (``update_partial``).

Oracles: the filter's own full update (a full-rank basis must reproduce it), and the exact
statement of the constraint: the base's pose the state gives moves only within the measured
directions, ``Log((X0 A)^-1 (X A))`` has no component outside ``span(B)``.
"""

from __future__ import annotations

import numpy as np
import pytest

from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize import FixQuality, LocalizerConfig, MapOdomFilter, TagFix
from tagloc.localize.events import EventKind
from tagloc.localize.fix import LocalizeError, PartialFix

S = 1_000_000_000
T_FIX = 2 * S


def _filter(planar: bool, seed: int = 0) -> MapOdomFilter:
    """A filter started from a prior with strong cross-correlations, odometry for 3 s (a level
    base driving along x and turning slowly)."""
    config = LocalizerConfig.model_validate({"filter": {"planar": planar}})
    buffer = TransformBuffer(window_ns=60 * S)
    for i in range(31):
        t = i * 0.1
        T = SE3.exp([0.5 * t, 0.02 * t, 0.0, 0.0, 0.0, 0.1 * t])
        buffer.set_transform("odom", "base_link", round(t * S), T)
    flt = MapOdomFilter.from_config(config, buffer)
    rng = np.random.default_rng(seed)
    L = rng.normal(size=(6, 6)) * np.array([0.1, 0.1, 0.05, 0.01, 0.01, 0.05])
    cov = L @ L.T + 1e-4 * np.eye(6)  # correlated: every axis with every other
    flt.initialize(0, SE3.exp([1.0, 2.0, 0.0, 0.0, 0.0, 0.3]), cov)
    flt.predict(T_FIX)
    return flt


def _true_base(flt: MapOdomFilter, offset: list[float]) -> SE3:
    return flt.T_map_base_at(T_FIX).plus(offset)


@pytest.mark.parametrize("planar", [False, True])
def test_corridor_fix_never_moves_the_unmeasured_directions(planar: bool) -> None:
    flt = _filter(planar)
    before = flt.T_map_base_at(T_FIX)
    basis = np.zeros((6, 2))
    basis[1, 0] = basis[5, 1] = 1.0  # y and yaw measured, x (and the rest) not
    fix = PartialFix(T_FIX, _true_base(flt, [0.3, 0.1, 0.0, 0.0, 0.0, 0.02]), basis,
                     np.diag([0.02**2, 0.01**2]), "lidar")  # fmt: skip
    event = flt.update_partial(fix)
    assert event.kind is EventKind.ACCEPTED
    moved = flt.T_map_base_at(T_FIX).minus(before)
    np.testing.assert_allclose(moved[[0, 2, 3, 4]], 0.0, atol=1e-12)
    assert abs(moved[1]) > 0.05 and abs(moved[5]) > 0.01
    # the oracle that the prior's correlations would move x: the same fix as a full fix with
    # x (and the off-plane axes) barely known moves x by centimetres
    oracle = _filter(planar)
    cov6 = np.diag([1e4, 0.02**2, 1e4, 1e4, 1e4, 0.01**2])
    oracle.update(TagFix(T_FIX, fix.T_map_base, cov6, "tag:1", FixQuality(0.1)))
    assert abs(oracle.T_map_base_at(T_FIX).minus(before)[0]) > 0.01


@pytest.mark.parametrize("planar", [False, True])
@pytest.mark.parametrize("offset_m", [0.02, 0.3])  # one step, and relinearizations
def test_full_rank_basis_reproduces_the_full_update(planar: bool, offset_m: float) -> None:
    rng = np.random.default_rng(3)
    basis, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    A = rng.normal(size=(6, 6)) * 0.1
    cov6 = A @ A.T + 1e-4 * np.eye(6)
    if planar:  # the planar filter ignores z, roll, pitch: keep them uncorrelated with the rest
        cov6[np.ix_([0, 1, 5], [2, 3, 4])] = cov6[np.ix_([2, 3, 4], [0, 1, 5])] = 0.0
    full, partial = _filter(planar, 1), _filter(planar, 1)
    T_fix = _true_base(full, [offset_m, -offset_m, 0.0, 0.0, 0.0, 0.05])
    e_full = full.update(TagFix(T_FIX, T_fix, cov6, "tag:1", FixQuality(0.1)))
    e_part = partial.update_partial(PartialFix(T_FIX, T_fix, basis, basis.T @ cov6 @ basis, "l"))
    assert e_full.kind is e_part.kind is EventKind.ACCEPTED
    assert e_part.d2 == pytest.approx(e_full.d2, rel=1e-10)
    np.testing.assert_allclose(partial.T_map_odom.minus(full.T_map_odom), 0.0, atol=1e-12)
    np.testing.assert_allclose(partial.covariance, full.covariance, atol=1e-12)
    cal_p, cal_f = partial.odometry_calibration, full.odometry_calibration
    assert cal_p is not None and cal_f is not None
    np.testing.assert_allclose(cal_p[0], cal_f[0], atol=1e-12)


def test_gate_on_k_dof_and_no_state() -> None:
    flt = _filter(False)
    basis = np.eye(6)[:, [1]]
    far = PartialFix(T_FIX, _true_base(flt, [0, 5.0, 0, 0, 0, 0]), basis, [[1e-4]], "lidar")
    event = flt.update_partial(far)
    assert event.kind is EventKind.GATED_CHI2
    assert event.threshold == pytest.approx(10.827566, rel=1e-5)  # chi2.ppf(0.999, 1)
    buffer = TransformBuffer(window_ns=S)
    empty = MapOdomFilter.from_config(LocalizerConfig(), buffer)
    buffer.set_transform("odom", "base_link", 0, SE3.identity())
    assert (
        empty.update_partial(PartialFix(0, SE3.identity(), basis, [[1e-4]], "lidar")).kind
        is EventKind.UNUSED_NO_STATE
    )


def test_partial_fix_validation() -> None:
    with pytest.raises(LocalizeError, match="orthonormal"):
        PartialFix(0, SE3.identity(), np.ones((6, 1)), [[1.0]], "lidar")
    with pytest.raises(LocalizeError, match=r"basis must be \(6, k\)"):
        PartialFix(0, SE3.identity(), np.eye(3), np.eye(3), "lidar")
    with pytest.raises(LocalizeError, match="positive definite"):
        PartialFix(0, SE3.identity(), np.eye(6)[:, :2], np.diag([1.0, -1.0]), "lidar")
