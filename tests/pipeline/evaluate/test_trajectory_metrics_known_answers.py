"""Trajectory metrics without evo: association ties, Umeyama on a mirrored path, all-pairs RPE ties."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose
from doorbatch.pipeline.evaluate.trajectory_metrics import matching_time_indices, rpe_pairs, umeyama_se2


def test_a_stamp_halfway_between_two_goes_to_the_earlier() -> None:
    """Reference stamps 0 and 10 ns, estimate stamp 5 ns, max_diff 5 ns: both 5 ns away. The module documents the
    tie as going to the earlier stamp, as evo's ``matching_time_indices`` does (``diff_ub < diff_lb`` takes the
    later one only when strictly nearer)."""
    est_idx, ref_idx = matching_time_indices([5], [0, 10], 5)
    assert est_idx.tolist() == [0] and ref_idx.tolist() == [0]
    est_idx, ref_idx = matching_time_indices([4, 6, 16], [0, 10], 5)  # no tie: the nearest; 16 is 6 ns off
    assert est_idx.tolist() == [0, 1] and ref_idx.tolist() == [0, 1]


def _l_path() -> np.ndarray:
    """An L: 4 m along x, then 2 m along y (no mirror symmetry), points every 0.5 m."""
    leg_x = np.stack([np.arange(0.0, 4.01, 0.5), np.zeros(9)], axis=1)
    leg_y = np.stack([np.full(4, 4.0), np.arange(0.5, 2.01, 0.5)], axis=1)
    return np.concatenate([leg_x, leg_y])


def _rigid_cost(transform: np.ndarray, x: np.ndarray, y: np.ndarray) -> float:
    """Σ ‖T(x_i) − y_i‖² for a proper SE(2) transform (t, θ)."""
    c, s = math.cos(transform[2]), math.sin(transform[2])
    moved = x @ np.array([[c, s], [-s, c]]) + transform[:2]
    return float(np.sum((moved - y) ** 2))


@settings(max_examples=20, deadline=None)
@given(st.floats(-10.0, 10.0), st.floats(-10.0, 10.0), st.floats(-math.pi, math.pi))
def test_alignment_of_a_mirrored_path_is_the_best_rotation_not_a_reflection(dx: float, dy: float,
                                                                            dyaw: float) -> None:
    """The estimate is the L mirrored in y, then moved rigidly. The best reflection would fit it exactly; the
    alignment must be the best *proper* rotation, found here by brute force over θ (the best translation for a
    rotation R being μ_y − R μ_x)."""
    ref = _l_path()
    mirrored = ref * [1.0, -1.0]
    est = compose(np.array([dx, dy, dyaw]), np.column_stack([mirrored, np.zeros(len(ref))]))[:, :2]
    found = umeyama_se2(est, ref)
    mean_x, mean_y = est.mean(axis=0), ref.mean(axis=0)
    thetas = np.linspace(-math.pi, math.pi, 200_001)
    c, s = np.cos(thetas), np.sin(thetas)
    xc, yc = est - mean_x, ref - mean_y
    # Σ ‖R xc − yc‖² = Σ‖xc‖² + Σ‖yc‖² − 2 (cos θ Σ xc·yc + sin θ Σ xc×yc)
    dot = float(np.sum(xc * yc))
    cross = float(np.sum(xc[:, 0] * yc[:, 1] - xc[:, 1] * yc[:, 0]))
    costs = np.sum(xc**2) + np.sum(yc**2) - 2.0 * (c * dot + s * cross)
    best = thetas[int(np.argmin(costs))]
    assert abs(float(wrap_angle(found[2] - best))) < 1e-4  # grid step 3.1e-5 rad
    rot = np.array([[math.cos(best), -math.sin(best)], [math.sin(best), math.cos(best)]])
    np.testing.assert_allclose(found[:2], mean_y - rot @ mean_x, atol=1e-3)
    assert _rigid_cost(found, est, ref) <= float(np.min(costs)) + 1e-6
    assert _rigid_cost(found, est, ref) > 1.0  # a mirrored L is no rigid copy


def test_all_pairs_rpe_tie_goes_to_the_earlier_pose() -> None:
    """Steps of 0.5 m, delta 0.75 m: from every pose the next two are 0.5 and 1.0 m on, both 0.25 m from delta.
    The tie goes to the earlier pose, as evo's ``filter_pairs_by_path`` (``np.argmin``: the first of equal
    distances) does. rel_delta_tol 0.5 keeps pairs 0.25 m off (0.1 would drop them all)."""
    poses = np.stack([np.arange(0.0, 3.01, 0.5), np.zeros(7), np.zeros(7)], axis=1)
    first, second = rpe_pairs(poses, 0.75, all_pairs=True, rel_delta_tol=0.5)
    assert first.tolist() == [0, 1, 2, 3, 4, 5]
    assert second.tolist() == [1, 2, 3, 4, 5, 6]
