"""Odometry increments (δrot1, δtrans, δrot2): the decomposition of Probabilistic Robotics, Table 5.6.

Shared by the simulator (which corrupts true increments into wheel odometry) and the localizers' motion
model (which samples particle motion around reported increments). An increment between two poses
(x, y, θ) → (x', y', θ') of one frame (odom) is

    δtrans = |p' − p|,    δrot1 = atan2(y' − y, x' − x) − θ,    δrot2 = θ' − θ − δrot1,

every angle wrapped to (−π, π]. Below a minimal translation the bearing atan2 is meaningless and the motion
is taken as a pure rotation: δrot1 = 0, δrot2 = θ' − θ (Nav2 AMCL uses 0.01 m).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, relative

FloatArray = npt.NDArray[np.float64]

# Nav2 AMCL: "Avoid computing a bearing from two poses that are extremely near each other (in-place rotation)".
MIN_TRANS_FOR_BEARING_M = 0.01


@dataclass(frozen=True)
class Increments:
    """Odometry increments (δrot1, δtrans, δrot2) between consecutive poses, each (K−1,)."""

    rot1: FloatArray
    trans: FloatArray
    rot2: FloatArray


def odometry_increments(x: FloatArray, y: FloatArray, yaw: FloatArray, min_trans_m: float = 1e-9) -> Increments:
    """Decompose consecutive poses into (δrot1, δtrans, δrot2) (Probabilistic Robotics, Table 5.6).

    δtrans = |p' − p|, δrot1 = atan2(Δy, Δx) − θ, δrot2 = θ' − θ − δrot1. Below ``min_trans_m`` the motion
    is a pure rotation: δrot1 = 0, δrot2 = θ' − θ.
    """
    dx, dy = np.diff(x), np.diff(y)
    trans = np.hypot(dx, dy)
    dyaw = wrap_angle(np.diff(yaw))
    rot1 = np.where(trans > min_trans_m, wrap_angle(np.arctan2(dy, dx) - yaw[:-1]), 0.0)
    return Increments(rot1, trans, wrap_angle(dyaw - rot1))


def rotation_noise_magnitude(rot: npt.ArrayLike) -> FloatArray:
    """r = min(|δrot|, π − |δrot|): the rotation the α-model's noise terms scale with (Nav2 AMCL's
    ``DifferentialMotionModel``), so that a step backwards (δrot1 ≈ ±π, δrot2 ≈ ∓π) is no noisier than one
    forwards: wheel odometry's heading error grows with the wheels' differential travel, and a backward step is
    a sign of the bearing, not a half turn of the wheels."""
    a = np.abs(wrap_angle(np.asarray(rot, dtype=np.float64)))
    out: FloatArray = np.minimum(a, np.pi - a)
    return out


def increment_variances(rot1: npt.ArrayLike, trans: npt.ArrayLike, rot2: npt.ArrayLike, alphas: Sequence[float]
                        ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Variances of the α-model's noise on (δrot1, δtrans, δrot2) (Probabilistic Robotics Table 5.6, Nav2 AMCL's
    ``DifferentialMotionModel``): α1 r1² + α2 δtrans², α3 δtrans² + α4 (r1² + r2²), α1 r2² + α2 δtrans², with
    r = :func:`rotation_noise_magnitude` of δrot; ``alphas`` = (α1, α2, α3, α4). The one model of the simulator's
    drift, the localizers' motion model and the scan matcher's prior."""
    a1, a2, a3, a4 = (float(a) for a in alphas)
    tr = np.asarray(trans, dtype=np.float64)
    r1, r2 = rotation_noise_magnitude(rot1), rotation_noise_magnitude(rot2)
    return a1 * r1**2 + a2 * tr**2, a3 * tr**2 + a4 * (r1**2 + r2**2), a1 * r2**2 + a2 * tr**2


def sideways_share(x: npt.ArrayLike, y: npt.ArrayLike, yaw: npt.ArrayLike, step_m: float) -> float:
    """The share of the travel that goes across the heading: Σ δtrans·|sin(δrot1 − Δθ/2)| / Σ δtrans over steps
    between poses at least ``step_m`` apart (each step ends at the first pose ``step_m`` or more from where it
    began, so that the jitter of a slow or standing robot makes no step).

    δrot1 − Δθ/2 is the bearing of the step against the heading halfway along it: 0 (or π, backwards) for any
    arc a differential-drive base can drive, since an arc's chord points along its mid heading; ±π/2 for a
    holonomic base strafing. NaN when no two poses lie ``step_m`` apart.
    """
    px, py, pyaw = (np.asarray(v, dtype=np.float64).ravel() for v in (x, y, yaw))
    keep = [0]
    for i in range(1, len(px)):  # sequential by nature (each step starts where the last ended); once per log
        if math.hypot(px[i] - px[keep[-1]], py[i] - py[keep[-1]]) >= step_m:
            keep.append(i)
    if len(keep) < 2:
        return float("nan")
    inc = odometry_increments(px[keep], py[keep], pyaw[keep])
    dyaw = wrap_angle(inc.rot1 + inc.rot2)
    across = inc.trans * np.abs(np.sin(inc.rot1 - dyaw / 2.0))
    return float(across.sum() / inc.trans.sum())


def sweep_smear_m(sweep_s: float, stamps_ns: npt.ArrayLike, poses: npt.ArrayLike, range_m: float,
                  quantile: float = 0.5) -> float:
    """How far a beam end point at ``range_m`` moves while a laser sweeps for ``sweep_s``: (v + ω·range)·sweep,
    v and ω the ``quantile`` of the speed and turn rate between consecutive ``poses`` (N, 3) at ``stamps_ns``
    (odometry). 0 for a sweep of 0 (time_increment unset) or fewer than two poses."""
    t = np.asarray(stamps_ns, dtype=np.int64)
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if sweep_s <= 0.0 or len(t) < 2:
        return 0.0
    dt = np.diff(t) / 1e9
    ok = dt > 0
    if not ok.any():
        return 0.0
    v = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))[ok] / dt[ok]
    w = np.abs(wrap_angle(np.diff(p[:, 2])))[ok] / dt[ok]
    return float((np.quantile(v, quantile) + np.quantile(w, quantile) * range_m) * sweep_s)


RESTART_WINDOW = 5  # steps on either side whose longest tells how far one message period moves the robot
RESTART_STEP_RATIO = 10.0  # a restart landing off the origin jumps at least this many of the robot's steps


def odometry_jumps(poses: npt.ArrayLike, min_jump_m: float, min_jump_rad: float, at_zero_m: float,
                   restart_steps: float = 0.0) -> npt.NDArray[np.intp]:
    """Indices ``i`` of odometry steps ``i − 1 → i`` no wheel made: a step farther than ``min_jump_m`` or turning
    more than ``min_jump_rad`` that lands near the frame's origin (a driver that restarted, its odometry starting
    again at (0, 0); the heading may come from a compass). Near: within ``at_zero_m``, or within ``restart_steps``
    times the longest of the :data:`RESTART_WINDOW` steps before and after it, for a step :data:`RESTART_STEP_RATIO`
    times that long or more (a restart's first message may come a message period after the driver started again,
    the robot moving: 5–10 mm at 0.5 m/s and 50 Hz). Speed is no
    test: real logs with coarse or synthesized stamps (CARMEN's) show steps of metres in a fifth of a second."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if p.shape[0] < 2:
        return np.zeros(0, dtype=np.intp)
    dist = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
    turn = np.abs(wrap_angle(np.diff(p[:, 2])))
    around = np.maximum(*_steps_around(np.where(dist > min_jump_m, 0.0, dist)))  # a gap's long step tells nothing
    landing = np.hypot(p[1:, 0], p[1:, 1])
    # landing a step or two off the origin: a restart only where the step is no motion of this robot's (ten of its
    # steps and more; orebro's coarse 0.3-0.5 m steps pass within a metre of its origin, and are none)
    moving_restart = (landing <= restart_steps * around) & (dist > RESTART_STEP_RATIO * around)
    at_zero = (landing <= at_zero_m) | moving_restart
    return np.flatnonzero(at_zero & ((dist > min_jump_m) | (turn > min_jump_rad))) + 1


TELEPORT_MAX_PERIODS = 3.0  # a step that took longer than this many message periods is a gap: motion unseen, kept


def odometry_teleports(stamps_s: npt.ArrayLike, poses: npt.ArrayLike, min_jump_m: float, steps_ratio: float
                       ) -> npt.NDArray[np.intp]:
    """Indices ``i`` of odometry steps ``i − 1 → i`` that put the robot elsewhere instead of moving it: farther than
    ``min_jump_m`` and ``steps_ratio`` times the longest of the :data:`RESTART_WINDOW` steps before and after it,
    within :data:`TELEPORT_MAX_PERIODS` median message periods (a pose set from outside: robot_localization's
    set_pose, a driver's fault; no base brakes from ten times its speed in one period). A step over a longer time is
    a gap in the messages (motion unseen, kept); a step among steps as long is motion (orebro's coarse 0.3–3.3 m
    steps come in runs), and so is one after steps of nothing while those after it move (an odometry that froze and
    caught up). A set pose that turns without moving is not found (a turn in one period can be real)."""
    t = np.asarray(stamps_s, dtype=np.float64).reshape(-1)
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if p.shape[0] < 2 or steps_ratio <= 0.0:
        return np.zeros(0, dtype=np.intp)
    dist = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
    dt = np.diff(t)
    if not (dt > 0.0).any():  # no stamps to tell a set pose from a gap by
        return np.zeros(0, dtype=np.intp)
    sudden = dt <= TELEPORT_MAX_PERIODS * float(np.median(dt[dt > 0.0]))
    # an odometry that stood frozen while the robot moved on (a stalled encoder link catching up in one step) is no
    # set pose: the steps before are nothing, those after are motion
    before, after = _steps_around(dist)
    frozen = (before == 0.0) & (after > 0.0)
    jumps = sudden & ~frozen & (dist > min_jump_m) & (dist > steps_ratio * np.maximum(before, after))
    return np.flatnonzero(jumps) + 1


def _steps_around(dist: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(K,) each, the longest of the :data:`RESTART_WINDOW` steps before and the longest of those after each of
    ``dist`` (not itself): how far one message period moves the robot there."""
    padded = np.pad(dist, RESTART_WINDOW)
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * RESTART_WINDOW + 1)
    before: FloatArray = windows[:, :RESTART_WINDOW].max(axis=1)
    after: FloatArray = windows[:, RESTART_WINDOW + 1:].max(axis=1)
    return before, after


def bridged_jumps(poses: npt.ArrayLike, jumps: npt.ArrayLike) -> FloatArray:
    """The odometry with each jump taken out: from a jump at ``i`` on, every pose is moved rigidly so that pose
    ``i`` equals pose ``i − 1`` (p'_k = p'_{i−1} ⊕ p_i⁻¹ ⊕ p_k), the motion after the jump kept as it was
    reported. The step across the jump becomes no motion (one message period lost: a choice, as the motion in
    it is unknown)."""
    out = np.array(poses, dtype=np.float64).reshape(-1, 3)
    for i in np.asarray(jumps, dtype=np.intp):
        out[i:] = compose(out[i - 1], relative(out[i], out[i:]))
    return out


def integrated_twist(stamps_s: npt.ArrayLike, vx: npt.ArrayLike, vy: npt.ArrayLike, wz: npt.ArrayLike) -> FloatArray:
    """Poses (x, y, yaw) from (0, 0, 0) by integrating body-frame velocities, each held until the next message:
    over dt_k = t_{k+1} − t_k the heading turns by wz_k·dt_k and the base moves by R(yaw_k + wz_k·dt_k/2)·(vx_k,
    vy_k)·dt_k (the midpoint heading: exact for a constant-curvature arc to second order). A base whose odometry
    fills only ``twist`` (its ``pose`` left at 0) is read so."""
    t = np.asarray(stamps_s, dtype=np.float64)
    dt = np.diff(t)
    v_x, v_y, w = (np.asarray(a, dtype=np.float64)[:-1] for a in (vx, vy, wz))
    yaw = np.concatenate([[0.0], np.cumsum(w * dt)])
    mid = yaw[:-1] + 0.5 * w * dt
    dx = (v_x * np.cos(mid) - v_y * np.sin(mid)) * dt
    dy = (v_x * np.sin(mid) + v_y * np.cos(mid)) * dt
    return np.column_stack([np.concatenate([[0.0], np.cumsum(dx)]), np.concatenate([[0.0], np.cumsum(dy)]),
                            wrap_angle(yaw)])
