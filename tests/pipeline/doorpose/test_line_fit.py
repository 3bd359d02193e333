"""Line fits of paper 003: exact on clean points, RANSAC ignores outliers that pull the others."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.pipeline.doorpose.line_fit import LineFit, fit_line, fit_lsq, fit_naive, fit_ransac


def _door_points(intercept: float, slope: float, n: int = 30) -> np.ndarray:
    x = np.linspace(-0.45, 0.45, n)
    return np.stack([x, intercept + slope * x], axis=1)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.5, 8.0), st.floats(-1.5, 1.5), st.sampled_from(list(LineFit)))
def test_every_fit_recovers_a_clean_line(intercept: float, slope: float, method: LineFit) -> None:
    line = fit_line(_door_points(intercept, slope), method, 200, 0.01, np.random.default_rng(0))
    assert line is not None
    assert line.intercept_m == pytest.approx(intercept, abs=1e-9)
    assert line.slope == pytest.approx(slope, abs=1e-9)


def test_obstacle_at_the_left_edge_breaks_naive_and_pulls_lsq_but_not_ransac() -> None:
    pts = _door_points(2.0, 0.1)
    pts[:5, 1] -= 0.4  # an obstacle 0.4 m in front of the door's left fifth (paper 003, Fig. 6)
    naive, lsq = fit_naive(pts), fit_lsq(pts)
    ransac = fit_ransac(pts, 1000, 0.01, np.random.default_rng(3))
    assert naive is not None and lsq is not None and ransac is not None
    assert abs(naive.slope - 0.1) > 0.3
    assert 0.05 < abs(lsq.slope - 0.1) < abs(naive.slope - 0.1)
    assert ransac.slope == pytest.approx(0.1, abs=1e-9)
    assert ransac.intercept_m == pytest.approx(2.0, abs=1e-9)
    assert not ransac.inliers[:5].any() and ransac.inliers[5:].all()


def test_ransac_is_deterministic_for_a_seed() -> None:
    rng = np.random.default_rng(0)
    pts = _door_points(3.0, -0.2) + np.column_stack([np.zeros(30), rng.normal(0, 0.01, 30)])
    a = fit_ransac(pts, 1000, 0.01, np.random.default_rng(7))
    b = fit_ransac(pts, 1000, 0.01, np.random.default_rng(7))
    assert a is not None and b is not None
    assert (a.intercept_m, a.slope) == (b.intercept_m, b.slope)


def test_degenerate_inputs_give_no_line() -> None:
    assert fit_naive(np.array([[0.1, 2.0], [0.1, 2.5]])) is None
    assert fit_lsq(np.array([[0.1, 2.0]])) is None
    assert fit_ransac(np.zeros((1, 2)), 10, 0.01, np.random.default_rng(0)) is None


def test_ransac_refits_its_inliers_by_least_squares() -> None:
    """The best two-point hypothesis is refitted by least squares on its inliers (module docstring)."""
    # four door points ±4 mm about z = 2: the residual pattern (+, −, −, +) is even in x, so the
    # least-squares line is z = 2 exactly (b = Σx·Δz / Σx² = 0, a = z̄ = 2); no line through two of them is
    # z = 2 (each misses another by 4 mm or more). The obstacle 0.5 m in front of the door is no inlier.
    pts = np.array([[-0.3, 2.004], [-0.1, 1.996], [0.1, 1.996], [0.3, 2.004], [0.05, 1.5]])
    line = fit_ransac(pts, 200, 0.01, np.random.default_rng(0))
    assert line is not None
    assert line.intercept_m == pytest.approx(2.0, abs=1e-12)
    assert line.slope == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_array_equal(line.inliers, [True, True, True, True, False])


def test_ransac_ties_in_inlier_count_go_to_the_tighter_line() -> None:
    """Equal inlier counts: the hypothesis with the smaller sum of inlier residuals wins (module docstring)."""
    # three collinear points of the door at z = 2 (every pair's line has residuals 0) and three of a wall
    # 0.5 m behind, the middle one 4 mm off (its pairs' lines leave 4–8 mm); lines across the 0.5 m gap have
    # 2 inliers only. Both surfaces have 3 inliers; the door's sum is 0, so its refit is z = 2.
    pts = np.array([[-0.4, 2.0], [-0.35, 2.0], [-0.3, 2.0], [0.3, 2.5], [0.35, 2.504], [0.4, 2.5]])
    line = fit_ransac(pts, 500, 0.01, np.random.default_rng(1))
    assert line is not None
    assert line.intercept_m == pytest.approx(2.0, abs=1e-12)
    assert line.slope == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_array_equal(line.inliers, [True, True, True, False, False, False])
