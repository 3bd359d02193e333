"""Robot motion: bounded differential-drive paths through waypoints; odometry noise with the model's
statistics (Probabilistic Robotics, sample_motion_model_odometry) plus systematic bias."""

from __future__ import annotations

import math

import numpy as np
import pytest

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.sim.motion import (
    Increments,
    MotionLimits,
    OdometryNoise,
    drift_poses,
    integrate_odometry,
    new_builder,
    odometry_increments,
    plan_path,
    sample_odometry_increments,
    sample_trajectory,
    simulate_odometry,
)

LIMITS = MotionLimits(max_speed_mps=0.8, max_accel_mps2=0.5, max_yaw_rate_rps=math.radians(60),
                      max_yaw_accel_rps2=math.radians(120), corner_radius_m=0.6,
                      max_fillet_turn_rad=math.radians(100))
WAYPOINTS = np.array([[0.0, 0.0], [6.0, 0.0], [6.5, -0.5], [8.0, -0.5], [8.0, 3.0], [8.0, 0.0], [12.0, 0.0]])


def _plan() -> tuple[object, np.ndarray]:
    builder = new_builder(0.0, 0.0, 0.0)
    builder.dwell(1.0)
    plan_path(builder, WAYPOINTS, LIMITS)
    traj = builder.trajectory()
    t = np.arange(0.0, traj.end_time_s + 1.0, 0.002)
    return traj, t


def test_path_respects_speed_turn_rate_and_acceleration_bounds() -> None:
    traj, t = _plan()
    p = sample_trajectory(traj, t)  # type: ignore[arg-type]
    assert p.v_mps.max() <= LIMITS.max_speed_mps + 1e-9 and p.v_mps.min() >= 0.0
    assert np.abs(p.w_rps).max() <= LIMITS.max_yaw_rate_rps + 1e-9
    # finite differences of the pose agree with the reported twist (away from the instants where a line
    # meets a fillet: curvature, and so ω, steps there) ...
    dt = np.diff(t)
    speed = np.hypot(np.diff(p.x), np.diff(p.y)) / dt
    inside = np.searchsorted(traj.t_start_s, t[:-1], "right") == np.searchsorted(traj.t_start_s, t[1:], "right")  # type: ignore[attr-defined]
    assert inside.mean() > 0.99
    np.testing.assert_allclose(speed[inside], 0.5 * (p.v_mps[1:] + p.v_mps[:-1])[inside], atol=2e-3)
    np.testing.assert_allclose((wrap_angle(np.diff(p.yaw)) / dt)[inside], 0.5 * (p.w_rps[1:] + p.w_rps[:-1])[inside],
                               atol=2e-3)
    # ... the speed changes no faster than the acceleration bound, and motion is along the heading
    assert np.abs(np.diff(p.v_mps) / dt).max() <= LIMITS.max_accel_mps2 + 1e-6
    heading = np.arctan2(np.diff(p.y), np.diff(p.x))
    moving = speed > 1e-3
    assert np.abs(wrap_angle(heading[moving] - p.yaw[:-1][moving])).max() < 0.01


def test_path_passes_every_waypoint_or_its_fillet_and_ends_at_the_last() -> None:
    traj, t = _plan()
    p = sample_trajectory(traj, t)  # type: ignore[arg-type]
    xy = np.stack([p.x, p.y], axis=1)
    np.testing.assert_allclose(xy[-1], WAYPOINTS[-1], atol=1e-9)
    for w in WAYPOINTS:
        # a fillet of radius r on a turn φ passes a corner at r(1/cos(φ/2) − 1) ≤ r·(√2 … ) < 0.6 m here
        assert np.min(np.hypot(*(xy - w).T)) < 0.35
    # the U-turn at (8, 3) is a stop and a turn in place: the robot stands exactly there
    assert np.min(np.hypot(*(xy - [8.0, 3.0]).T)) < 1e-9


def test_noise_free_odometry_integrates_back_to_the_truth() -> None:
    traj, t = _plan()
    p = sample_trajectory(traj, t[::10])  # type: ignore[arg-type]
    inc = odometry_increments(p.x, p.y, p.yaw)
    x, y, yaw = integrate_odometry(float(p.x[0]), float(p.y[0]), float(p.yaw[0]), inc)
    np.testing.assert_allclose(x, p.x, atol=1e-9)
    np.testing.assert_allclose(y, p.y, atol=1e-9)
    np.testing.assert_allclose(wrap_angle(yaw - p.yaw), 0.0, atol=1e-9)


@pytest.mark.parametrize(("rot1", "trans", "rot2"), [(0.01, 0.02, -0.005), (0.0, 0.015, 0.0), (0.2, 0.0, 0.0)])
def test_odometry_increment_errors_have_the_model_statistics(rot1: float, trans: float, rot2: float) -> None:
    noise = OdometryNoise(alpha1=0.05, alpha2=0.02, alpha3=0.04, alpha4=0.01, scale_error=0.02,
                          yaw_drift_rad_per_m=0.01)
    n = 400_000
    true = Increments(np.full(n, rot1), np.full(n, trans), np.full(n, rot2))
    rep = sample_odometry_increments(true, noise, np.random.default_rng(42))
    err1, err_t, err2 = rep.rot1 - rot1, rep.trans - trans, rep.rot2 - rot2
    # the model: means (bias) and standard deviations
    sd1 = math.sqrt(noise.alpha1 * rot1**2 + noise.alpha2 * trans**2)
    sd_t = math.sqrt(noise.alpha3 * trans**2 + noise.alpha4 * (rot1**2 + rot2**2))
    sd2 = math.sqrt(noise.alpha1 * rot2**2 + noise.alpha2 * trans**2)
    mean_t, mean2 = noise.scale_error * trans, noise.yaw_drift_rad_per_m * trans
    for err, sd, mean in ((err1, sd1, 0.0), (err_t, sd_t, mean_t), (err2, sd2, mean2)):
        if sd == 0.0:
            np.testing.assert_allclose(err, mean, atol=1e-15)
            continue
        assert err.std() == pytest.approx(sd, rel=0.10)
        if mean != 0.0:
            assert err.mean() == pytest.approx(mean, rel=0.10)
        else:  # zero-mean: within 5 standard errors
            assert abs(err.mean()) < 5 * sd / math.sqrt(n)


def test_a_step_backwards_is_no_noisier_than_the_same_step_forwards() -> None:
    """A 10 cm creep backwards decomposes into δrot1 ≈ π, δrot2 ≈ −π; its heading error must be that of the
    10 cm step forwards (wheel travel, not the bearing's sign, makes odometry noise; Nav2 AMCL folds the same
    way), not σ = √α1·π (about 25° at α1 = 0.06)."""
    noise = OdometryNoise(alpha1=0.06, alpha2=0.02, alpha3=0.04, alpha4=0.01)
    n = 200_000
    forward = odometry_increments(np.array([0.0, 0.1]), np.array([0.0, 0.0]), np.array([0.0, 0.02]))
    backward = odometry_increments(np.array([0.0, -0.1]), np.array([0.0, 0.0]), np.array([0.0, 0.02]))
    assert abs(backward.rot1[0]) == pytest.approx(math.pi)
    turns = []
    for inc in (forward, backward):
        true = Increments(np.repeat(inc.rot1, n), np.repeat(inc.trans, n), np.repeat(inc.rot2, n))
        rep = sample_odometry_increments(true, noise, np.random.default_rng(3))
        turns.append(wrap_angle(rep.rot1 + rep.rot2 - inc.rot1[0] - inc.rot2[0]))
    assert np.std(turns[1]) == pytest.approx(np.std(turns[0]), rel=0.02)
    assert np.std(turns[1]) < math.radians(3.0)


def test_odometry_along_a_path_drifts_with_the_systematic_bias() -> None:
    traj, t = _plan()
    truth = sample_trajectory(traj, t[::10])  # type: ignore[arg-type]  # 50 Hz
    biased = OdometryNoise(0.0, 0.0, 0.0, 0.0, scale_error=0.05, yaw_drift_rad_per_m=0.0)
    odom = simulate_odometry(truth, biased, np.random.default_rng(0),
                             start=(float(truth.x[0]), float(truth.y[0]), float(truth.yaw[0])))
    driven = np.hypot(np.diff(truth.x), np.diff(truth.y)).sum()
    odom_driven = np.hypot(np.diff(odom.x), np.diff(odom.y)).sum()
    assert odom_driven == pytest.approx(1.05 * driven, rel=1e-9)
    noisy = simulate_odometry(truth, OdometryNoise(0.02, 0.005, 0.02, 0.001, 0.015, 0.003),
                              np.random.default_rng(1))
    assert noisy.x[0] == 0.0 and noisy.y[0] == 0.0  # odom starts at the origin, like a robot that just booted


def _arc_path(step_m: float) -> np.ndarray:
    """An 8 m path (a straight 4 m, a quarter circle of radius 2.5 m) as poses every ``step_m``."""
    s = np.arange(0.0, 4.0 + 2.5 * np.pi / 2 + 1e-9, step_m)
    arc = np.clip(s - 4.0, 0.0, None) / 2.5
    x = np.where(s <= 4.0, s, 4.0 + 2.5 * np.sin(arc))
    y = np.where(s <= 4.0, 0.0, 2.5 * (1.0 - np.cos(arc)))
    return np.column_stack([x, y, arc])


def test_a_thinned_path_drifts_like_the_odometry_stream_that_drove_it() -> None:
    """The α's are per odometry step: poses 1 m apart corrupted in 2 cm / 1.2° substeps drift like the same
    path given every 2 cm, not like eight 1 m steps (√50 times the heading noise)."""
    noise = OdometryNoise(alpha1=0.02, alpha2=0.005, alpha3=0.02, alpha4=0.001)
    fine, coarse = _arc_path(0.02), _arc_path(1.0)
    step = dict(step_m=0.02, step_rad=math.radians(1.2))

    def end_yaw_std(poses: np.ndarray, **kw: float) -> float:
        ends = [drift_poses(poses, noise, np.random.default_rng(seed), **kw)[-1, 2] - poses[-1, 2]
                for seed in range(400)]
        return float(np.std(wrap_angle(np.asarray(ends))))

    reference, substepped, whole = end_yaw_std(fine), end_yaw_std(coarse, **step), end_yaw_std(coarse)
    assert substepped == pytest.approx(reference, rel=0.2)
    assert whole > 3.0 * reference


def test_substeps_without_noise_return_the_poses_and_drive_a_backward_step_backwards() -> None:
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.2, 0.3], [0.9, 0.2, 0.3], [0.9, 0.2, -1.0], [0.9, 0.2, -1.0]])
    exact = drift_poses(poses, OdometryNoise(0.0, 0.0, 0.0, 0.0), np.random.default_rng(0), step_m=0.02,
                        step_rad=0.02)
    np.testing.assert_allclose(exact, poses, atol=1e-9)
    noise = OdometryNoise(alpha1=0.05, alpha2=0.0, alpha3=0.0, alpha4=0.0)  # rotation noise only
    back = np.array([[0.0, 0.0, 0.0], [-0.1, 0.0, 0.0]])  # 10 cm straight back: no turn to charge
    moved = drift_poses(back, noise, np.random.default_rng(1), step_m=0.02, step_rad=0.02)
    np.testing.assert_allclose(moved, back, atol=1e-9)

