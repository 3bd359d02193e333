"""Log-odds grid: exact cells of known beams, one update per cell per scan, clearing, growth, map output."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gridmap_sim import cast
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.config import GridConfig
from doorbatch.maps import UNKNOWN
from doorbatch.pipeline.gridmap.occupancy import (
    LogOddsGrid,
    free_fraction,
    integrate_scan,
    integrate_scan_numpy,
    new_grid,
    to_occupancy_map,
)

# surface_band_m = 0: these tests check the DDA's exact cells; the band has its own tests below.
CFG = GridConfig(resolution_m=0.1, initial_size_m=2.0, growth_margin_m=0.5, surface_band_m=0.0)
NO_DIRS = np.zeros((0, 2))
FREE, OCC = float(np.float32(CFG.l_free)), float(np.float32(CFG.l_occ))


def _grid() -> LogOddsGrid:
    """A 20 × 20 grid of 0.1 m cells with its corner at the world origin."""
    grid = new_grid(CFG, (1.0, 1.0))
    assert (grid.origin_x_m, grid.origin_y_m, grid.shape) == (0.0, 0.0, (20, 20))
    return grid


def _cells(grid: LogOddsGrid, value: float) -> set[tuple[int, int]]:
    """(column j, row i) of the cells holding ``value``."""
    ii, jj = np.nonzero(np.isclose(grid.log_odds, value))
    return set(zip(jj.tolist(), ii.tolist(), strict=True))


def test_wall_beam_marks_its_end_cell_occupied_and_the_cells_before_free() -> None:
    grid = integrate_scan(_grid(), (0.25, 0.25), [[1.05, 0.25]], NO_DIRS, CFG)
    assert _cells(grid, CFG.l_occ) == {(10, 2)}
    assert _cells(grid, CFG.l_free) == {(j, 2) for j in range(2, 10)}
    assert np.count_nonzero(grid.log_odds) == 9


def test_oblique_beam_visits_the_dda_cells() -> None:
    # Δ = (5, 3) cells: 5 steps of (1, 0.6) from (2.5, 2.5) → cells (2,2) (3,3) (4,3) (5,4) (6,4); end (7,5).
    grid = integrate_scan(_grid(), (0.25, 0.25), [[0.75, 0.55]], NO_DIRS, CFG)
    assert _cells(grid, CFG.l_occ) == {(7, 5)}
    assert _cells(grid, CFG.l_free) == {(2, 2), (3, 3), (4, 3), (5, 4), (6, 4)}


def test_a_cell_crossed_by_many_beams_gets_one_free_update_per_scan() -> None:
    angles = np.linspace(0.1, 0.7, 50)
    points = 0.25 + 1.2 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    grid = integrate_scan(_grid(), (0.25, 0.25), points, NO_DIRS, CFG)
    assert set(np.unique(grid.log_odds[grid.log_odds != 0]).tolist()) <= {FREE, OCC}
    assert grid.log_odds[2, 2] == pytest.approx(CFG.l_free)
    grid = integrate_scan(grid, (0.25, 0.25), points, NO_DIRS, CFG)
    assert grid.log_odds[2, 2] == pytest.approx(2 * CFG.l_free)


def test_an_end_cell_is_not_also_freed_by_a_longer_beam_of_the_same_scan() -> None:
    grid = integrate_scan(_grid(), (0.25, 0.25), [[0.65, 0.25], [1.45, 0.25], [0.62, 0.28]], NO_DIRS, CFG)
    assert grid.log_odds[2, 6] == pytest.approx(CFG.l_occ)  # two hits, one occupied update
    assert grid.log_odds[2, 14] == pytest.approx(CFG.l_occ)
    assert grid.log_odds[2, 10] == pytest.approx(CFG.l_free)
    assert grid.hits[2, 6] == 1  # counted once per scan


def test_no_return_beams_clear_up_to_no_return_clear_m_only() -> None:
    cfg = CFG.model_copy(update={"no_return_clear_m": 1.0})
    grid = integrate_scan(_grid(), (0.25, 0.25), np.zeros((0, 2)), [[1.0, 0.0]], cfg)
    row = grid.log_odds[2]
    assert np.allclose(row[2:12], cfg.l_free)  # x from 0.25 to 1.25 (exclusive)
    assert np.all(row[12:] == 0.0) and np.all(row[:2] == 0.0)
    assert not np.any(grid.log_odds == np.float32(cfg.l_occ))
    off = CFG.model_copy(update={"no_return_clear_m": 0.0})
    assert not np.any(integrate_scan(_grid(), (0.25, 0.25), np.zeros((0, 2)), [[1.0, 0.0]], off).log_odds)


@pytest.mark.parametrize("integrate", [integrate_scan, integrate_scan_numpy])
def test_no_return_beams_clear_no_farther_than_the_scans_range_max(integrate: object) -> None:
    # A 0.6 m lidar's no-return reading says nothing lies within 0.6 m; beyond it nothing was seen.
    cfg = CFG.model_copy(update={"no_return_clear_m": 1.0})
    grid = integrate(_grid(), (0.25, 0.25), np.zeros((0, 2)), [[1.0, 0.0]], cfg, None, 0.6)  # type: ignore[operator]
    row = grid.log_odds[2]
    assert np.allclose(row[2:8], cfg.l_free)  # x from 0.25 to 0.85 (exclusive)
    assert np.all(row[8:] == 0.0)


def test_hits_beyond_max_range_only_clear_up_to_max_range() -> None:
    cfg = CFG.model_copy(update={"max_range_m": 0.5})
    grid = integrate_scan(_grid(), (0.25, 0.25), [[1.55, 0.25]], NO_DIRS, cfg)
    assert not np.any(np.isclose(grid.log_odds, cfg.l_occ))
    assert np.allclose(grid.log_odds[2, 2:7], cfg.l_free)
    assert np.all(grid.log_odds[2, 8:] == 0.0)


def test_dynamic_end_points_clear_their_beam_but_are_not_integrated() -> None:
    grid = integrate_scan(_grid(), (0.25, 0.25), [[1.05, 0.25], [0.25, 1.05]], NO_DIRS, CFG,
                          dynamic_mask=[True, False])
    assert grid.log_odds[2, 10] == 0.0 and grid.hits[2, 10] == 0
    assert np.allclose(grid.log_odds[2, 3:10], CFG.l_free)
    assert grid.log_odds[10, 2] == pytest.approx(CFG.l_occ)


def test_growth_keeps_integrated_cells_at_their_world_position() -> None:
    grid = integrate_scan(_grid(), (0.25, 0.25), [[1.05, 0.25]], NO_DIRS, CFG)
    before = grid.log_odds.copy()
    grown = integrate_scan(grid, (0.25, 0.25), [[-3.05, -2.55], [0.25, 5.95]], NO_DIRS, CFG)
    assert grown is not grid
    assert grown.origin_x_m < -3.05 and grown.origin_y_m < -2.55
    assert grown.contains([[0.25, 5.95], [-3.05, -2.55]]).all()
    for x, y in [(1.05, 0.25), (0.55, 0.25)]:
        (k,) = grid.flat_index([[x, y]])
        (m,) = grown.flat_index([[x, y]])
        assert grown.log_odds.reshape(-1)[m] == before.reshape(-1)[k]
    i = round(-grown.origin_y_m / CFG.resolution_m)
    j = round(-grown.origin_x_m / CFG.resolution_m)
    assert math.isclose(grown.origin_x_m + j * CFG.resolution_m, 0.0, abs_tol=1e-9)
    assert np.array_equal(grown.log_odds[i:i + 20, j:j + 20][2, 10:11], before[2, 10:11])
    assert grown.log_odds[i + 2, j + 10] == pytest.approx(CFG.l_occ)


def test_growth_is_amortized() -> None:
    grid = _grid()
    shapes = set()
    for k in range(200):
        grid = integrate_scan(grid, (0.1 * k, 0.25), [[0.1 * k + 1.0, 0.25]], NO_DIRS, CFG)
        shapes.add(grid.shape)
    assert len(shapes) <= 6


def test_occupancy_map_has_unknown_free_and_occupied_cells() -> None:
    grid = integrate_scan(_grid(), (0.25, 0.25), [[1.05, 0.25]], NO_DIRS, CFG)
    grid = integrate_scan(grid, (0.25, 0.25), [[1.05, 0.25]], NO_DIRS, CFG)
    occ_map = to_occupancy_map(grid)
    assert occ_map.occupancy.shape == grid.shape
    assert occ_map.occupancy[2, 10] > 65 and 0 <= occ_map.occupancy[2, 5] < 35
    assert occ_map.occupancy[10, 10] == UNKNOWN
    assert (occ_map.origin_x_m, occ_map.origin_y_m, occ_map.resolution_m) == (0.0, 0.0, 0.1)
    assert occ_map.world_to_cell([1.05, 0.25]).tolist() == [2, 10]


@settings(max_examples=40, deadline=None)
@given(st.floats(-3, 3), st.floats(-3, 3), st.integers(1, 60), st.integers(0, 2**31 - 1))
def test_one_scan_changes_each_cell_by_at_most_one_update(ox: float, oy: float, n: int, seed: int) -> None:
    ox, oy = ox + 0.0123, oy + 0.0371  # off cell borders, where float32 and float64 floors may differ
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.05, 4.0, n)
    a = rng.uniform(-math.pi, math.pi, n)
    points = np.stack([ox + r * np.cos(a), oy + r * np.sin(a)], axis=1)
    grid = integrate_scan(new_grid(CFG, (0.0, 0.0)), (ox, oy), points, NO_DIRS, CFG)
    assert set(np.unique(grid.log_odds).tolist()) <= {0.0, FREE, OCC}
    assert np.allclose(grid.log_odds.reshape(-1)[grid.flat_index(points)], CFG.l_occ)
    (origin_cell,) = grid.flat_index([[ox, oy]])
    assert grid.log_odds.reshape(-1)[origin_cell] != 0.0


def test_a_beam_stops_clearing_one_band_before_the_surface_it_hit() -> None:
    """free_fraction: 1 − band / (r sin θ), θ from the nearer neighbouring end point."""
    wall = np.stack([np.linspace(0.5, 1.5, 11), np.full(11, 1.0)], axis=1)  # a wall y = 1, seen from (1, 0)
    frac = free_fraction(wall, 1.0, 0.0, 0.05)
    r = np.hypot(wall[:, 0] - 1.0, 1.0)
    sin = 1.0 / r  # the beam's angle to the wall: sin θ = distance to the wall / range
    np.testing.assert_allclose(frac, 1.0 - 0.05 / (r * sin), atol=1e-12)
    grazing = np.stack([np.linspace(5.0, 6.0, 11), np.full(11, 1.0)], axis=1)  # seen from (0, 0.9): 1°
    assert np.all(free_fraction(grazing, 0.0, 0.9, 0.05) < 0.5)


def test_grazing_beams_do_not_clear_a_wall_on_a_cell_border() -> None:
    """A wall on a cell border (y = 1 m) puts its hits into two rows of cells. Seen from 6–12 m away at
    2–5°, a cell of it is rarely a beam's end point, but beams that end farther along the wall pass
    through its near-side row for metres: without the surface band that row goes below
    p_transient_below (and its wall points would turn dynamic); with it, it is never cleared."""
    wall = np.array([[[0.0, 1.0], [30.0, 1.0]]])
    angles = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    near_row = [[x, 0.975] for x in np.arange(6.0, 12.0, 0.05)]
    lowest = {}
    for band in (0.05, 0.0):
        cfg = GridConfig(surface_band_m=band)
        rng = np.random.default_rng(4)
        grid = new_grid(cfg, (10.0, 1.0))
        for x0 in np.linspace(0.5, 2.5, 20):
            origin = np.array([x0, 0.5])
            r = cast(origin, dirs, wall) + rng.normal(0.0, 0.01, angles.size)
            hit = r < 20.0
            grid = integrate_scan(grid, origin, origin + r[hit, None] * dirs[hit], dirs[~hit], cfg)
        lowest[band] = float(grid.log_odds.reshape(-1)[grid.flat_index(near_row)].min())
    assert lowest[0.05] >= 0.0
    assert lowest[0.0] < GridConfig().l_low
