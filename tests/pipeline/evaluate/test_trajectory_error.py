"""``align_first_pose`` and ``ate_rmse``: known answers."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.pipeline.evaluate.trajectory_error import align_first_pose, ate_rmse

_coord = st.floats(-20.0, 20.0)
_yaw = st.floats(-math.pi, math.pi)


@settings(max_examples=60, deadline=None)
@given(_coord, _coord, _yaw, _coord, _coord, _yaw)
def test_aligned_estimate_starts_at_the_reference_first_pose(ex: float, ey: float, eyaw: float, rx: float, ry: float,
                                                             ryaw: float) -> None:
    """By definition the aligned estimate's first pose is the reference's, whatever both first poses are."""
    est = np.array([[ex, ey, eyaw], [ex + 1.0, ey - 0.5, eyaw + 0.3]])
    ref = np.array([[rx, ry, ryaw], [rx, ry + 2.0, ryaw - 0.2]])
    first = align_first_pose(est, ref)[0]
    np.testing.assert_allclose(first[:2], ref[0, :2], atol=1e-9)
    assert abs(float(wrap_angle(first[2] - ref[0, 2]))) < 1e-9


def test_aligned_estimate_keeps_its_relative_motion() -> None:
    """Estimate from (1, 0, π/2) one metre ahead (to (1, 1)); reference starts at (0, 0, 0): by hand, the aligned
    estimate is (0, 0, 0) then one metre ahead along x, (1, 0, 0)."""
    est = np.array([[1.0, 0.0, math.pi / 2], [1.0, 1.0, math.pi / 2]])
    ref = np.array([[0.0, 0.0, 0.0], [5.0, 5.0, 1.0]])
    np.testing.assert_allclose(align_first_pose(est, ref), [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], atol=1e-12)


def test_ate_rmse_is_the_root_of_the_mean_squared_position_error() -> None:
    """Position errors 0 m and 2 m: √((0² + 2²)/2) = √2 (their mean would be 1)."""
    ref = np.zeros((2, 3))
    est = np.array([[0.0, 0.0, 0.3], [0.0, 2.0, -0.1]])  # headings do not count
    assert math.isclose(ate_rmse(est, ref), math.sqrt(2.0), rel_tol=1e-12)
    assert ate_rmse(np.zeros((0, 3)), np.zeros((0, 3))) == 0.0
