"""Transient and seen-occupied flags, dynamic end points (set 1) and fallen cells (set 2), paper 000 Sec. III."""

from __future__ import annotations

import numpy as np

from doorbatch.config import GridConfig
from doorbatch.pipeline.gridmap.dynamic import (
    classify_endpoints,
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
    for _ in range(5):
        grid = integrate_scan(grid, origin, [target], NO_DIRS, CFG)
    assert grid.seen_occupied[2, 12]
    start = grid.scan_count
    for _ in range(20):  # the object left: beams now pass through the cell
        grid = integrate_scan(grid, origin, [[1.85, 0.25]], NO_DIRS, CFG)
    points = take_fallen_points(grid, CFG, since_scan=start)
    np.testing.assert_allclose(points, [target], atol=1e-5)
    assert not grid.seen_occupied[2, 12]
    assert take_fallen_cells(grid, CFG, since_scan=start).size == 0


def test_a_cell_still_hit_during_the_pass_is_consumed_but_not_returned() -> None:
    grid = new_grid(CFG, (1.0, 1.0))
    grid.log_odds[2, 12] = CFG.l_low - 1.0
    grid.seen_occupied[2, 12] = True
    grid.last_hit_scan[2, 12] = 7
    assert take_fallen_cells(grid, CFG, since_scan=5).size == 0
    assert not grid.seen_occupied[2, 12]
