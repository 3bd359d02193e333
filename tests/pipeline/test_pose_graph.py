"""SE(2) pose-graph optimization on known geometry: a square loop closed, a false loop edge rejected."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, relative
from doorbatch.pipeline.poses.pose_graph import PoseGraphEdges, edge_errors, edge_jacobians, optimize_pose_graph

SIGMA_M, SIGMA_RAD = 0.02, np.deg2rad(0.5)


def _square(side_nodes: int = 4, side_m: float = 4.0) -> np.ndarray:
    """Poses around a square, counter-clockwise, turning 90° at each corner; the last node is the first again."""
    step = side_m / side_nodes
    steps = [np.array([step, 0.0, np.pi / 2 if k == side_nodes - 1 else 0.0])
             for _ in range(4) for k in range(side_nodes)]
    poses = [np.zeros(3)]
    for s in steps:
        poses.append(compose(poses[-1], s))
    return np.array(poses)


def _information(n: int, sigma_m: float = SIGMA_M, sigma_rad: float = SIGMA_RAD) -> np.ndarray:
    return np.tile(np.diag([sigma_m**-2, sigma_m**-2, sigma_rad**-2]), (n, 1, 1))


def _chain(truth: np.ndarray, corner: int, error_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Sequential measurements (the true steps, one with a heading error) and the dead-reckoned poses."""
    steps = relative(truth[:-1], truth[1:])
    steps[corner, 2] += error_rad
    poses = [truth[0]]
    for s in steps:
        poses.append(compose(poses[-1], s))
    return steps, np.array(poses)


def _edges(steps: np.ndarray, information: np.ndarray, loops: list[tuple[int, int, np.ndarray, np.ndarray]]
           ) -> PoseGraphEdges:
    n = len(steps)
    first = np.r_[np.arange(n), [i for i, _, _, _ in loops]].astype(np.int64)
    second = np.r_[np.arange(1, n + 1), [j for _, j, _, _ in loops]].astype(np.int64)
    measurement = np.vstack([steps, *[z[None] for _, _, z, _ in loops]])
    info = np.concatenate([information, *[w[None] for _, _, _, w in loops]])
    robust = np.r_[np.zeros(n, dtype=bool), np.ones(len(loops), dtype=bool)]
    return PoseGraphEdges(first, second, measurement, info, robust)


def _position_error(poses: np.ndarray, truth: np.ndarray) -> float:
    return float(np.hypot(*(poses[:, :2] - truth[:, :2]).T).max())


def test_loop_closure_puts_a_known_heading_error_back_where_the_uncertainty_is() -> None:
    """A 6° heading error in the step after the first corner, on the edge the front end marked uncertain
    (a fallback to the odometry: σ_yaw = 20°): closing the loop takes the whole error out of that edge and
    restores the truth."""
    truth = _square()
    steps, dead_reckoned = _chain(truth, corner=4, error_rad=np.deg2rad(6.0))
    information = _information(len(steps))
    information[4] = np.diag([SIGMA_M**-2, SIGMA_M**-2, np.deg2rad(20.0) ** -2])
    loop = (len(steps), 0, relative(truth[-1], truth[0]), _information(1)[0])
    solution = optimize_pose_graph(dead_reckoned, _edges(steps, information, [loop]))
    assert _position_error(dead_reckoned, truth) > 0.4
    # The other edges keep about (0.5°/20°)² of the error between them: within 1 cm and 0.1° of the truth.
    assert _position_error(solution.poses, truth) < 0.01
    assert np.rad2deg(np.abs(wrap_angle(solution.poses[:, 2] - truth[:, 2]))).max() < 0.1
    assert solution.active.all()
    assert np.allclose(solution.poses[0], truth[0])  # the gauge stays


def test_loop_closure_spreads_an_error_over_equally_certain_edges() -> None:
    """With equal weights the 6° error is shared by the edges of the cycle (none takes more than 1°), so the
    poses come much closer to the truth and the loop edge itself is satisfied to within its σ."""
    truth = _square()
    steps, dead_reckoned = _chain(truth, corner=4, error_rad=np.deg2rad(6.0))
    loop = (len(steps), 0, relative(truth[-1], truth[0]), _information(1)[0])
    edges = _edges(steps, _information(len(steps)), [loop])
    solution = optimize_pose_graph(dead_reckoned, edges)
    assert _position_error(solution.poses, truth) < 0.3 * _position_error(dead_reckoned, truth)
    turns = np.rad2deg(wrap_angle(relative(solution.poses[:-1], solution.poses[1:])[:, 2] - steps[:, 2]))
    assert np.abs(turns).max() < 1.0 and np.count_nonzero(np.abs(turns) > 0.05) > 10
    assert solution.chi2[-1] < 1.0


def test_a_false_loop_edge_is_switched_off_and_leaves_the_true_solution() -> None:
    """Opposite corners (4, 0) and (0, 4) claimed to be 1 m apart with a confident edge: the χ² gate switches it
    off, and the solution is the one without it; least squares without the robust treatment would bend the
    square towards it."""
    truth = _square()
    steps, dead_reckoned = _chain(truth, corner=4, error_rad=np.deg2rad(6.0))
    true_loop = (len(steps), 0, relative(truth[-1], truth[0]), _information(1)[0])
    false_loop = (4, 12, np.array([1.0, 0.0, np.pi]), _information(1)[0])
    clean = optimize_pose_graph(dead_reckoned, _edges(steps, _information(len(steps)), [true_loop]))
    robust = optimize_pose_graph(dead_reckoned, _edges(steps, _information(len(steps)), [true_loop, false_loop]))
    assert robust.active.tolist() == [True] * (len(steps) + 1) + [False]
    assert _position_error(robust.poses, clean.poses) < 1e-3
    plain_edges = _edges(steps, _information(len(steps)), [true_loop, false_loop])
    plain = optimize_pose_graph(dead_reckoned, PoseGraphEdges(plain_edges.first, plain_edges.second,
                                                             plain_edges.measurement, plain_edges.information,
                                                             np.zeros(plain_edges.size, dtype=bool)))
    assert _position_error(plain.poses, clean.poses) > 0.5


def test_graph_inputs_are_checked() -> None:
    edges = PoseGraphEdges(np.array([0]), np.array([2]), np.zeros((1, 3)), _information(1), np.zeros(1, dtype=bool))
    with pytest.raises(ValueError, match="outside"):
        optimize_pose_graph(np.zeros((2, 3)), edges)
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        optimize_pose_graph(np.zeros((2, 2)), edges)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-5.0, 5.0), min_size=9, max_size=9))
def test_analytic_jacobians_match_finite_differences(values: list[float]) -> None:
    v = np.asarray(values)
    poses = np.array([v[0:3], v[3:6]])
    edges = PoseGraphEdges(np.array([0]), np.array([1]), v[6:9][None], _information(1), np.zeros(1, dtype=bool))
    a, b = edge_jacobians(poses, edges)
    h = 1e-6
    for node, analytic in ((0, a[0]), (1, b[0])):
        for axis in range(3):
            plus, minus = poses.copy(), poses.copy()
            plus[node, axis] += h
            minus[node, axis] -= h
            diff = edge_errors(plus, edges)[0] - edge_errors(minus, edges)[0]
            diff[2] = wrap_angle(diff[2])
            assert np.allclose(diff / (2 * h), analytic[:, axis], atol=1e-5)
