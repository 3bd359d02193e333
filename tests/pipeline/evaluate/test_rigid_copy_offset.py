"""``rigid_copy_offset``: zero for a trajectory moved rigidly, the size of what parts it from one otherwise."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.se2 import compose
from doorbatch.pipeline.evaluate.trajectory_error import rigid_copy_offset

# Paths start away from the origin: with ref[0] the identity, the correction ref[0] ⊕ est[0]⁻¹ and its reversal
# est[0]⁻¹ ⊕ ref[0] are both est[0]⁻¹, and the order of the composition would go untested.
START = np.array([2.0, -1.0, 0.4])


def _path(seed: int, n: int = 60) -> np.ndarray:
    """A wandering planar path from ``START`` (steps of 0.05–0.3 m, turns up to 0.4 rad)."""
    rng = np.random.default_rng(seed)
    steps = np.column_stack([rng.uniform(0.05, 0.3, n), np.zeros(n), rng.uniform(-0.4, 0.4, n)])
    poses = [START]
    for step in steps:
        poses.append(compose(poses[-1], step))
    return np.array(poses)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.floats(-50, 50), st.floats(-50, 50), st.floats(-np.pi, np.pi))
def test_a_rigidly_moved_copy_is_offset_by_nothing(seed: int, x: float, y: float, yaw: float) -> None:
    path = _path(seed)
    moved = compose(np.array([x, y, yaw]), path)
    off_m, off_rad = rigid_copy_offset(moved, path)
    assert off_m < 1e-9 and off_rad < 1e-9


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 59), st.floats(0.002, 1.0), st.floats(0.001, 0.5))
def test_one_pose_moved_off_the_copy_is_the_offset(seed: int, k: int, shift_m: float, turn_rad: float) -> None:
    path = _path(seed)
    copy = compose(np.array([3.0, -1.0, 0.7]), path)
    copy[k] = compose(copy[k], np.array([shift_m, 0.0, turn_rad]))  # ahead by shift_m, turned by turn_rad
    off_m, off_rad = rigid_copy_offset(copy, path)
    assert np.isclose(off_m, shift_m) and np.isclose(off_rad, turn_rad)


def test_odometry_that_gains_one_percent_is_no_copy() -> None:
    path = _path(3)
    drifted = path.copy()
    drifted[:, :2] *= 1.01
    off_m, off_rad = rigid_copy_offset(drifted, path)
    # headings unchanged, so aligning the first poses is a shift by −0.01 p_0: p_k ends 0.01 |p_k − p_0| off
    from_start = np.hypot(path[:, 0] - START[0], path[:, 1] - START[1])
    assert np.isclose(off_m, 0.01 * np.max(from_start), rtol=1e-9, atol=1e-12) and off_rad < 1e-12
