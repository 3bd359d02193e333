"""Differential-drive motion: waypoint paths with bounded velocities, and noisy, biased wheel odometry.

Path. A path through waypoints is a chain of motion primitives: straight lines, circular fillets at
corners (radius ``corner_radius_m``, shrunk to fit, for turns up to ``max_fillet_turn``), and turns in
place where the robot has to stop (sharper corners, the start, a U-turn). Lines follow a trapezoidal speed
profile between their boundary speeds (0 at stops, the fillet speed v_arc = min(v_max, ω_max·r) at
fillets); boundary speeds are lowered in a forward and a backward pass so that every line can reach them
with the acceleration bound (|v̇| ≤ a_max). Turns in place follow the same profile in ω (|ω| ≤ ω_max,
|ω̇| ≤ α_max). Poses are closed-form functions of time, so any sensor can sample them at its own stamps.

Odometry (Thrun, Burgard, Fox: Probabilistic Robotics, Table 5.6, sample_motion_model_odometry). Each
true increment between consecutive odometry stamps is decomposed into (δrot1, δtrans, δrot2) and
reported as

    δ̂rot1  = δrot1 + ε1,                    ε1 ~ N(0, α1 r1² + α2 δtrans²)
    δ̂trans = (1 + k) δtrans + ε2,           ε2 ~ N(0, α3 δtrans² + α4 (r1² + r2²))
    δ̂rot2  = δrot2 + c δtrans + ε3,        ε3 ~ N(0, α1 r2² + α2 δtrans²)

with a systematic scale error k (``scale_error``) and a yaw drift c per metre driven (``yaw_drift_rad_per_m``);
the α's are per odometry step (the model's variances, not standard deviations, as in the book and AMCL), and
r = min(|δrot|, π − |δrot|) as in Nav2 AMCL and the localizers' model: a step backwards (δrot1 ≈ ±π) is
no noisier than one forwards (with δrot itself in the variances it drew heading errors of ~90° on 10 cm
creeps backwards, which no wheel odometry makes).
The reported increments are integrated into the odometry pose, which therefore drifts without bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import numpy.typing as npt

# The increment decomposition is shared with the localizers' motion model (re-exported for the simulator's callers).
from doorbatch.geometry.odometry import Increments as Increments
from doorbatch.geometry.odometry import increment_variances
from doorbatch.geometry.odometry import odometry_increments as odometry_increments
from doorbatch.geometry.rotations import wrap_angle

FloatArray = npt.NDArray[np.float64]

# Waypoints closer than this (m) are merged; turns smaller than this (rad) need no corner.
_EPS_M = 1e-9
_EPS_RAD = 1e-9


class PrimitiveKind(IntEnum):
    """Kinds of motion primitive."""

    DWELL = 0  # standing still
    MOVE = 1  # line (curvature 0) or arc; progress s is arc length (m)
    ROTATE = 2  # turn in place; progress s is |Δθ| (rad), direction in ``sign``


@dataclass(frozen=True)
class MotionLimits:
    """Bounds of a differential-drive robot."""

    max_speed_mps: float
    max_accel_mps2: float
    max_yaw_rate_rps: float
    max_yaw_accel_rps2: float
    corner_radius_m: float
    max_fillet_turn_rad: float


@dataclass(frozen=True)
class Trajectory:
    """M motion primitives back to back in time, as arrays; evaluate with :func:`sample_trajectory`."""

    t_start_s: FloatArray  # (M,)
    duration_s: FloatArray  # (M,)
    kind: npt.NDArray[np.int8]  # (M,) PrimitiveKind
    x0: FloatArray  # (M,) start pose
    y0: FloatArray
    yaw0: FloatArray
    curvature: FloatArray  # (M,) 1/m, MOVE only
    sign: FloatArray  # (M,) ROTATE direction (+1 CCW)
    length: FloatArray  # (M,) total progress (m or rad)
    v0: FloatArray  # (M,) profile: boundary speeds, peak speed, acceleration, phase durations
    v1: FloatArray
    v_peak: FloatArray
    accel: FloatArray
    t_acc: FloatArray
    t_cruise: FloatArray

    @property
    def end_time_s(self) -> float:
        """Time at which the last primitive ends."""
        return float(self.t_start_s[-1] + self.duration_s[-1]) if self.t_start_s.size else 0.0


@dataclass(frozen=True)
class PoseSamples:
    """Poses and body twist at K times."""

    t_s: FloatArray
    x: FloatArray
    y: FloatArray
    yaw: FloatArray
    v_mps: FloatArray
    w_rps: FloatArray


@dataclass(frozen=True)
class OdometryNoise:
    """Odometry motion model parameters (see the module docstring)."""

    alpha1: float  # rad²/rad² : rotation noise from rotation
    alpha2: float  # rad²/m²   : rotation noise from translation
    alpha3: float  # m²/m²     : translation noise from translation
    alpha4: float  # m²/rad²   : translation noise from rotation
    scale_error: float = 0.0  # fraction: reported distance = (1 + k)·true distance
    yaw_drift_rad_per_m: float = 0.0  # systematic heading error per metre driven


# --------------------------------------------------------------------------------------------- profiles


def _profile(length: float, v0: float, v1: float, vmax: float, accel: float
             ) -> tuple[float, float, float, float]:
    """Trapezoidal profile over ``length`` from speed v0 to v1: (v_peak, t_acc, t_cruise, duration).

    With enough room the speed ramps v0→v_max, cruises, ramps v_max→v1; otherwise it peaks at
    v_p = √(a·L + (v0² + v1²)/2), where the two ramps meet.
    """
    if length <= 0.0:
        return max(v0, v1), 0.0, 0.0, 0.0
    d_acc = (vmax**2 - v0**2) / (2 * accel)
    d_dec = (vmax**2 - v1**2) / (2 * accel)
    if d_acc + d_dec <= length:
        v_peak, t_cruise = vmax, (length - d_acc - d_dec) / vmax
    else:
        v_peak = math.sqrt(max(accel * length + (v0**2 + v1**2) / 2, max(v0, v1) ** 2))
        t_cruise = 0.0
    t_acc = (v_peak - v0) / accel
    t_dec = (v_peak - v1) / accel
    return v_peak, t_acc, t_cruise, t_acc + t_cruise + t_dec


def _progress(tau: FloatArray, v0: FloatArray, v_peak: FloatArray, accel: FloatArray, t_acc: FloatArray,
              t_cruise: FloatArray, length: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Progress s(τ) and speed v(τ) of trapezoidal profiles (vectorized over samples)."""
    t2 = tau - t_acc
    t3 = t2 - t_cruise
    d_acc = v0 * t_acc + 0.5 * accel * t_acc**2
    s = np.where(
        tau < t_acc,
        v0 * tau + 0.5 * accel * tau**2,
        np.where(t2 < t_cruise, d_acc + v_peak * t2, d_acc + v_peak * t_cruise + v_peak * t3 - 0.5 * accel * t3**2),
    )
    v = np.where(tau < t_acc, v0 + accel * tau, np.where(t2 < t_cruise, v_peak, v_peak - accel * t3))
    return np.clip(s, 0.0, length), np.maximum(v, 0.0)


# --------------------------------------------------------------------------------------------- planning


class _Builder:
    """Accumulates primitives (a plain list; paths have tens of primitives)."""

    def __init__(self, x: float, y: float, yaw: float, t: float = 0.0) -> None:
        self.rows: list[tuple[float, ...]] = []
        self.x, self.y, self.yaw, self.t = x, y, yaw, t

    def _add(self, duration: float, kind: PrimitiveKind, curvature: float, sign: float, length: float,
             v0: float, v1: float, v_peak: float, accel: float, t_acc: float, t_cruise: float) -> None:
        if duration <= 0.0:
            return
        self.rows.append((self.t, duration, float(kind), self.x, self.y, self.yaw, curvature, sign, length,
                          v0, v1, v_peak, accel, t_acc, t_cruise))
        self.t += duration

    def dwell(self, duration: float) -> None:
        self._add(duration, PrimitiveKind.DWELL, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)

    def rotate_to(self, yaw: float, limits: MotionLimits) -> None:
        delta = float(wrap_angle(yaw - self.yaw))
        if abs(delta) < _EPS_RAD:
            return
        vp, ta, tc, dur = _profile(abs(delta), 0.0, 0.0, limits.max_yaw_rate_rps, limits.max_yaw_accel_rps2)
        self._add(dur, PrimitiveKind.ROTATE, 0.0, math.copysign(1.0, delta), abs(delta), 0.0, 0.0, vp,
                  limits.max_yaw_accel_rps2, ta, tc)
        self.yaw = float(wrap_angle(self.yaw + delta))

    def move(self, length: float, curvature: float, v0: float, v1: float, limits: MotionLimits) -> None:
        if length <= _EPS_M:
            return
        if curvature == 0.0:
            vp, ta, tc, dur = _profile(length, v0, v1, limits.max_speed_mps, limits.max_accel_mps2)
        else:  # arcs at constant speed v0 (= v1)
            vp, ta, tc, dur = v0, 0.0, length / v0, length / v0
        self._add(dur, PrimitiveKind.MOVE, curvature, 0.0, length, v0, v1, vp, limits.max_accel_mps2, ta, tc)
        end = _move_pose(np.array([self.x]), np.array([self.y]), np.array([self.yaw]), np.array([curvature]),
                         np.array([length]))
        self.x, self.y, self.yaw = float(end[0][0]), float(end[1][0]), float(wrap_angle(end[2][0]))

    def trajectory(self) -> Trajectory:
        data = np.array(self.rows, dtype=np.float64).reshape(-1, 15)
        cols = [data[:, i].copy() for i in range(15)]
        return Trajectory(cols[0], cols[1], cols[2].astype(np.int8), *cols[3:])


def plan_path(builder: _Builder, waypoints: FloatArray, limits: MotionLimits) -> None:
    """Append the motion through ``waypoints`` (N, 2) from the builder's current pose; ends standing still.

    Corners with turn |φ| ≤ max_fillet_turn get a fillet of radius r (tangent length r·tan(|φ|/2) limited
    to half of each adjacent leg); others stop and turn in place.
    """
    pts = [np.array([builder.x, builder.y])]
    for p in np.asarray(waypoints, dtype=np.float64).reshape(-1, 2):
        if np.hypot(*(p - pts[-1])) > _EPS_M:
            pts.append(p)
    if len(pts) < 2:
        return
    legs = np.diff(np.array(pts), axis=0)
    leg_len = np.hypot(legs[:, 0], legs[:, 1])
    heading = np.arctan2(legs[:, 1], legs[:, 0])
    n_corner = len(legs) - 1
    turn = wrap_angle(heading[1:] - heading[:-1]) if n_corner else np.zeros(0)
    tangent = np.zeros(n_corner)
    radius = np.zeros(n_corner)
    speed = np.zeros(n_corner + 2)  # boundary speeds at start, corners, end
    for i in range(n_corner):
        phi = abs(float(turn[i]))
        if phi < _EPS_RAD:
            speed[i + 1] = limits.max_speed_mps
        elif phi <= limits.max_fillet_turn_rad and limits.corner_radius_m > 0.0:
            tan_half = math.tan(phi / 2)
            tangent[i] = min(limits.corner_radius_m * tan_half, 0.5 * leg_len[i], 0.5 * leg_len[i + 1])
            radius[i] = tangent[i] / tan_half
            speed[i + 1] = min(limits.max_speed_mps, limits.max_yaw_rate_rps * radius[i])
    straight = leg_len - np.concatenate([[0.0], tangent]) - np.concatenate([tangent, [0.0]])
    a = limits.max_accel_mps2
    for i in range(len(straight)):  # forward then backward pass: reachable boundary speeds
        speed[i + 1] = min(speed[i + 1], math.sqrt(speed[i] ** 2 + 2 * a * straight[i]))
    for i in reversed(range(len(straight))):
        speed[i] = min(speed[i], math.sqrt(speed[i + 1] ** 2 + 2 * a * straight[i]))
    builder.rotate_to(float(heading[0]), limits)
    for i in range(len(legs)):
        builder.move(float(straight[i]), 0.0, float(speed[i]), float(speed[i + 1]), limits)
        if i == n_corner:
            break
        if radius[i] > 0.0:
            phi = float(turn[i])
            builder.move(radius[i] * abs(phi), math.copysign(1.0 / radius[i], phi), float(speed[i + 1]),
                         float(speed[i + 1]), limits)
            builder.yaw = float(heading[i + 1])  # remove rounding drift of the arc
        else:
            builder.rotate_to(float(heading[i + 1]), limits)
        builder.x, builder.y = float(pts[i + 1][0] + tangent[i] * math.cos(heading[i + 1])), float(
            pts[i + 1][1] + tangent[i] * math.sin(heading[i + 1]))


def new_builder(x: float, y: float, yaw: float) -> _Builder:
    """A primitive builder starting at pose (x, y, yaw) at t = 0."""
    return _Builder(x, y, yaw)


# --------------------------------------------------------------------------------------------- sampling


def _move_pose(x0: FloatArray, y0: FloatArray, yaw0: FloatArray, curvature: FloatArray, s: FloatArray
               ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Pose after arc length s on a path of constant curvature κ (κ = 0: a line).

    The chord has length s·sinc(κs/2) and direction yaw0 + κs/2, which is exact and stable as κ → 0.
    """
    half = 0.5 * curvature * s
    chord = s * np.sinc(half / np.pi)
    direction = yaw0 + half
    return x0 + chord * np.cos(direction), y0 + chord * np.sin(direction), yaw0 + curvature * s


def sample_trajectory(traj: Trajectory, t_s: npt.ArrayLike) -> PoseSamples:
    """Poses and twists at times ``t_s`` (vectorized; before the start and after the end the robot stands)."""
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    idx = np.clip(np.searchsorted(traj.t_start_s, t, side="right") - 1, 0, traj.t_start_s.size - 1)
    tau = np.clip(t - traj.t_start_s[idx], 0.0, traj.duration_s[idx])
    s, v = _progress(tau, traj.v0[idx], traj.v_peak[idx], traj.accel[idx], traj.t_acc[idx], traj.t_cruise[idx],
                     traj.length[idx])
    kind = traj.kind[idx]
    moving = kind == PrimitiveKind.MOVE
    rotating = kind == PrimitiveKind.ROTATE
    s_move = np.where(moving, s, 0.0)
    x, y, yaw = _move_pose(traj.x0[idx], traj.y0[idx], traj.yaw0[idx], traj.curvature[idx], s_move)
    yaw = yaw + np.where(rotating, traj.sign[idx] * s, 0.0)
    v_lin = np.where(moving, v, 0.0)
    w = np.where(moving, traj.curvature[idx] * v, np.where(rotating, traj.sign[idx] * v, 0.0))
    ended = t >= traj.end_time_s
    return PoseSamples(t, x, y, wrap_angle(yaw), np.where(ended, 0.0, v_lin), np.where(ended, 0.0, w))


# --------------------------------------------------------------------------------------------- odometry


def sample_odometry_increments(true: Increments, noise: OdometryNoise, rng: np.random.Generator) -> Increments:
    """Reported increments: true ones with the α-model noise and the systematic bias (module docstring)."""
    tr = true.trans
    var_rot1, var_trans, var_rot2 = increment_variances(true.rot1, tr, true.rot2,
                                                        (noise.alpha1, noise.alpha2, noise.alpha3, noise.alpha4))
    sd_rot1, sd_trans, sd_rot2 = np.sqrt(var_rot1), np.sqrt(var_trans), np.sqrt(var_rot2)
    eps = rng.standard_normal((3, tr.shape[0]))
    return Increments(
        rot1=true.rot1 + sd_rot1 * eps[0],
        trans=(1.0 + noise.scale_error) * tr + sd_trans * eps[1],
        rot2=true.rot2 + noise.yaw_drift_rad_per_m * tr + sd_rot2 * eps[2],
    )


def integrate_odometry(x0: float, y0: float, yaw0: float, inc: Increments) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Poses from a start pose and increments: θ ← θ + δrot1; p ← p + δtrans·(cos θ, sin θ); θ ← θ + δrot2.

    Vectorized with cumulative sums; returns K = len(increments) + 1 poses.
    """
    turn = inc.rot1 + inc.rot2
    yaw_before = yaw0 + np.concatenate([[0.0], np.cumsum(turn)[:-1]]) if turn.size else np.zeros(0)
    heading = yaw_before + inc.rot1
    x = x0 + np.concatenate([[0.0], np.cumsum(inc.trans * np.cos(heading))])
    y = y0 + np.concatenate([[0.0], np.cumsum(inc.trans * np.sin(heading))])
    yaw = yaw0 + np.concatenate([[0.0], np.cumsum(turn)])
    return x, y, wrap_angle(yaw)


def simulate_odometry(truth: PoseSamples, noise: OdometryNoise, rng: np.random.Generator,
                      start: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> PoseSamples:
    """Wheel odometry along sampled truth poses: noisy increments integrated from ``start`` (odom frame).

    The twist is the reported increment over the sampling interval (δ̂trans/Δt, (δ̂rot1 + δ̂rot2)/Δt).
    """
    true = odometry_increments(truth.x, truth.y, truth.yaw)
    rep = sample_odometry_increments(true, noise, rng)
    x, y, yaw = integrate_odometry(*start, rep)
    dt = np.diff(truth.t_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.concatenate([[0.0], np.where(dt > 0, rep.trans / dt, 0.0)])
        w = np.concatenate([[0.0], np.where(dt > 0, (rep.rot1 + rep.rot2) / dt, 0.0)])
    return PoseSamples(truth.t_s, x, y, yaw, v, w)


def drift_poses(poses: npt.ArrayLike, noise: OdometryNoise, rng: np.random.Generator,
                step_m: float | None = None, step_rad: float | None = None) -> FloatArray:
    """Corrupt a pose sequence (N, 3) into drifting wheel odometry with the simulator's odometry model:
    the true increments get the α-noise and the systematic bias, and are integrated from the first pose.

    The α's are per odometry step, so the noise a path gets depends on how finely it is stepped (variance ∝
    step², so one 3 m step draws about √n times the heading noise of n steps covering it). With ``step_m`` and
    ``step_rad`` each increment is first driven as the model decomposes it, in substeps of at most that
    translation and rotation (:func:`_substeps`: turn in place, the chord forwards or backwards, turn in place),
    the model applied per substep, and the odometry returned at the given poses: a thinned log (CARMEN's
    corrected logs hold a pose every 0.5–3 m) then gets the noise of the odometry stream that drove it
    (:func:`doorbatch.sim.simulate.scenario_drift`).
    Without them each given increment is one odometry step.

    DESIGN.md: the CARMEN logs' own odometry equals their corrected poses, so tests of scan matching and
    localization on them need odometry made worse this way (with a fixed seed).
    """
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    keep = np.arange(p.shape[0])
    if (step_m is not None or step_rad is not None) and p.shape[0] > 1:
        p, keep = _substeps(p, step_m or math.inf, step_rad or math.inf)
    rep = sample_odometry_increments(odometry_increments(p[:, 0], p[:, 1], p[:, 2]), noise, rng)
    x, y, yaw = integrate_odometry(float(p[0, 0]), float(p[0, 1]), float(p[0, 2]), rep)
    return np.stack([x, y, yaw], axis=1)[keep]


def _substeps(p: FloatArray, step_m: float, step_rad: float) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    """The poses with each increment driven as the motion model decomposes it, in substeps of at most
    ``step_m`` / ``step_rad``: turn in place by δrot1, drive the chord, turn in place by δrot2 (a chord whose
    bearing is behind the robot is driven backwards, turning by δrot1 − π); and the indices of the given poses
    among them. Interpolating position and heading together instead would make the robot crab sideways, and
    the model would charge every substep the heading-to-bearing angle as a rotation."""
    inc = odometry_increments(p[:, 0], p[:, 1], p[:, 2])
    backwards = np.abs(inc.rot1) > 0.5 * np.pi
    turn1 = np.where(backwards, wrap_angle(inc.rot1 - np.pi), inc.rot1)
    rows: list[FloatArray] = [p[:1]]
    keep = [0]
    for k in range(inc.trans.size):
        x0, y0, yaw0 = p[k]
        heading = yaw0 + turn1[k]
        n1 = math.ceil(abs(turn1[k]) / step_rad)
        n2 = math.ceil(inc.trans[k] / step_m)
        turn2 = wrap_angle(p[k + 1, 2] - heading)
        n3 = math.ceil(abs(turn2) / step_rad)
        f1, f2, f3 = (np.arange(1, n + 1) / n for n in (n1, n2, n3))
        rows.append(np.column_stack([np.full(n1, x0), np.full(n1, y0), yaw0 + f1 * turn1[k]]))
        rows.append(np.column_stack([x0 + f2 * (p[k + 1, 0] - x0), y0 + f2 * (p[k + 1, 1] - y0), np.full(n2, heading)]))
        rows.append(np.column_stack([np.full(n3, p[k + 1, 0]), np.full(n3, p[k + 1, 1]), heading + f3 * turn2]))
        if n1 + n2 + n3 == 0:
            rows.append(p[k + 1 : k + 2])
        keep.append(keep[-1] + max(n1 + n2 + n3, 1))
    fine = np.concatenate(rows)
    fine[:, 2] = wrap_angle(fine[:, 2])
    return fine, np.asarray(keep, dtype=np.int64)
