"""Laser conventions: upside-down lasers, NaN/inf/range limits, points in base_link."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.laser import beam_masks, dropouts, scan_points, wraps_around
from doorbatch.geometry.rotations import transform_matrix
from doorbatch.records import Scan


def _scan(ranges: np.ndarray, angle_min: float, inc: float) -> Scan:
    return Scan(0, 0, "laser", angle_min, inc, 0.1, 20.0, ranges.astype(np.float32))


@settings(max_examples=50, deadline=None)
@given(st.integers(10, 400), st.floats(0.5, 3.0), st.floats(-0.5, 0.5), st.floats(-math.pi, math.pi),
       st.integers(0, 2**31))
def test_upside_down_laser_with_negative_increment_gives_upright_points(
    n: int, fov: float, tx: float, yaw: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    ranges = rng.uniform(0.2, 15.0, n)
    inc = fov / (n - 1)
    upright = _scan(ranges, -fov / 2, inc)
    mount_up = transform_matrix([tx, 0.1, 0.4], [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])
    # Rotated 180° about x: laser y points to base −y. The same physical beams then have angles −θ,
    # listed in the same physical order, i.e. starting at +fov/2 with a negative increment.
    flip_x = transform_matrix([0, 0, 0], [1.0, 0.0, 0.0, 0.0])
    flipped = _scan(ranges, fov / 2, -inc)
    a = scan_points(upright, mount_up)
    b = scan_points(flipped, mount_up @ flip_x)
    np.testing.assert_allclose(a.points, b.points, atol=1e-9)
    np.testing.assert_array_equal(a.beam_index, b.beam_index)


def test_beam_masks_follow_the_conventions() -> None:
    ranges = np.array([np.nan, np.inf, 20.0, 25.0, 0.05, 5.0], dtype=np.float32)
    hit, no_return = beam_masks(_scan(ranges, 0.0, 0.1))
    assert hit.tolist() == [False, False, False, False, False, True]
    assert no_return.tolist() == [False, True, True, True, False, False]


def test_points_of_a_known_scan() -> None:
    scan = _scan(np.array([1.0, 2.0, 3.0]), -math.pi / 2, math.pi / 2)
    pts = scan_points(scan, transform_matrix([1.0, 0.0, 0.0], [0, 0, 0, 1])).points
    np.testing.assert_allclose(pts, [[1.0, -1.0], [3.0, 0.0], [1.0, 3.0]], atol=1e-12)


def test_dropouts_are_short_runs_of_no_return_between_two_hits() -> None:
    h, n = True, False  # hit / no return, beam by beam; 2 beams at most
    hit = np.array([n, h, n, h, n, n, h, n, n, n, h, n, h, h, n])
    no_return = ~hit
    assert np.flatnonzero(dropouts(no_return, hit, 2)).tolist() == [2, 4, 5, 11]  # not the ends, not the 3-run
    assert np.flatnonzero(dropouts(no_return, hit, 3)).tolist() == [2, 4, 5, 7, 8, 9, 11]
    assert not dropouts(no_return, hit, 0).any()
    nan_between = np.array([h, n, h])  # a NaN beam is neither hit nor no return: nothing to keep from clearing
    assert not dropouts(np.array([False, False, False]), nan_between, 2).any()


def test_a_nan_beam_is_a_lost_echo_in_the_run_it_lies_in() -> None:
    """hit, no return, NaN, hit: two beams lost between two hits, so the no-return one is a dropout (with one
    beam at most, the run is too long); hit, no return, NaN, NaN, hit: three, none with two at most."""
    nan = float("nan")
    for ranges, max_beams, want in (([1.0, np.inf, nan, 1.0], 2, [1]), ([1.0, np.inf, nan, 1.0], 1, []),
                                    ([1.0, nan, np.inf, nan, 1.0], 3, [2]), ([1.0, np.inf, nan, nan, 1.0], 2, [])):
        r = np.array(ranges)
        assert np.flatnonzero(dropouts(np.isposinf(r), np.isfinite(r), max_beams)).tolist() == want


def test_a_run_across_the_first_beam_of_a_full_circle_is_one_run() -> None:
    """A 360° laser: beams 0 and 359 are neighbours, so no return on 359 and 0 between hits on 358 and 1 is a
    two-beam run, a dropout; a 270° laser's ends are ends."""
    ranges = np.full(360, 2.0)
    ranges[[359, 0]] = np.inf
    nr, hit = np.isposinf(ranges), np.isfinite(ranges)
    assert wraps_around(np.radians(1.0), 360) and not wraps_around(np.radians(0.25), 1081)
    assert np.flatnonzero(dropouts(nr, hit, 2, wraps=True)).tolist() == [0, 359]
    assert not dropouts(nr, hit, 1, wraps=True).any()
    assert not dropouts(nr, hit, 2, wraps=False).any()


def _run_around(gap: np.ndarray, i: int, wraps: bool) -> tuple[int, bool]:
    """Length of the run of beams without a hit that holds beam i, and whether a hit lies on each side of it."""
    n = gap.shape[0]
    length, flanked = 1, True
    for step in (-1, 1):
        j = i + step
        while True:
            if not wraps and not 0 <= j < n:
                flanked = False
                break
            if not gap[j % n]:
                break
            length += 1
            if length >= n:
                return n, False
            j += step
    return length, flanked


@given(st.lists(st.sampled_from(["hit", "none", "nan"]), min_size=1, max_size=40), st.integers(0, 4),
       st.booleans())
def test_dropouts_are_exactly_the_no_returns_in_short_runs_flanked_by_hits(kinds: list[str], max_beams: int,
                                                                           wraps: bool) -> None:
    hit = np.array([k == "hit" for k in kinds])
    no_return = np.array([k == "none" for k in kinds])
    d = dropouts(no_return, hit, max_beams, wraps)
    for i in range(len(kinds)):
        length, flanked = _run_around(~hit, i, wraps) if not hit[i] else (0, False)
        assert d[i] == (bool(no_return[i]) and flanked and length <= max_beams)
