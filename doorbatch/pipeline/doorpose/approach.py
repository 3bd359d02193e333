"""Positioning in front of a simulated door (paper 003, Sec. III-C and IV-C).

The robot knows its pose only from wheel odometry (the simulator's noise model, integrated at the odometry
rate, starting at the true start pose). Every control period it senses the door at its *true* pose (camera,
detector boxes, laser), and the estimated goal, relative to the robot, is put into the odometry frame with
the robot's odometry pose:

* ``initial``: the goal is estimated once, at the start pose;
* ``continuous``: it is re-estimated every control period while the odometry pose is farther than
  ``stop_updating_within_m`` from the current goal (and a door box is usable; else the last goal stays).

The polar controller drives the odometry pose to the goal; the run ends when the odometry pose is within
the goal tolerances or after ``max_duration_s``. The error is that of the *true* final pose against the true
goal: |Δx| + |Δy| + |Δθ| (Table II).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorPoseConfig
from doorbatch.errors import PipelineError
from doorbatch.geometry.odometry import Increments
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.pipeline.doorpose.controller import polar_command, polar_error, unicycle_step
from doorbatch.pipeline.doorpose.fusion import estimate_door, to_planar
from doorbatch.sim.door_scene import CAMERA_FRAME, DoorScene, observe
from doorbatch.sim.motion import OdometryNoise, integrate_odometry, sample_odometry_increments
from doorbatch.sim.raycast import RayBuffers

FloatArray = npt.NDArray[np.float64]
GoalUpdating = Literal["initial", "continuous"]


@dataclass(frozen=True)
class ApproachResult:
    """One positioning run: final true and odometry poses, the true goal, the summed error, the path."""

    start: FloatArray  # (3,)
    final_true: FloatArray  # (3,)
    final_odom: FloatArray  # (3,)
    goal_true: FloatArray  # (3,)
    error: float  # |Δx| + |Δy| + |Δθ| of final_true against goal_true
    n_goal_updates: int
    duration_s: float
    reached: bool  # within the tolerances (by odometry) before max_duration_s
    true_path: FloatArray  # (T, 3)
    goals: FloatArray  # (T, 3) the goal in use at each control period (odometry frame)


def summed_pose_error(pose: FloatArray, truth: FloatArray) -> float:
    """|x − x*| + |y − y*| + |wrap(θ − θ*)| (paper 003, Sec. IV-B/C)."""
    return float(abs(pose[0] - truth[0]) + abs(pose[1] - truth[1]) + abs(float(wrap_angle(pose[2] - truth[2]))))


def _estimate_goal(door_scene: DoorScene, true_pose: FloatArray, odom_pose: FloatArray, config: DoorPoseConfig,
                   rng: np.random.Generator, buffers: RayBuffers) -> FloatArray | None:
    obs = observe(door_scene, true_pose, rng, buffers)
    door = estimate_door(door_scene.camera, obs.detections, obs.points_cam, config, rng)
    if door is None:
        return None
    cam_to_base = door_scene.tf.lookup("base_link", CAMERA_FRAME, 0)
    return to_planar(door, cam_to_base, odom_pose).goal


def _drive(true_pose: FloatArray, odom_pose: FloatArray, v: float, w: float, dt: float, substeps: int,
           noise: OdometryNoise, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Move the true pose along the commanded arc in ``substeps`` odometry periods; the odometry integrates
    noisy increments (δrot1 = δrot2 = ω·h/2, δtrans = v·h, signed for backing up)."""
    h = dt / substeps
    for _ in range(substeps):
        true_pose = unicycle_step(true_pose, v, w, h)
    half = np.full(substeps, w * h / 2)
    rep = sample_odometry_increments(Increments(half, np.full(substeps, v * h), half.copy()), noise, rng)
    x, y, yaw = integrate_odometry(float(odom_pose[0]), float(odom_pose[1]), float(odom_pose[2]), rep)
    return true_pose, np.array([x[-1], y[-1], yaw[-1]])


def simulate_approach(door_scene: DoorScene, start: FloatArray, config: DoorPoseConfig, noise: OdometryNoise,
                      rng: np.random.Generator, updating: GoalUpdating | None = None,
                      odometry_rate_hz: float = 50.0) -> ApproachResult:
    """Drive from ``start`` (true pose, map frame) to the goal in front of the door (module docstring).

    Raises:
        PipelineError: no door estimate from the start pose.
    """
    mode = updating or config.goal_updating
    buffers = RayBuffers()
    dt = 1.0 / config.control_rate_hz
    substeps = max(1, round(odometry_rate_hz * dt))
    true_pose = np.asarray(start, dtype=np.float64).copy()
    odom = true_pose.copy()
    goal = _estimate_goal(door_scene, true_pose, odom, config, rng, buffers)
    if goal is None:
        raise PipelineError(f"no door estimate from the start pose {np.round(start, 3).tolist()}")
    updates, path, goals = 1, [true_pose], [goal]
    tol_yaw = math.radians(config.goal_tolerance_deg)
    steps = math.ceil(config.max_duration_s / dt)
    reached = False
    for _ in range(steps):
        if mode == "continuous" and math.hypot(*(odom[:2] - goal[:2])) > config.stop_updating_within_m:
            new = _estimate_goal(door_scene, true_pose, odom, config, rng, buffers)
            if new is not None:
                goal, updates = new, updates + 1
        rho, _, _, _ = polar_error(odom, goal)
        if rho < config.goal_tolerance_m and abs(float(wrap_angle(odom[2] - goal[2]))) < tol_yaw:
            reached = True
            break
        cmd = polar_command(odom, goal, config)
        true_pose, odom = _drive(true_pose, odom, cmd.v_mps, cmd.w_rps, dt, substeps, noise, rng)
        path.append(true_pose)
        goals.append(goal)
    truth = door_scene.true_goal(config.goal_offset_m)
    return ApproachResult(np.asarray(start, dtype=np.float64), true_pose, odom, truth,
                          summed_pose_error(true_pose, truth), updates, (len(path) - 1) * dt, reached,
                          np.array(path), np.array(goals))
