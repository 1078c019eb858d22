"""A small drive simulator for the filter tests (truth, drifting odometry, noisy fixes), and
tests that it draws what it claims (the filter's consistency tests rely on that).

Frames: the true ``T_map_base(t)``; odometry ``T_odom_base(t)`` integrates the true increments
perturbed in the base frame, ``D_k (+) n_k`` with ``n_k ~ N(0, diag(s_m^2 d_k + s_rad^2 r_k +
s_s^2 dt_k))`` (the filter's process model); so the true correction is
``T_map_odom(t) = T_map_base(t) @ T_odom_base(t)^-1``. Fixes are ``T_map_base(t) (+) e`` with
``e ~ N(0, cov)`` drawn from their stated covariance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3, SO3
from tagloc.localize import FixQuality, LocalizerConfig, MapOdomFilter, TagFix

S, MS = 1_000_000_000, 1_000_000
SIGMA_M = np.array([0.05, 0.05, 0.02, 0.005, 0.005, 0.02])
SIGMA_RAD = np.array([0.02, 0.02, 0.005, 0.005, 0.005, 0.03])
SIGMA_S = np.array([0.002, 0.002, 0.002, 0.001, 0.001, 0.001])
FIX_COV = np.diag(np.square([0.03, 0.03, 0.05, 0.01, 0.01, 0.01]))


@dataclass
class Drive:
    """Truth and odometry at ``stamps_ns`` (``(N,)`` int64)."""

    stamps_ns: np.ndarray
    T_map_base: SE3
    T_odom_base: SE3

    def index(self, stamp_ns: int) -> int:
        return int(np.searchsorted(self.stamps_ns, stamp_ns))

    def T_map_odom(self, stamp_ns: int) -> SE3:
        i = self.index(stamp_ns)
        return self.T_map_base[i] @ self.T_odom_base[i].inverse()

    def fill(self, buffer: TransformBuffer, until_ns: int | None = None) -> None:
        """Insert the odometry (up to ``until_ns``) as ``odom -> base_link``."""
        n = len(self.stamps_ns) if until_ns is None else self.index(until_ns) + 1
        buffer.set_transforms("odom", "base_link", self.stamps_ns[:n], self.T_odom_base[:n])

    def teleported(self, stamp_ns: int, T_jump: SE3) -> Drive:
        """The robot carried off at ``stamp_ns`` (``T_map_base <- T_jump @ T_map_base``), unseen
        by the odometry (a kidnap)."""
        i = self.index(stamp_ns)
        truth = list(self.T_map_base)
        truth[i:] = [T_jump @ T for T in truth[i:]]
        return Drive(self.stamps_ns, SE3.stack(truth), self.T_odom_base)


def square_path(
    side_m: float = 6.0,
    laps: int = 2,
    speed: float = 1.0,
    turn_rate: float = 1.0,
    rate_hz: float = 100.0,
    z_wobble_m: float = 0.0,
) -> tuple[np.ndarray, SE3]:
    """A square loop (drive a side, turn 90 deg in place), starting at (1, 2) heading +x."""
    dt = 1.0 / rate_hz
    poses = []
    x, y, yaw = 1.0, 2.0, 0.0
    for _ in range(4 * laps):
        for _ in range(round(side_m / speed / dt)):
            x, y = x + speed * dt * np.cos(yaw), y + speed * dt * np.sin(yaw)
            poses.append((x, y, yaw))
        for _ in range(round(np.pi / 2 / turn_rate / dt)):
            yaw += turn_rate * dt
            poses.append((x, y, yaw))
    xyz = np.array(poses)
    stamps = (np.arange(len(xyz)) * dt * S).astype(np.int64)
    z = z_wobble_m * np.sin(np.arange(len(xyz)) * 0.05)
    T = SE3(
        rotation=SO3.from_rotvec(np.outer(xyz[:, 2], [0.0, 0.0, 1.0])),
        translation=np.stack([xyz[:, 0], xyz[:, 1], z], axis=1),
    )
    return stamps, T


def simulate(rng: np.random.Generator, *, noise_scale: float = 1.0, **path: float) -> Drive:
    """Drive the square with drifting odometry drawn from the filter's process model."""
    stamps, truth = square_path(**path)  # type: ignore[arg-type]
    steps = truth[:-1].inverse() @ truth[1:]
    dist = np.linalg.norm(steps.translation, axis=1)
    rot = np.linalg.norm(steps.rotation.log(), axis=1)
    dts = np.diff(stamps) / S
    var = np.outer(dist, SIGMA_M**2) + np.outer(rot, SIGMA_RAD**2) + np.outer(dts, SIGMA_S**2)
    noise = noise_scale * rng.standard_normal(var.shape) * np.sqrt(var)
    measured = steps @ SE3.exp(noise) if noise_scale else steps
    odom = [SE3.identity()]
    for step in measured:
        odom.append(odom[-1] @ step)
    return Drive(stamps, truth, SE3.stack(odom))


def make_fix(
    drive: Drive,
    stamp_ns: int,
    rng: np.random.Generator | None,
    source: str = "tag:1",
    cov: np.ndarray = FIX_COV,
    offset: SE3 | None = None,
    reproj: float = 0.4,
) -> TagFix:
    """A fix at ``stamp_ns``: truth (moved by ``offset`` on the left) perturbed by ``cov``."""
    T = drive.T_map_base[drive.index(stamp_ns)]
    if offset is not None:
        T = offset @ T
    if rng is not None:
        T = T.plus(rng.multivariate_normal(np.zeros(6), cov))
    return TagFix(stamp_ns, T, cov, source, FixQuality(reproj_err_px=reproj))


def make_filter(buffer: TransformBuffer, **sections: dict[str, object]) -> MapOdomFilter:
    """``MapOdomFilter.from_config`` with the simulator's noise and section overrides.

    Odometry calibration is off unless a test turns it on: this simulator's odometry drifts by
    the filter's random-walk model alone (no systematic error to calibrate), and several tests
    check the random-walk mechanics exactly. ``test_localize_calibration`` tests it.
    """
    data: dict[str, object] = {
        "process_noise": {
            "sigma_per_sqrt_m": SIGMA_M.tolist(),
            "sigma_per_sqrt_rad": SIGMA_RAD.tolist(),
            "sigma_per_sqrt_s": SIGMA_S.tolist(),
        },
        "calibration": {"enabled": False},
        **sections,
    }
    return MapOdomFilter.from_config(LocalizerConfig.model_validate(data), buffer)


def fix_stamps(drive: Drive, rate_hz: float, start_s: float = 0.0, stop_s: float | None = None):
    stop = drive.stamps_ns[-1] if stop_s is None else round(stop_s * S)
    return np.arange(round(start_s * S), stop, round(S / rate_hz), dtype=np.int64)


# ----- the simulator draws what it claims ----------------------------------------------------
def test_odometry_drift_matches_the_process_model() -> None:
    rng = np.random.default_rng(7)
    runs = [simulate(rng, laps=1) for _ in range(40)]
    stamps = runs[0].stamps_ns
    end = len(stamps) - 1
    # Correction error after one lap against the model's prediction from the buffer path.
    buffer = TransformBuffer(window_ns=1000 * S)
    runs[0].fill(buffer)
    flt = make_filter(buffer)
    flt.initialize(0, runs[0].T_map_odom(0), np.eye(6) * 1e-12)
    Q = flt.pose_at(int(stamps[end])).cov  # covariance of T_map_base: odometry drift only
    errs = np.array([r.T_map_base[end].minus(r.T_map_odom(0) @ r.T_odom_base[end]) for r in runs])
    ratio = np.var(errs, axis=0) / np.diag(Q)
    assert np.all((ratio > 0.4) & (ratio < 2.5)), ratio


def test_fixes_are_drawn_from_their_covariance() -> None:
    rng = np.random.default_rng(8)
    drive = simulate(rng, noise_scale=0.0, laps=1)
    t = int(drive.stamps_ns[500])
    errs = np.array(
        [make_fix(drive, t, rng).T_map_base.minus(drive.T_map_base[500]) for _ in range(2000)]
    )
    np.testing.assert_allclose(np.cov(errs.T), FIX_COV, atol=3e-4)


def run_fixes(
    flt: MapOdomFilter,
    drive: Drive,
    rng: np.random.Generator,
    stamps: np.ndarray,
    sources: tuple[str, ...] = ("tag:1", "tag:2", "tag:3", "tag:4"),
    offsets: dict[str, SE3] | None = None,
) -> list[tuple[TagFix, object]]:
    """Feed one fix per stamp, cycling through ``sources``; return (fix, event) pairs."""
    out = []
    for i, t in enumerate(stamps):
        source = sources[i % len(sources)]
        fix = make_fix(drive, int(t), rng, source, offset=(offsets or {}).get(source))
        out.append((fix, flt.update(fix)))
    return out


def pose_error(T_est: SE3, T_true: SE3) -> tuple[float, float]:
    """Translation (m) and rotation (rad) of ``T_est^-1 @ T_true``."""
    delta = T_est.inverse() @ T_true
    return float(np.linalg.norm(delta.translation)), float(np.linalg.norm(delta.rotation.log()))


def base_error(
    flt: MapOdomFilter, drive: Drive, stamp_ns: int, published: bool = False
) -> tuple[float, float]:
    """Error of the filter's ``T_map_base`` at ``stamp_ns`` (what planners see) vs truth."""
    pose = flt.pose_at(stamp_ns, published=published)
    return pose_error(pose.T_map_base, drive.T_map_base[drive.index(stamp_ns)])
