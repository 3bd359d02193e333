"""The em stage's doors leave the static map as the grid stage's do (mapping.without_leaves)."""

from __future__ import annotations

import math

import numpy as np

from doorbatch.config import DoorbatchConfig
from doorbatch.io.preview import PreviewDoor
from doorbatch.pipeline.gridmap.occupancy import new_grid, to_occupancy_map
from doorbatch.pipeline.mapping import DoorMap, without_leaves

CFG = DoorbatchConfig()


def _occupied(occ: np.ndarray, grid_cell: tuple[int, int]) -> bool:
    return bool(occ[grid_cell] >= 65)


def _door_map_with_an_open_leaf() -> tuple[DoorMap, np.ndarray, np.ndarray, np.ndarray]:
    """A wall along y = 0 with a 0.9 m doorway at x ∈ [0, 0.9] and a leaf standing open at 90° from the hinge
    (0, 0) (a door that never moved while mapping: the grid stage kept its leaf), free space around."""
    gcfg = CFG.grid
    grid = new_grid(gcfg, (0.0, 0.0), 6.0)
    grid.log_odds[:] = gcfg.l_min
    wall = np.stack([np.concatenate([np.arange(-2.0, 0.0, 0.025), np.arange(0.9, 2.0, 0.025)]),
                     np.zeros(124)], 1)
    leaf = np.stack([np.zeros(36), np.linspace(0.025, 0.9, 36)], 1)
    flat = grid.log_odds.reshape(-1)
    flat[grid.flat_index(wall)] = gcfg.l_max
    flat[grid.flat_index(leaf)] = gcfg.l_max
    door_map = DoorMap(to_occupancy_map(grid), [], [], "reference", 0, grid=grid)
    return door_map, grid.flat_index(leaf), grid.flat_index(wall), grid.flat_index([[0.0, 0.0]])


def test_an_em_door_that_never_moved_leaves_the_static_map_but_its_hinge_and_the_wall_stay() -> None:
    door_map, leaf, wall, hinge = _door_map_with_an_open_leaf()
    door = PreviewDoor(0.0, 0.0, 0.9, 0.0, math.pi / 2, math.pi / 2, moved=False)
    out = without_leaves(door_map, [door], CFG)
    before = door_map.static_map.occupancy.reshape(-1)
    after = out.static_map.occupancy.reshape(-1)
    centres = out.grid.cell_centers(leaf)  # type: ignore[union-attr]
    beyond_hinge = np.hypot(*centres.T) > CFG.doors.hinge_keep_m + 0.05
    assert np.all(before[leaf] >= 65)
    assert beyond_hinge.sum() >= 10 and np.all(after[leaf[beyond_hinge]] < 65)
    assert after[hinge[0]] >= 65
    assert np.all(after[wall] >= 65)
    # the grid stage's map is not changed in place
    assert np.all(door_map.static_map.occupancy.reshape(-1)[leaf] >= 65)


def test_a_door_elsewhere_or_no_door_changes_nothing() -> None:
    door_map, *_ = _door_map_with_an_open_leaf()
    assert without_leaves(door_map, [], CFG) is door_map
    far = PreviewDoor(10.0, 10.0, 0.9, 0.0, 0.0, 1.0)
    out = without_leaves(door_map, [far], CFG)
    np.testing.assert_array_equal(out.static_map.occupancy, door_map.static_map.occupancy)
