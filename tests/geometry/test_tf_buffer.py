"""TF buffer: exact interpolation on constructed cases, chains through the tree, clear errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

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


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 40), st.booleans(), st.booleans())
def test_an_edges_samples_are_its_lookups_and_odometry_poses_are_the_trees(seed: int, n: int, above: bool,
                                                                           below: bool) -> None:
    """odom (→ odom_shift, static, tilted) → base_footprint (dynamic, n samples) (→ base_link, static, tilted): an
    edge's samples are what a lookup gives at their stamps, to the bit, and the odometry read off the tree
    (recording._tf_poses, all samples at once) is each stamp's lookup of base_link in odom, its planar part."""
    from doorbatch.io.recording import _planar, _tf_poses

    rng = np.random.default_rng(seed)
    tf = TfBuffer()
    parent = "odom"
    if above:
        tf.add(Transform(0, "odom", "odom_shift", rng.normal(size=3), Rotation.random(random_state=seed).as_quat(),
                         True))
        parent = "odom_shift"
    stamps = np.sort(rng.choice(10**9, size=n, replace=False)).astype(np.int64)
    for t in stamps:
        q = Rotation.from_euler("z", rng.uniform(-3, 3)).as_quat()
        tf.add(Transform(int(t), parent, "base_footprint", np.r_[rng.normal(size=2), 0.0], q, False))
    base = "base_footprint"
    if below:
        tf.add(Transform(0, "base_footprint", "base_link", rng.normal(size=3), Rotation.from_euler(
            "xyz", rng.uniform(-0.2, 0.2, 3)).as_quat(), True))
        base = "base_link"
    got_stamps, mats = tf.samples("base_footprint")
    assert got_stamps.tolist() == stamps.tolist()
    for t, mat in zip(stamps, mats, strict=True):
        assert np.array_equal(mat, tf.lookup(parent, "base_footprint", int(t)))
    poses = _tf_poses(tf, "odom", base)
    assert [p.stamp_ns for p in poses] == stamps.tolist()
    for p in poses:
        np.testing.assert_allclose([p.x, p.y, p.yaw], _planar(tf.lookup("odom", base, p.stamp_ns)), atol=1e-12)
