"""Door leaf geometry: end points, point-to-leaf distance and its derivative w.r.t. the door angle, reach test."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_geometry import (
    doors_in_reach,
    hinge_unknown,
    leaf_endpoints,
    point_to_leaf_distance,
    subset_doors,
    with_closed_in_range,
    with_unmoved_swing,
)

FloatArray = npt.NDArray[np.float64]


def door_set(hinge: npt.ArrayLike, length: npt.ArrayLike, closed_yaw: npt.ArrayLike) -> DoorSet:
    h = np.asarray(hinge, dtype=np.float64).reshape(-1, 2)
    n = h.shape[0]
    return DoorSet(hinge=h, length=np.broadcast_to(np.asarray(length, dtype=np.float64), (n,)).copy(),
                   closed_yaw=np.broadcast_to(np.asarray(closed_yaw, dtype=np.float64), (n,)).copy(),
                   angle_min=np.zeros(n), angle_max=np.full(n, math.pi / 2))


def brute_distance(p: FloatArray, h: FloatArray, e: FloatArray) -> float:
    """Distance from p to segment h→e by dense sampling (independent of the closed form)."""
    s = np.linspace(0.0, 1.0, 2001)
    pts = h + s[:, None] * (e - h)
    return float(np.min(np.hypot(*(pts - p).T)))


def test_leaf_endpoints_follow_closed_yaw_plus_angle() -> None:
    doors = door_set([[1.0, 2.0], [0.0, 0.0]], [0.8, 1.0], [math.pi / 2, 0.0])
    ends = leaf_endpoints(doors, np.array([[math.radians(30.0), math.radians(-90.0)]]))
    np.testing.assert_allclose(ends[0, 0], [1.0 + 0.8 * math.cos(math.radians(120.0)),
                                            2.0 + 0.8 * math.sin(math.radians(120.0))], atol=1e-12)
    np.testing.assert_allclose(ends[0, 1], [0.0, -1.0], atol=1e-12)
    assert ends.shape == (1, 2, 2)


@settings(max_examples=200, deadline=None)
@given(st.floats(-5, 5), st.floats(-5, 5), st.floats(0.4, 1.3), st.floats(-math.pi, math.pi),
       st.floats(-math.pi, math.pi), st.floats(-2.5, 2.5), st.floats(-2.5, 2.5))
def test_distance_and_jacobian_match_brute_force_and_finite_differences(
    hx: float, hy: float, length: float, closed: float, angle: float, px: float, py: float
) -> None:
    doors = door_set([hx, hy], length, closed)
    p = np.array([hx + px, hy + py])
    dist, jac = point_to_leaf_distance(p[None, None], doors, np.array([[angle]]), dtype=np.float64)
    end = leaf_endpoints(doors, np.array([[angle]]))[0, 0]
    brute = brute_distance(p, doors.hinge[0], end)
    assert dist[0, 0, 0] <= brute + 1e-12
    assert dist[0, 0, 0] >= brute - length / 2000 - 1e-9
    if dist[0, 0, 0] < 1e-3:  # |·| has a kink on the leaf itself
        return
    h = 1e-6
    plus, _ = point_to_leaf_distance(p[None, None], doors, np.array([[angle + h]]), dtype=np.float64)
    minus, _ = point_to_leaf_distance(p[None, None], doors, np.array([[angle - h]]), dtype=np.float64)
    fd = (plus[0, 0, 0] - minus[0, 0, 0]) / (2 * h)
    assert abs(jac[0, 0, 0] - fd) < 1e-5 * (1.0 + abs(fd))
    assert abs(jac[0, 0, 0]) <= length + 1e-12  # |J| ≤ L: the bound the likelihood's pruning relies on


def test_jacobian_is_the_distance_along_the_leaf_when_the_foot_is_on_it() -> None:
    doors = door_set([0.0, 0.0], 1.0, 0.0)  # leaf along +x at angle 0
    pts = np.array([[[0.3, 0.2], [0.7, -0.4], [0.4, 0.0]]])
    dist, jac = point_to_leaf_distance(pts, doors, np.zeros((1, 1)), dtype=np.float64)
    np.testing.assert_allclose(dist[0, :, 0], [0.2, 0.4, 0.0], atol=1e-12)
    # CCW of the leaf: turning it CCW brings it closer (−t); CW of it: farther (+t); on it: −t (|J| = t).
    np.testing.assert_allclose(jac[0, :, 0], [-0.3, 0.7, -0.4], atol=1e-12)


def test_end_point_and_hinge_cases() -> None:
    doors = door_set([0.0, 0.0], 1.0, 0.0)
    angle = math.radians(20.0)
    p = np.array([1.5, 0.9])  # beyond the free end
    dist, jac = point_to_leaf_distance(p[None, None], doors, np.array([[angle]]), dtype=np.float64)
    e = np.array([math.cos(angle), math.sin(angle)])
    w = p - e
    assert abs(dist[0, 0, 0] - np.hypot(*w)) < 1e-12
    de_da = np.array([-math.sin(angle), math.cos(angle)])  # d(free end)/da for L = 1
    np.testing.assert_allclose(jac[0, 0, 0], -(w @ de_da) / np.hypot(*w), atol=1e-12)
    behind = np.array([-0.4, -0.3])  # the hinge is the closest point: the angle does not matter
    dist, jac = point_to_leaf_distance(behind[None, None], doors, np.array([[angle]]), dtype=np.float64)
    assert abs(dist[0, 0, 0] - 0.5) < 1e-12
    assert jac[0, 0, 0] == 0.0


def test_vectorized_over_particles_matches_a_per_particle_loop() -> None:
    rng = np.random.default_rng(3)
    n, b, d = 1000, 20, 6
    doors = door_set(rng.uniform(-4, 4, (d, 2)), rng.uniform(0.6, 1.1, d), rng.uniform(-math.pi, math.pi, d))
    pts = rng.uniform(-5, 5, (n, b, 2))
    angles = rng.uniform(-1.5, 1.5, (n, d))
    dist, jac = point_to_leaf_distance(pts, doors, angles)
    assert dist.dtype == np.float32 and dist.shape == (n, b, d)
    for i in range(0, n, 97):
        di, ji = point_to_leaf_distance(pts[i:i + 1], doors, angles[i:i + 1], dtype=np.float64)
        np.testing.assert_allclose(dist[i], di[0], atol=1e-5)
        np.testing.assert_allclose(jac[i], ji[0], atol=1e-5)
    loop = np.stack([point_to_leaf_distance(pts[i:i + 1], doors, angles[i:i + 1])[0][0] for i in range(n)])
    np.testing.assert_array_equal(loop, dist)


def test_ten_thousand_particles_sixty_beams_ten_doors_fit_in_float32_outputs() -> None:
    rng = np.random.default_rng(0)
    doors = door_set(rng.uniform(-4, 4, (10, 2)), 0.9, 0.0)
    pts = rng.uniform(-5, 5, (10000, 60, 2))
    dist, jac = point_to_leaf_distance(pts, doors, np.zeros((10000, 10)))
    assert dist.shape == jac.shape == (10000, 60, 10)
    assert dist.nbytes + jac.nbytes == 2 * 10000 * 60 * 10 * 4
    assert np.all(np.isfinite(dist)) and np.all(dist >= 0)


def test_doors_in_reach_keeps_doors_near_the_points_only() -> None:
    doors = door_set([[0.0, 0.0], [10.0, 0.0], [3.4, 0.0]], 0.9, 0.0)
    pts = np.array([[[0.5, 0.5], [1.0, -0.5], [np.nan, np.nan]]])
    np.testing.assert_array_equal(doors_in_reach(doors, pts, 1.4), [True, False, False])
    np.testing.assert_array_equal(doors_in_reach(doors, pts, 1.6), [True, False, True])
    assert not doors_in_reach(doors, np.full((1, 1, 2), np.nan), 100.0).any()
    sub = subset_doors(doors, doors_in_reach(doors, pts, 1.6))
    np.testing.assert_array_equal(sub.hinge, [[0.0, 0.0], [3.4, 0.0]])


def test_every_door_range_includes_closed() -> None:
    """A never-moved door mapped open at −90° (zero-width range), one seen only between 20° and 80°, and one
    with a range across closed: the first two widen to closed, the third is unchanged."""
    doors = DoorSet(np.zeros((3, 2)), np.ones(3), np.zeros(3), np.radians([-90.0, 20.0, -10.0]),
                    np.radians([-90.0, 80.0, 70.0]))
    out = with_closed_in_range(doors)
    np.testing.assert_allclose(np.degrees(out.angle_min), [-90.0, 0.0, -10.0])
    np.testing.assert_allclose(np.degrees(out.angle_max), [0.0, 80.0, 70.0])
    np.testing.assert_array_equal(out.hinge, doors.hinge)


def test_a_never_moved_door_opens_by_the_swing_to_the_side_it_was_seen_open_or_to_both() -> None:
    """Never moved: seen at −90° (opens to −), at 30° (opens to +, and further), closed (either side); a moved
    door keeps its observed range; a swing of 0 leaves every range as it was."""
    doors = DoorSet(np.zeros((4, 2)), np.ones(4), np.zeros(4), np.radians([-90.0, 30.0, -2.8, 0.0]),
                    np.radians([-90.0, 30.0, 0.0, 40.0]))
    unmoved = np.array([True, True, True, False])
    out = with_unmoved_swing(doors, unmoved, math.radians(90.0), math.radians(10.0))
    np.testing.assert_allclose(np.degrees(out.angle_min), [-90.0, 0.0, -90.0, 0.0])
    np.testing.assert_allclose(np.degrees(out.angle_max), [0.0, 90.0, 90.0, 40.0])
    assert with_unmoved_swing(doors, unmoved, 0.0, math.radians(10.0)) is doors
    # only the one seen closed may have its hinge at its free end
    assert hinge_unknown(unmoved, doors, math.radians(10.0)).tolist() == [False, False, True, False]

