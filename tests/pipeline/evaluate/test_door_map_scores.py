"""Door-map scoring: greedy hinge matching, opening-range error, static-map agreement (known answers)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from doorbatch.maps import DoorSet
from doorbatch.pipeline.evaluate.door_map import match_by_hinge, score_doors, score_static_map


def _doors(hinge: list[tuple[float, float]], closed_yaw: list[float], angle_min: list[float],
           angle_max: list[float]) -> DoorSet:
    """Doors of leaf 0.9 m."""
    return DoorSet(np.array(hinge, dtype=np.float64).reshape(-1, 2), np.full(len(hinge), 0.9),
                   np.array(closed_yaw), np.array(angle_min), np.array(angle_max))


def test_hinges_match_greedily_by_increasing_distance() -> None:
    """Detected (0, 0), (0.21, 0); truth (0.2, 0), (−0.25, 0); within 0.3 m. Distances: d1–t0 0.01, d0–t0 0.2,
    d0–t1 0.25 (d1–t1 0.46 is too far). Closest first: d1↔t0, then d0↔t1 (t0 is taken). Matching in row order
    would pair d0↔t0 and leave d1 with nothing."""
    matched, dist = match_by_hinge([[0.0, 0.0], [0.21, 0.0]], [[0.2, 0.0], [-0.25, 0.0]], 0.3)
    assert matched == [(1, 0), (0, 1)]
    np.testing.assert_allclose(dist, [[0.2, 0.25], [0.01, 0.46]], atol=1e-12)


def test_an_opening_range_with_swapped_ends_has_no_range_error() -> None:
    """Truth leaf from 0 to 1.5 rad (closed_yaw 0, range [0, 1.5]); the detection gives the same two ends in the
    other order (range [1.5, 0]). The range error takes either orientation of the range (``_range_error``), so
    the ends coincide: error 0 (the same orientation alone would give 1.5 rad at both ends)."""
    truth = _doors([(1.0, 2.0)], [0.0], [0.0], [1.5])
    detected = _doors([(1.0, 2.0)], [0.0], [1.5], [0.0])
    score = score_doors(detected, truth, [True])
    assert score.matches == [(0, 0)] and score.precision == 1.0 and score.recall == 1.0
    np.testing.assert_allclose(score.range_error_rad, [0.0], atol=1e-12)


def test_range_error_is_the_larger_end_difference() -> None:
    """Truth [0, 1.5] against detected [0.1, 1.2] (same orientation): ends 0.1 and 0.3 rad off → 0.3."""
    truth = _doors([(0.0, 0.0)], [0.0], [0.0], [1.5])
    detected = _doors([(0.05, 0.0)], [0.0], [0.1], [1.2])
    score = score_doors(detected, truth, [True])
    np.testing.assert_allclose(score.range_error_rad, [0.3], atol=1e-12)
    np.testing.assert_allclose(score.hinge_error_m, [0.05], atol=1e-12)
    assert math.isclose(float(score.length_error_m[0]), 0.0, abs_tol=1e-12)


@pytest.mark.parametrize(("column", "agreement", "spurious"), [
    (3, 1.0, 0),  # one cell off the wall, within the tolerance of 1: all 6 observed cells agree
    (4, 5 / 6, 1),  # two cells off: spurious, 5 of 6 agree
])
def test_an_occupied_cell_agrees_within_the_tolerance_of_a_truth_wall(column: int, agreement: float,
                                                                    spurious: int) -> None:
    """Truth wall in column 2 of a 5 × 5 grid; the estimate: free cells in column 0 and one occupied cell."""
    truth = np.zeros((5, 5), dtype=np.int8)
    truth[:, 2] = 100
    estimate = np.full((5, 5), -1, dtype=np.int8)
    estimate[2, column] = 100
    estimate[:, 0] = 0
    score = score_static_map(estimate, truth, tolerance_cells=1)
    assert score.observed_cells == 6 and score.spurious_occupied_cells == spurious
    assert math.isclose(score.agreement, agreement)


def test_a_map_without_doors_has_no_precision_and_a_truth_without_doors_no_recall() -> None:
    """No detection against two truth doors: precision is undefined (NaN), not a perfect 1.0, and recall is 0;
    a detection against a truth with no door counted: precision 0, recall undefined."""
    truth = _doors([(0.0, 0.0), (3.0, 0.0)], [0.0, 0.0], [0.0, 0.0], [1.5, 1.5])
    empty = _doors([], [], [], [])
    score = score_doors(empty, truth, [True, True])
    assert math.isnan(score.precision) and score.recall == 0.0 and score.missed == [0, 1]
    score = score_doors(truth, empty, [])
    assert score.precision == 0.0 and math.isnan(score.recall) and score.false_positives == [0, 1]


def test_a_door_that_never_moved_is_scored_at_the_nearer_end_of_its_leaf() -> None:
    # truth: hinges at x = 0 and x = 5, leaves 0.9 m along +x, closed. The map's second door never moved and has its
    # hinge at the free end (5.9, 0) looking back (−x): the same leaf. The first moved: its hinge is known.
    truth = _doors([(0.0, 0.0), (5.0, 0.0)], [0.0, 0.0], [0.0, 0.0], [1.5, 0.0])
    detected = _doors([(0.0, 0.0), (5.9, 0.0)], [0.0, math.pi], [0.0, 0.0], [1.5, 0.0])
    blind = score_doors(detected, truth, [True, True])
    assert blind.precision == 0.5 and blind.missed == [1]
    score = score_doors(detected, truth, [True, True], hinge_unknown=[False, True])
    assert score.precision == 1.0 and score.recall == 1.0
    assert np.allclose(score.hinge_error_m, 0.0, atol=1e-9) and np.allclose(score.range_error_rad, 0.0, atol=1e-9)
    # a door whose hinge is known keeps it: the first door mapped at its free end is not moved onto the truth
    wrong_end = _doors([(0.9, 0.0)], [math.pi], [0.0], [1.5])
    assert score_doors(wrong_end, truth, [True, True], hinge_unknown=[False]).precision == 0.0
    # a never-moved leaf across the first doorway (hinged 1.1 m off the truth hinge, pointing back at it): its free
    # end lies 0.2 m from the truth hinge, but it is not the truth's leaf, flipped or not (rev40)
    across = _doors([(0.0, 1.1)], [-math.pi / 2], [0.0], [0.0])
    assert score_doors(across, truth, [True, True], hinge_unknown=[True]).precision == 0.0
