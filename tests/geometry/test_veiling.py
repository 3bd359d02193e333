"""Veiling (mixed pixels): ScanShadowsFilter's incidence test on known scan geometry."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.veiling import veiling_mask

STEP = math.radians(0.5)
MIN = math.radians(10.0)


def _wall_ranges(distance_m: float, bearings: np.ndarray, normal: float = 0.0) -> np.ndarray:
    """Ranges to an infinite wall ``distance_m`` from the laser whose normal points at bearing ``normal``."""
    return distance_m / np.cos(bearings - normal)


def test_a_wall_seen_face_on_keeps_every_point() -> None:
    bearings = np.arange(-40, 41) * STEP
    assert not veiling_mask(_wall_ranges(3.0, bearings), STEP, MIN).any()


def test_a_point_between_a_leaf_edge_and_the_wall_behind_is_veiling_and_so_are_the_edge_points() -> None:
    r = np.array([2.0] * 10 + [3.4] + [5.0] * 10)  # leaf at 2 m, a mixed pixel, the wall behind at 5 m
    mask = veiling_mask(r, STEP, MIN)
    assert mask[10]  # the mixed pixel
    assert mask[9] and mask[11]  # both ends of the jump (laser_filters removes them too)
    assert not mask[:9].any() and not mask[12:].any()


def test_a_surface_at_grazing_incidence_is_dropped_below_the_angle_and_kept_above() -> None:
    """On a plane, the angle at a point between the ray back to the laser and the next point is the incidence."""
    bearings = np.arange(0, 11) * STEP
    for incidence_deg, dropped in ((5.0, True), (15.0, False)):
        normal = math.radians(90.0 - incidence_deg) + 5 * STEP  # the middle beam meets the wall at that incidence
        mask = veiling_mask(_wall_ranges(1.0, bearings, normal), STEP, MIN)
        assert bool(mask[5]) is dropped


def test_no_return_and_error_codes_are_not_measured_points() -> None:
    """A laser that writes range_max for no return (Gazebo) or a tiny error code (Hokuyo): such a beam beside a hit is
    no depth jump, and it stays a no-return (it clears free space)."""
    r = np.array([3.0] * 4 + [30.0] * 4)  # range_max 30: the last four returned nothing
    assert not veiling_mask(r, STEP, MIN, range_max_m=30.0).any()
    r = np.array([3.0] * 4 + [0.005] + [3.0] * 4)  # an error code below range_min between hits
    assert not veiling_mask(r, STEP, MIN, range_min_m=0.02).any()


@settings(max_examples=50, deadline=None)
@given(st.lists(st.one_of(st.floats(0.05, 30.0), st.just(math.inf), st.just(math.nan)), min_size=2, max_size=60))
def test_beams_without_a_finite_range_are_never_marked(ranges: list[float]) -> None:
    r = np.asarray(ranges)
    mask = veiling_mask(r, STEP, MIN, window=2)
    assert not mask[~np.isfinite(r)].any()
    # an equal-range arc (a circle around the laser: incidence 90°) is never veiling
    assert not veiling_mask(np.full(r.shape[0], 2.0), STEP, MIN, window=2).any()


def test_a_recording_read_with_the_filter_drops_exactly_the_veiling_beams(write_log: Callable[..., Path]) -> None:
    """``io.veiling_min_angle_deg`` (off by default): the beams the mask marks read as NaN (no information: neither a
    hit nor a no-return), every other beam as before."""
    from doorbatch.config import DoorbatchConfig
    from doorbatch.io.recording import load_recording

    path = write_log("scans.mcap")
    plain = load_recording(path, DoorbatchConfig())
    filtered = load_recording(path, DoorbatchConfig.model_validate({"io": {"veiling_min_angle_deg": 10.0}}))
    marked = 0
    for i in range(len(plain.scans)):
        r = plain.scans.ranges[i]
        mask = veiling_mask(r, float(plain.scans.angle_increment[i]), math.radians(10.0))
        marked += int(mask.sum())
        assert np.all(np.isnan(filtered.scans.ranges[i][mask]))
        assert np.array_equal(filtered.scans.ranges[i][~mask], r[~mask], equal_nan=True)
    assert marked > 0
