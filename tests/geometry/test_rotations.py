"""Quaternion helpers: the heading of any unit quaternion, and interpolation along the shorter arc whatever the
sign a publisher gave each quaternion (q and −q are one rotation)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from doorbatch.geometry.rotations import quaternion_to_matrix, slerp, wrap_angle, yaw_of_matrix
from doorbatch.geometry.tf_buffer import TfBuffer
from doorbatch.io.decode import yaw_from_quaternion
from doorbatch.records import Transform


def _yaw_q(yaw: float) -> np.ndarray:
    return np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])


@settings(max_examples=100, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(-1.4, 1.4), st.floats(-math.pi, math.pi), st.booleans())
def test_the_heading_of_a_tilted_quaternion_is_its_x_axis_on_the_floor(yaw: float, pitch: float, roll: float,
                                                                       flip: bool) -> None:
    """A 3D estimator's pose (roll, pitch, yaw as ZYX Euler angles, scipy's convention): the heading is the yaw,
    the angle of the body's x axis projected onto the xy plane, for q and for −q."""
    q = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()  # x, y, z, w
    q = -q if flip else q
    assert abs(float(wrap_angle(yaw_from_quaternion(*q) - yaw))) < 1e-9
    assert yaw_from_quaternion(*q) == pytest.approx(yaw_of_matrix(quaternion_to_matrix(q)), abs=1e-9)


def test_an_upside_down_frame_has_the_heading_of_its_x_axis() -> None:
    assert yaw_from_quaternion(1.0, 0.0, 0.0, 0.0) == pytest.approx(0.0)  # rolled over: x still ahead
    assert abs(yaw_from_quaternion(0.0, 1.0, 0.0, 0.0)) == pytest.approx(math.pi)  # pitched over: x points back


def test_slerp_takes_the_shorter_arc_whatever_the_signs() -> None:
    q0, q1 = _yaw_q(math.radians(170.0)), -_yaw_q(math.radians(-170.0))  # 20° apart, written with opposite signs
    mid = slerp(q0, q1, 0.5)
    assert yaw_of_matrix(quaternion_to_matrix(mid)) == pytest.approx(math.pi)  # 180°, not 0° the long way round
    q = _yaw_q(0.7)
    assert yaw_of_matrix(quaternion_to_matrix(slerp(q, -q, 0.5))) == pytest.approx(0.7)


def test_tf_between_quaternions_of_opposite_sign_turns_the_short_way() -> None:
    buf = TfBuffer()
    buf.add(Transform(0, "odom", "base_link", np.zeros(3), _yaw_q(math.radians(170.0)), False))
    buf.add(Transform(100, "odom", "base_link", np.zeros(3), -_yaw_q(math.radians(-170.0)), False))
    assert abs(yaw_of_matrix(buf.lookup("odom", "base_link", 50))) == pytest.approx(math.pi)
