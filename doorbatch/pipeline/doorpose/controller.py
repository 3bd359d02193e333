"""Differential-drive positioning controller in polar coordinates (Siegwart, Nourbakhsh & Scaramuzza,
*Introduction to Autonomous Mobile Robots*, Sec. 3.6.2.4; paper 003, Sec. III-C).

With the error expressed in the goal frame (goal at the origin, heading 0), robot at (Δx, Δy) = −p and
heading θ:

    ρ = √(Δx² + Δy²),  α = −θ + atan2(Δy, Δx),  β = −θ − α
    v = k_ρ·ρ,  ω = k_α·α + k_β·β

locally exponentially stable for k_ρ > 0, k_β < 0, k_α − k_ρ > 0. When the goal lies behind the robot
(|α| > π/2) the robot backs up: the same law for the robot and the goal both turned by π (so Δx, Δy
change sign and θ does not), with v = −k_ρ·ρ. The command
is scaled down (v and ω together, so the path's curvature is kept) to the speed limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorPoseConfig
from doorbatch.geometry.rotations import wrap_angle

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PolarCommand:
    """A velocity command and the polar error it came from."""

    v_mps: float
    w_rps: float
    rho_m: float
    alpha_rad: float
    beta_rad: float


def polar_error(pose: FloatArray, goal: FloatArray) -> tuple[float, float, float, bool]:
    """(ρ, α, β, backward) of a robot pose (x, y, θ) toward a goal pose, in the goal frame."""
    gx, gy, gth = (float(v) for v in goal)
    c, s = math.cos(gth), math.sin(gth)
    dx, dy = gx - float(pose[0]), gy - float(pose[1])
    ex, ey = c * dx + s * dy, -s * dx + c * dy  # (Δx, Δy) in the goal frame
    theta = float(wrap_angle(float(pose[2]) - gth))
    rho = math.hypot(ex, ey)
    alpha = float(wrap_angle(-theta + math.atan2(ey, ex)))
    backward = abs(alpha) > math.pi / 2
    if backward:  # a robot turned by π driving forward to the goal turned by π: (Δx, Δy) → (−Δx, −Δy)
        alpha = float(wrap_angle(-theta + math.atan2(-ey, -ex)))
    return rho, alpha, float(wrap_angle(-theta - alpha)), backward


def polar_command(pose: FloatArray, goal: FloatArray, config: DoorPoseConfig) -> PolarCommand:
    """v = ±k_ρ·ρ, ω = k_α·α + k_β·β, scaled into |v| ≤ max_linear_mps, |ω| ≤ max_angular_rps."""
    rho, alpha, beta, backward = polar_error(pose, goal)
    v = (-1.0 if backward else 1.0) * config.k_rho * rho
    w = config.k_alpha * alpha + config.k_beta * beta
    scale = max(abs(v) / config.max_linear_mps, abs(w) / config.max_angular_rps, 1.0)
    return PolarCommand(v / scale, w / scale, rho, alpha, beta)


def unicycle_step(pose: FloatArray, v_mps: float, w_rps: float, dt_s: float) -> FloatArray:
    """Exact unicycle motion over dt with constant (v, ω): an arc, or a straight line for ω = 0."""
    x, y, th = (float(p) for p in pose)
    dth = w_rps * dt_s
    if abs(dth) < 1e-9:
        return np.array([x + v_mps * dt_s * math.cos(th), y + v_mps * dt_s * math.sin(th), th])
    r = v_mps / w_rps
    return np.array([x + r * (math.sin(th + dth) - math.sin(th)), y - r * (math.cos(th + dth) - math.cos(th)),
                     float(wrap_angle(th + dth))])
