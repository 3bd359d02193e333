"""Siegwart's polar positioning law: the error coordinates on known poses, and convergence of a noise-free
unicycle from start poses around the goal (forward and backing up)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from doorbatch.config import DoorPoseConfig
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.pipeline.doorpose.controller import polar_command, polar_error, unicycle_step


def test_polar_error_of_known_poses() -> None:
    goal = np.array([1.0, 2.0, math.pi / 2])
    # 1 m straight behind the goal (in its frame: x = −1), already facing the goal's heading
    rho, alpha, beta, backward = polar_error(np.array([1.0, 1.0, math.pi / 2]), goal)
    assert (rho, alpha, beta, backward) == pytest.approx((1.0, 0.0, 0.0, False))
    # 1 m behind and 1 m right of the goal, facing the goal's heading: the goal lies 45° to the left
    rho, alpha, beta, backward = polar_error(np.array([2.0, 1.0, math.pi / 2]), goal)
    assert (rho, alpha, beta, backward) == pytest.approx((math.sqrt(2.0), math.pi / 4, -math.pi / 4, False))
    # 1 m past the goal facing its heading: back up straight (α = β = 0 for the turned robot)
    assert polar_error(np.array([1.0, 3.0, math.pi / 2]), goal) == pytest.approx((1.0, 0.0, 0.0, True))


@pytest.mark.parametrize(("pose", "binding"), [
    ((0.0, -3.0, 1.2), "linear"),  # 3 m away: k_rho·ρ = 9 m/s against 0.3, ω 2.97 rad/s against 1
    ((0.0, -0.3, 0.3), "angular"),  # 0.3 m away, turned 73° from the goal: ω 10.2 rad/s against 1, v 0.9 against 0.3
])
def test_command_respects_the_speed_limits_and_keeps_curvature(pose: tuple[float, float, float],
                                                                binding: str) -> None:
    """The command is scaled down as a whole until the tighter limit holds with equality: the same arc, slower."""
    cfg = DoorPoseConfig()
    cmd = polar_command(np.array(pose), np.array([0.0, 0.0, math.pi / 2]), cfg)
    raw_v = cfg.k_rho * cmd.rho_m
    raw_w = cfg.k_alpha * cmd.alpha_rad + cfg.k_beta * cmd.beta_rad
    assert abs(cmd.v_mps) <= cfg.max_linear_mps + 1e-12 and abs(cmd.w_rps) <= cfg.max_angular_rps + 1e-12
    if binding == "linear":
        assert abs(cmd.v_mps) == pytest.approx(cfg.max_linear_mps) and abs(cmd.w_rps) < cfg.max_angular_rps
    else:
        assert abs(cmd.w_rps) == pytest.approx(cfg.max_angular_rps) and abs(cmd.v_mps) < cfg.max_linear_mps
    assert cmd.v_mps > 0.0  # the goal lies ahead: forward
    assert cmd.w_rps / cmd.v_mps == pytest.approx(raw_w / raw_v)


def test_unicycle_arc_is_exact() -> None:
    # a quarter circle of radius 1 m, counter-clockwise from the origin heading +x
    end = unicycle_step(np.zeros(3), math.pi / 2, math.pi / 2, 1.0)
    np.testing.assert_allclose(end, [1.0, 1.0, math.pi / 2], atol=1e-12)


@pytest.mark.parametrize("start", [(-0.8, -2.5, 1.3), (0.6, -1.6, 2.0), (0.0, -3.0, math.pi / 2),
                                   (0.3, 0.4, math.pi / 2), (-1.0, -1.0, 0.0)])
def test_noise_free_robot_reaches_the_goal(start: tuple[float, float, float]) -> None:
    cfg = DoorPoseConfig()
    goal = np.array([0.0, -0.5, math.pi / 2])
    pose = np.array(start)
    for _ in range(int(cfg.max_duration_s * cfg.control_rate_hz)):
        cmd = polar_command(pose, goal, cfg)
        pose = unicycle_step(pose, cmd.v_mps, cmd.w_rps, 1.0 / cfg.control_rate_hz)
    assert math.hypot(*(pose[:2] - goal[:2])) < 0.01
    assert abs(float(wrap_angle(pose[2] - goal[2]))) < math.radians(1.0)
