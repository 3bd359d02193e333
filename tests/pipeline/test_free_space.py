"""What a scan's beams say about a point (doorbatch.pipeline.poses.free_space), on known geometry."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.se2 import transform_points
from doorbatch.pipeline.poses.free_space import RangeProfile, on_seen_surfaces


def _wall_scan(distance_m: float = 5.0, fov_deg: float = 90.0, beams: int = 91) -> np.ndarray:
    """Hits of a scan facing a wall x = distance (sensor at the origin, heading +x, 1° beams)."""
    a = np.radians(np.linspace(-fov_deg / 2, fov_deg / 2, beams))
    r = distance_m / np.cos(a)
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def test_in_front_of_the_hits_is_free_beyond_them_behind_on_them_or_outside_the_beams_neither() -> None:
    profile = RangeProfile.of_scan(_wall_scan())
    assert math.isclose(profile.bearing_tolerance_rad, 1.5 * math.radians(1.0), rel_tol=1e-6)
    points = np.array([[3.0, 0.0],     # 2 m in front of the wall
                       [4.8, 1.0],     # 0.2 m in front: within the 0.3 m margin, on the surface
                       [6.0, 0.5],     # 1 m behind the wall
                       [0.5, 3.0],     # bearing 80°, outside the ±45° beams
                       [-2.0, 0.0]])   # behind the sensor
    free, behind, on_surface = profile.verdicts(points, margin_m=0.3)
    assert free.tolist() == [True, False, False, False, False]
    assert behind.tolist() == [False, False, True, False, False]
    assert on_surface.tolist() == [False, True, False, False, False]
    assert on_seen_surfaces([profile], np.zeros((1, 3)), points, 0.3).tolist() == [False, True, False, False, False]


def test_a_point_on_a_grazed_wall_between_two_beams_is_neither_free_nor_behind() -> None:
    """A corridor wall y = 0.5 seen from its end: at 1° steps the beams hit it 0.4-0.9 m apart 3-5 m away. A
    point on the wall between two such hits lies behind the nearer one and in front of the farther one: the scan
    saw that surface, so it neither saw the point's place free nor hidden."""
    a = np.radians(np.arange(3.0, 46.0, 1.0))
    r = 0.5 / np.sin(a)
    profile = RangeProfile.of_scan(np.stack([r * np.cos(a), r * np.sin(a)], axis=1))
    between = math.radians(6.5)  # between the beams at 6° (4.78 m) and 7° (4.10 m)
    on_wall = np.array([[0.5 / math.tan(between), 0.5]])
    free, behind, on_surface = profile.verdicts(on_wall, margin_m=0.3)
    assert on_surface[0] and not free[0] and not behind[0]
    free, behind, _ = profile.verdicts(on_wall * 0.8, margin_m=0.3)  # 0.9 m short of the wall along it
    assert free[0] and not behind[0]


@settings(max_examples=50, deadline=None)
@given(st.floats(-5.0, 5.0), st.floats(-5.0, 5.0), st.floats(-math.pi, math.pi), st.floats(0.5, 8.0),
       st.floats(-40.0, 40.0))
def test_a_point_is_on_the_seen_wall_exactly_when_it_lies_within_the_margin_of_it(
        x: float, y: float, yaw: float, r: float, bearing_deg: float) -> None:
    """In the sensor frame and, with the scan at any pose, in the map frame."""
    pose = np.array([x, y, yaw])
    profile = RangeProfile.of_scan(_wall_scan())
    b = math.radians(bearing_deg)
    local = np.array([[r * math.cos(b), r * math.sin(b)]])
    free, behind, surface = profile.verdicts(local, 0.3)
    assert int(free[0]) + int(behind[0]) + int(surface[0]) == 1  # every bearing in ±40° has beams: one verdict
    on_surface = bool(on_seen_surfaces([profile], pose[None], transform_points(pose, local), 0.3)[0])
    assert on_surface == bool(surface[0])
    off_wall = 5.0 / math.cos(b) - r  # how far the wall lies beyond the point along its bearing
    if abs(abs(off_wall) - 0.3) > 0.05:  # away from the margin (the neighbouring beams hit within ±4 cm)
        assert bool(free[0]) == (off_wall > 0.3) and bool(behind[0]) == (off_wall < -0.3)
        assert on_surface == (abs(off_wall) < 0.3)


def test_a_point_is_on_a_seen_surface_when_more_scans_say_so_than_contradict_it() -> None:
    """Three scans of the wall x = 5 see (4.9, 0) on it; one more saw past that place, its wall 1 m farther (a
    pass whose pose was off, or a door open then): 3 votes to 1. Two against two is no longer on a seen surface,
    nor is a point only contradicting scans look at."""
    profile = RangeProfile.of_scan(_wall_scan())
    past = RangeProfile.of_scan(_wall_scan(distance_m=6.0))  # its wall lies 1 m farther
    point = np.array([[4.9, 0.0]])
    at = np.zeros((4, 3))
    assert on_seen_surfaces([profile] * 3 + [past], at, point, 0.3).tolist() == [True]
    assert on_seen_surfaces([profile] * 2 + [past] * 2, at, point, 0.3).tolist() == [False]
    assert on_seen_surfaces([past], at[:1], point, 0.3).tolist() == [False]


def test_the_beams_either_side_of_the_back_of_a_full_circle_scan_are_neighbours() -> None:
    """A 360° scan of a circular wall of radius 3 m: a point 3 m away straight behind (bearing ±π, between the
    last beam and the first) is on the wall, one 2 m away in front of it, whichever side of ±π it lies on."""
    a = np.radians(np.arange(-179.5, 180.0, 1.0))
    profile = RangeProfile.of_scan(np.stack([3.0 * np.cos(a), 3.0 * np.sin(a)], axis=1))
    for y in (1e-6, -1e-6):
        free, behind, on_surface = profile.verdicts(np.array([[-3.0, y], [-2.0, y]]), margin_m=0.3)
        assert on_surface.tolist() == [True, False] and free.tolist() == [False, True] and not behind.any()
