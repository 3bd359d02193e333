"""TF buffer: exact interpolation on constructed cases, chains through the tree, clear errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from doorbatch.errors import TransformError
from doorbatch.geometry.rotations import invert_transform, transform_matrix, yaw_of_matrix
from doorbatch.geometry.tf_buffer import TfBuffer
from doorbatch.records import Transform


def _yaw_q(yaw: float) -> np.ndarray:
    return np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])


def _tf(stamp: int, parent: str, child: str, xyz: tuple[float, float, float], q: np.ndarray,
        static: bool = False) -> Transform:
    return Transform(stamp, parent, child, np.array(xyz, dtype=float), q, static)


def test_interpolation_between_two_dynamic_transforms_is_exact() -> None:
    buf = TfBuffer()
    buf.add(_tf(1_000, "odom", "base_link", (0.0, 0.0, 0.0), _yaw_q(0.0)))
    buf.add(_tf(3_000, "odom", "base_link", (2.0, -4.0, 1.0), _yaw_q(math.pi / 2)))
    mat = buf.lookup("odom", "base_link", 1_500)  # a quarter of the way
    np.testing.assert_allclose(mat[:3, 3], [0.5, -1.0, 0.25], atol=1e-12)
    assert yaw_of_matrix(mat) == pytest.approx(math.pi / 8, abs=1e-12)
    np.testing.assert_allclose(mat[:3, :3] @ mat[:3, :3].T, np.eye(3), atol=1e-12)


def test_lookup_chains_static_and_dynamic_edges_and_inverts() -> None:
    buf = TfBuffer()
    buf.add(_tf(0, "base_link", "laser", (0.2, 0.0, 0.3), _yaw_q(0.0), static=True))
    buf.add(_tf(0, "odom", "base_link", (1.0, 0.0, 0.0), _yaw_q(0.0)))
    buf.add(_tf(10, "odom", "base_link", (1.0, 0.0, 0.0), _yaw_q(math.pi)))
    mat = buf.lookup("odom", "laser", 10)
    np.testing.assert_allclose(mat[:2, 3], [0.8, 0.0], atol=1e-12)
    back = buf.lookup("laser", "odom", 10)
    np.testing.assert_allclose(back @ mat, np.eye(4), atol=1e-12)


def test_unconnected_frames_and_far_extrapolation_raise() -> None:
    buf = TfBuffer(extrapolation_limit_ns=5)
    buf.add(_tf(100, "odom", "base_link", (0.0, 0.0, 0.0), _yaw_q(0.0)))
    buf.add(_tf(200, "odom", "base_link", (1.0, 0.0, 0.0), _yaw_q(0.0)))
    with pytest.raises(TransformError, match="camera"):
        buf.lookup("base_link", "camera", 150)
    with pytest.raises(TransformError, match="outside"):
        buf.lookup("odom", "base_link", 300)
    np.testing.assert_allclose(buf.lookup("odom", "base_link", 203)[0, 3], 1.0)  # within the limit: clamped


def test_a_mount_lookup_holds_a_dynamic_edge_that_never_changed_and_a_pose_lookup_does_not() -> None:
    """A mount logged on /tf once (or again and again, the same) holds before and after its stamps for a mount's
    lookup; a pose lookup (odometry, a reference) keeps the limit, so no pose is made up where the edge has no data;
    once one transform differs, the edge moves, and far from its stamps it is an error for both."""
    buf = TfBuffer(extrapolation_limit_ns=5)
    buf.add(_tf(100, "base_link", "laser", (0.2, 0.0, 0.3), _yaw_q(0.5)))
    buf.add(_tf(200, "base_link", "laser", (0.2, 0.0, 0.3), _yaw_q(0.5)))
    for t in (0, 150, 10_000):
        mat = buf.lookup("base_link", "laser", t, hold_constant=True)
        np.testing.assert_allclose(mat[:3, 3], [0.2, 0.0, 0.3], atol=1e-12)
        assert yaw_of_matrix(mat) == pytest.approx(0.5, abs=1e-12)
    with pytest.raises(TransformError, match="outside"):
        buf.lookup("base_link", "laser", 10_000)
    buf.add(_tf(300, "base_link", "laser", (0.2, 0.01, 0.3), _yaw_q(0.5)))
    with pytest.raises(TransformError, match="outside"):
        buf.lookup("base_link", "laser", 10_000, hold_constant=True)


@given(st.floats(-3.0, 3.0), st.floats(-5, 5), st.floats(-5, 5), st.floats(-math.pi, math.pi))
def test_transform_times_inverse_is_identity(qx: float, x: float, y: float, yaw: float) -> None:
    q = np.array([qx, 0.3, math.sin(yaw / 2), math.cos(yaw / 2)])
    q /= np.linalg.norm(q)
    mat = transform_matrix([x, y, 0.5], q)
    np.testing.assert_allclose(mat @ invert_transform(mat), np.eye(4), atol=1e-9)
