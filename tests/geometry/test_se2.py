"""SE(2) invariants: a ⊕ a⁻¹ = 0, associativity, relative poses, points moved like the poses."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.se2 import compose, inverse, relative, rotation_matrix, transform_points

coord = st.floats(-50.0, 50.0)
angle = st.floats(-10.0, 10.0)
pose = st.tuples(coord, coord, angle).map(np.array)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    d_yaw = np.angle(np.exp(1j * (a[..., 2] - b[..., 2])))
    return bool(np.allclose(a[..., :2], b[..., :2], atol=1e-9) and np.allclose(d_yaw, 0.0, atol=1e-9))


@settings(max_examples=100, deadline=None)
@given(pose, pose, pose)
def test_group_laws(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> None:
    assert _same(compose(a, inverse(a)), np.zeros(3))
    assert _same(compose(inverse(a), a), np.zeros(3))
    assert _same(compose(compose(a, b), c), compose(a, compose(b, c)))
    assert _same(compose(a, relative(a, b)), b)
    assert -np.pi < compose(a, b)[2] <= np.pi


@settings(max_examples=50, deadline=None)
@given(pose, pose)
def test_points_follow_composition(a: np.ndarray, b: np.ndarray) -> None:
    pts = np.random.default_rng(0).normal(size=(7, 2))
    assert np.allclose(transform_points(compose(a, b), pts), transform_points(a, transform_points(b, pts)))
    assert np.allclose(transform_points(a, pts), pts @ rotation_matrix(a[2]).T + a[:2])


def test_vectorized_over_leading_axes() -> None:
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(4, 5, 3)), rng.normal(size=(4, 5, 3))
    out = compose(a, b)
    assert out.shape == (4, 5, 3)
    assert _same(out[2, 3], compose(a[2, 3], b[2, 3]))
    assert _same(compose(a, b[0, 0]), np.stack([[compose(x, b[0, 0]) for x in row] for row in a]))


def test_interpolate_poses_is_exact_on_linear_motion_and_flags_outside() -> None:
    from doorbatch.geometry.se2 import interpolate_poses

    stamps = np.array([0, 10, 20], dtype=np.int64)
    poses = np.array([[0.0, 0.0, 3.0], [1.0, 2.0, -3.0], [2.0, 4.0, -2.0]])
    out, valid = interpolate_poses(stamps, poses, np.array([5, 10, 15, 25, -1]), max_gap_ns=20)
    np.testing.assert_allclose(out[0, :2], [0.5, 1.0])
    # 3.0 → −3.0 is a 0.283 rad turn through ±π, not 6 rad the long way round.
    expected = np.arctan2(np.sin(3.0 + (2 * np.pi - 6.0) / 2), np.cos(3.0 + (2 * np.pi - 6.0) / 2))
    assert out[0, 2] == pytest.approx(expected)
    np.testing.assert_allclose(out[1], poses[1])
    assert valid.tolist() == [True, True, True, False, False]
    _, gap_valid = interpolate_poses(stamps, poses, np.array([5, 10, 20]), max_gap_ns=5)
    assert gap_valid.tolist() == [False, True, True]  # on a stamp: valid across any gap
