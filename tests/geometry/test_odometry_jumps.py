"""Odometry jumps no wheel made (a driver restarting at zero): found and taken out."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.odometry import bridged_jumps, odometry_jumps, odometry_teleports
from doorbatch.geometry.se2 import compose, relative

JUMP = {"min_jump_m": 0.5, "min_jump_rad": math.radians(30), "at_zero_m": 0.001, "restart_steps": 2.0}


def _drive(n: int, seed: int) -> np.ndarray:
    """A 50 Hz odometry at up to 1 m/s and 1 rad/s."""
    rng = np.random.default_rng(seed)
    steps = np.column_stack([rng.uniform(0.0, 0.02, n - 1), np.zeros(n - 1), rng.uniform(-0.02, 0.02, n - 1)])
    poses = [np.zeros(3)]
    for s in steps:
        poses.append(compose(poses[-1], s))
    return np.array(poses)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(100, 900), st.floats(-3.0, 3.0))
def test_a_restart_at_zero_is_found_and_bridged(seed: int, at: int, yaw0: float) -> None:
    """The driver restarts at step ``at``: from there it reports its motion from (0, 0, yaw0). The jump is found
    there (and nowhere else), and bridging it keeps every reported step but the one across it, which becomes
    no motion."""
    truth = _drive(1000, seed)
    start = np.array([25.0, -4.0, 1.0])
    odom = compose(start, truth)
    odom[at:] = compose(np.array([0.0, 0.0, yaw0]), relative(truth[at], truth[at:]))
    jumps = odometry_jumps(odom, **JUMP)
    assert jumps.tolist() == [at]
    fixed = bridged_jumps(odom, jumps)
    steps, want = relative(fixed[:-1], fixed[1:]), relative(truth[:-1], truth[1:])
    keep = np.arange(999) != at - 1
    np.testing.assert_allclose(steps[keep], want[keep], atol=1e-9)
    np.testing.assert_allclose(steps[at - 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(fixed[:at], odom[:at])


def test_long_steps_that_do_not_land_at_zero_are_not_jumps() -> None:
    """3 m between two messages (a gap, or a CARMEN log's coarse stamps), a message repeated, a turn of 57° in one
    step: no restart. A turn of 57° onto (0, 0) from a robot standing near it is one."""
    poses = np.array([[0.2, 0, 0], [0.22, 0, 0], [3.22, 0, 0], [3.22, 0, 0], [3.22, 0, 1.0]], dtype=np.float64)
    assert odometry_jumps(poses, **JUMP).size == 0
    near = np.array([[0.1, 0.1, 0.0], [0.0, 0.0, 1.0]])
    assert odometry_jumps(near, **JUMP).tolist() == [1]


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(100, 900), st.floats(-3.0, 3.0))
def test_a_restart_whose_first_message_comes_a_step_later_is_found(seed: int, at: int, yaw0: float) -> None:
    """The driver restarts at (0, 0, yaw0) with the robot moving: its first message, at ``at``, already holds one
    step of motion (up to 2 cm here), so it lands off the origin by more than ``at_zero_m``. Found there, and only
    there, and bridged as the restart at zero is."""
    truth = _drive(1000, seed)
    odom = compose(np.array([25.0, -4.0, 1.0]), truth)
    odom[at:] = compose(np.array([0.0, 0.0, yaw0]), relative(truth[at - 1], truth[at:]))
    assert np.hypot(*odom[at, :2]) > JUMP["at_zero_m"] or np.hypot(*(truth[at, :2] - truth[at - 1, :2])) < 1e-3
    jumps = odometry_jumps(odom, **JUMP)
    assert jumps.tolist() == [at]
    fixed = bridged_jumps(odom, jumps)
    np.testing.assert_allclose(relative(fixed[at:-1], fixed[at + 1:]), relative(truth[at:-1], truth[at + 1:]),
                               atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(100, 900), st.floats(2.0, 20.0), st.floats(-3.0, 3.0),
       st.floats(-math.pi, math.pi))
def test_a_pose_set_from_outside_is_found_and_bridged(seed: int, at: int, dist_m: float, bearing: float,
                                                      yaw_jump: float) -> None:
    """An EKF's set_pose at step ``at``: the odometry goes on from a pose ``dist_m`` away, turned, within one
    50 Hz period. Found there and only there (not a restart: it lands far from (0, 0)), and bridged."""
    truth = _drive(1000, seed)
    odom = compose(np.array([25.0, -4.0, 1.0]), truth)
    moved = compose(np.array([dist_m * math.cos(bearing), dist_m * math.sin(bearing), yaw_jump]), odom[at - 1])
    odom[at:] = compose(moved, relative(truth[at - 1], truth[at:]))
    stamps = np.arange(1000) * 0.02
    assert odometry_jumps(odom, **JUMP).size == 0
    jumps = odometry_teleports(stamps, odom, 0.5, 10.0)
    assert jumps.tolist() == [at]
    fixed = bridged_jumps(odom, jumps)
    np.testing.assert_allclose(relative(fixed[at:-1], fixed[at + 1:]), relative(truth[at:-1], truth[at + 1:]),
                               atol=1e-9)


def test_steps_after_a_gap_or_among_long_steps_are_no_set_pose() -> None:
    """3 m over a 6 s gap in the messages (the robot drove on unseen), 3 m steps among 0.4 m ones (orebro's coarse
    steps), a 57° turn in one period: none is a set pose. The same 3 m in one period among 2 cm steps is one."""
    t = np.array([0.0, 0.2, 0.4, 6.4, 6.6, 6.8])
    gap = np.array([[0, 0, 0], [0.02, 0, 0], [0.04, 0, 0], [3.04, 0, 0], [3.06, 0, 0], [3.08, 0, 1.0]])
    assert odometry_teleports(t, gap, 0.5, 10.0).size == 0
    coarse = np.cumsum(np.array([[0.4, 0, 0]] * 6 + [[3.0, 0, 0]] + [[0.4, 0, 0]] * 6), axis=0)
    assert odometry_teleports(np.arange(13) * 0.2, coarse, 0.5, 10.0).size == 0
    t_even = np.arange(6) * 0.2
    assert odometry_teleports(t_even, gap, 0.5, 10.0).tolist() == [3]
    assert odometry_teleports(t_even, gap, 0.5, 0.0).size == 0
    assert odometry_teleports(np.zeros(6), gap, 0.5, 10.0).size == 0  # no stamps: a gap cannot be told from it


def test_an_odometry_that_froze_and_caught_up_is_no_set_pose() -> None:
    """A reviewer's case: the encoder link stalls for 1.2 s at 50 Hz (stamps go on, the pose stands), then the
    ticks land in one 0.6 m step and the robot drives on. That is motion, not a set pose: kept."""
    x = np.r_[np.arange(200) * 0.01, np.full(60, 1.99), 2.59 + np.arange(100) * 0.01]
    poses = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    assert odometry_teleports(np.arange(x.size) * 0.02, poses, 0.5, 10.0).size == 0
    moving = x.copy()
    moving[200:] = x[199] + np.arange(160) * 0.01 + 6.0 * (np.arange(160) >= 60)  # a set pose while moving: found
    poses = np.stack([moving, np.zeros_like(x), np.zeros_like(x)], axis=1)
    assert odometry_teleports(np.arange(x.size) * 0.02, poses, 0.5, 10.0).tolist() == [260]
