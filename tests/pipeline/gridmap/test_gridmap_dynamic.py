"""Transient and seen-occupied flags, dynamic end points (set 1) and fallen cells (set 2), paper 000 Sec. III."""

from __future__ import annotations

import numpy as np

from doorbatch.config import GridConfig
from doorbatch.pipeline.gridmap.dynamic import (
    begin_pass,
    classify_and_integrate,
    classify_endpoints,
    classify_scan,
    seen_free_grid,
    take_fallen_cells,
    take_fallen_points,
    transient_cells,
    update_transient,
)
from doorbatch.pipeline.gridmap.occupancy import LogOddsGrid, integrate_scan, new_grid

CFG = GridConfig(resolution_m=0.1, initial_size_m=2.0, transient_neighborhood_cells=1)
NO_DIRS = np.zeros((0, 2))


def _free_grid_with_wall() -> LogOddsGrid:
    """20 × 20 cells all seen free except an occupied wall in column 10 and the never-seen one-cell rim."""
    grid = new_grid(CFG, (1.0, 1.0))
    grid.log_odds[1:-1, 1:-1] = CFG.l_min
    grid.log_odds[1:-1, 10] = CFG.l_max
    return grid


def _centre(grid: LogOddsGrid, i: int, j: int) -> list[float]:
    return [grid.origin_x_m + (j + 0.5) * grid.resolution_m, grid.origin_y_m + (i + 0.5) * grid.resolution_m]


def test_cells_next_to_a_wall_are_not_transient() -> None:
    grid = _free_grid_with_wall()
    pts = [_centre(grid, 5, j) for j in (8, 9, 10, 11, 12)]
    assert classify_endpoints(grid, pts, CFG).tolist() == [True, False, False, False, True]
    assert grid.transient[5, 8] and not grid.transient[5, 9]


def test_neighbourhood_radius_two_keeps_two_cells_off_the_wall() -> None:
    cfg = CFG.model_copy(update={"transient_neighborhood_cells": 2})
    grid = new_grid(cfg, (1.0, 1.0))
    grid.log_odds[2:-2, 2:-2] = CFG.l_min
    grid.log_odds[2:-2, 10] = CFG.l_max
    pts = [_centre(grid, 5, j) for j in (7, 8, 9, 11, 12, 13)]
    assert classify_endpoints(grid, pts, cfg).tolist() == [True, False, False, False, False, True]


def test_neighbourhood_radius_zero_marks_every_seen_free_cell() -> None:
    cfg = CFG.model_copy(update={"transient_neighborhood_cells": 0})
    grid = _free_grid_with_wall()
    assert classify_endpoints(grid, [_centre(grid, 5, 9), _centre(grid, 5, 10)], cfg).tolist() == [True, False]


def test_a_transient_cell_stays_transient_and_seen_free_after_hits() -> None:
    grid = _free_grid_with_wall()
    target = _centre(grid, 5, 5)
    assert transient_cells(grid, [5 * 20 + 5], CFG).tolist() == [True]
    for _ in range(10):  # integrated on purpose, as if it were static
        grid = integrate_scan(grid, _centre(grid, 5, 2), [target], NO_DIRS, CFG)
    assert grid.log_odds[5, 5] > CFG.l_high
    assert seen_free_grid(grid, CFG)[5, 5]
    assert transient_cells(grid, [5 * 20 + 5], CFG).tolist() == [True]


def test_a_cell_that_was_free_without_its_neighbourhood_is_not_transient_later() -> None:
    grid = _free_grid_with_wall()
    grid.log_odds[5, 5] = CFG.l_max  # re-occupied before its neighbourhood was checked
    assert transient_cells(grid, [5 * 20 + 5], CFG).tolist() == [False]


def test_points_outside_the_grid_are_static() -> None:
    grid = _free_grid_with_wall()
    assert classify_endpoints(grid, [[50.0, 50.0], [-1.0, 0.5], [0.35, 0.45]], CFG).tolist() == [False, False, True]


def test_update_transient_matches_the_lazy_flag() -> None:
    rng = np.random.default_rng(3)
    grid = new_grid(CFG, (1.0, 1.0))
    grid.log_odds[1:-1, 1:-1] = rng.choice([CFG.l_min, 0.0, CFG.l_max], size=(18, 18), p=[0.8, 0.1, 0.1])
    lazy = transient_cells(grid, np.arange(400), CFG).reshape(20, 20)
    assert lazy.any() and not lazy.all()
    grid.transient[:] = False
    update_transient(grid, CFG)
    assert np.array_equal(grid.transient, lazy)


def test_a_seen_occupied_cell_that_falls_low_gives_its_cell_mean_once() -> None:
    grid = new_grid(CFG, (1.0, 1.0))
    origin, target = [0.25, 0.25], [1.23, 0.27]
    begin_pass(grid, CFG)
    for _ in range(5):
        grid = integrate_scan(grid, origin, [target], NO_DIRS, CFG)
    assert grid.seen_occupied[2, 12]
    start = grid.scan_count
    begin_pass(grid, CFG)
    for _ in range(20):  # the object left: beams now pass through the cell
        grid = integrate_scan(grid, origin, [[1.85, 0.25]], NO_DIRS, CFG)
    points = take_fallen_points(grid, CFG, since_scan=start)
    np.testing.assert_allclose(points, [target], atol=1e-5)
    assert not grid.seen_occupied[2, 12]
    assert take_fallen_cells(grid, CFG, since_scan=start).size == 0


def test_a_cell_falls_by_the_evidence_of_its_pass_alone() -> None:
    """A saturated cell seen free a few times in a pass (a leaf seen obliquely through a doorway) is not
    below p_transient_below overall, but the pass's own evidence is: it falls."""
    grid = new_grid(CFG, (1.0, 1.0))
    begin_pass(grid, CFG)
    grid.log_odds[2, 12] = CFG.l_max
    grid.seen_occupied[2, 12] = True
    grid.last_hit_scan[2, 12] = 0
    grid.scan_count = 10
    begin_pass(grid, CFG)
    n_free = int(np.ceil(-CFG.l_low / -CFG.l_free))  # free updates that bring an unknown cell below the level
    grid.log_odds[2, 12] = CFG.l_max + (n_free - 1) * CFG.l_free
    assert take_fallen_cells(grid, CFG, since_scan=10).size == 0  # one update short
    grid.log_odds[2, 12] = CFG.l_max + n_free * CFG.l_free
    assert grid.log_odds[2, 12] > CFG.l_low  # still not low overall …
    assert take_fallen_cells(grid, CFG, since_scan=10).tolist() == [2 * 20 + 12]  # … but gone in this pass


def test_a_cell_still_hit_during_the_pass_is_not_returned_and_stays_seen_occupied() -> None:
    """A wall on a cell border flickers between hit and free within a pass: it is a surface present in
    the pass, not an object that left, and its flag keeps it out of the next pass's dynamic points."""
    grid = new_grid(CFG, (1.0, 1.0))
    grid.seen_occupied[2, 12] = True
    begin_pass(grid, CFG)
    grid.log_odds[2, 12] = CFG.l_low - 1.0
    grid.last_hit_scan[2, 12] = 7
    assert take_fallen_cells(grid, CFG, since_scan=5).size == 0
    assert grid.seen_occupied[2, 12]


def test_points_near_structure_known_before_the_pass_are_static() -> None:
    """Transient cells next to a cell seen occupied before the pass (a wall that grazing beams cleared)
    hold no dynamic measurements; farther than the neighbourhood they do."""
    grid = new_grid(CFG, (1.0, 1.0))
    grid.log_odds[1:-1, 1:-1] = CFG.l_min
    grid.seen_occupied[5, 10] = True  # e.g. a wall cell that was hit, then cleared by grazing beams
    begin_pass(grid, CFG)
    pts = [_centre(grid, 5, j) for j in (9, 11, 12)]
    assert classify_endpoints(grid, pts, CFG).tolist() == [False, False, True]
    # the mapper's compiled paths (classify_scan's kernel, and the fused classify-and-integrate step) agree
    assert classify_scan(grid, pts, CFG).dynamic.tolist() == [False, False, True]
    _, classes = classify_and_integrate(grid, _centre(grid, 12, 10), pts, NO_DIRS, CFG)
    assert classes.dynamic.tolist() == [False, False, True]
