"""The grid stage on simulated passes: doors found to tolerance, no false doors, people leave no trace."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest
from gridmap_sim import Corridor, Door, scan_pass

from doorbatch.pipeline.gridmap.build import GridMapResult, build_grid_map
from doorbatch.pipeline.gridmap.doors import DetectedDoor

OPEN = math.radians(60.0)
B_OPEN = math.radians(45.0)  # door B stands open in every pass: it never moves


@cache
def _run(sign: int, first: float, second: float, person: bool = False) -> tuple[Corridor, GridMapResult]:
    world = Corridor(door_a=Door((5.0, 3.0), 0.9, 0.0, sign))
    walker = ((12.5, 1.0), (1.5, 1.0)) if person else None
    passes = [scan_pass(world, first, B_OPEN, reverse=False, seed=1, person=walker),
              scan_pass(world, second, B_OPEN, reverse=True, seed=2)]
    return world, build_grid_map(passes)


def _check_door(door: DetectedDoor, truth: Door, lo: float, hi: float) -> None:
    assert math.hypot(door.hinge_x - truth.hinge[0], door.hinge_y - truth.hinge[1]) <= 0.10
    assert abs(door.length - truth.length) <= 0.10
    tol = math.radians(10.0)
    # The same range written from the truth's closed direction.
    shift = math.remainder(door.closed_yaw - truth.closed_yaw, 2 * math.pi)
    assert abs(shift) <= tol
    assert abs(door.angle_min + shift - lo) <= tol
    assert abs(door.angle_max + shift - hi) <= tol
    assert door.moved and door.n_observations >= 2


@pytest.mark.parametrize(("sign", "first", "second"), [
    (-1, 0.0, OPEN),  # opens into the corridor (seen free in pass 1): the paper's transient path
    (+1, 0.0, OPEN),  # opens into the unexplored room: closed leaf from set 2, open one from the grid
    (+1, OPEN, 0.0),  # open into the room first, closed later: closed leaf from set 1
])
def test_a_door_seen_at_two_angles_is_found_and_nothing_else(sign: int, first: float, second: float) -> None:
    world, result = _run(sign, first, second)
    assert len(result.doors) == 1  # not the pillar, the walls, nor door B that never moved
    truth = world.door_a
    lo, hi = sorted((0.0, sign * OPEN))
    _check_door(result.doors[0], truth, lo, hi)


def _truth_occupied(world: Corridor, shape: tuple[int, int], res: float, ox: float, oy: float) -> np.ndarray:
    """Cells that the door-less static geometry passes through."""
    segs = world.static
    t = np.linspace(0.0, 1.0, 400)[None, :, None]
    pts = (segs[:, None, 0] * (1 - t) + segs[:, None, 1] * t).reshape(-1, 2)
    j = np.floor((pts[:, 0] - ox) / res).astype(int)
    i = np.floor((pts[:, 1] - oy) / res).astype(int)
    occ = np.zeros(shape, dtype=bool)
    occ[i, j] = True
    return occ


def test_static_map_agrees_with_the_door_less_truth_and_holds_no_leaf() -> None:
    world, result = _run(+1, 0.0, OPEN)
    m = result.static_map
    truth = _truth_occupied(world, m.occupancy.shape, m.resolution_m, m.origin_x_m, m.origin_y_m)
    near_truth = np.zeros_like(truth)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            near_truth |= np.roll(np.roll(truth, di, axis=0), dj, axis=1)
    known = m.occupancy >= 0
    occupied = m.occupancy >= 65
    agree = np.where(occupied, near_truth, ~truth)
    assert agree[known].mean() >= 0.95
    leaf = world.door_a
    for alpha in (0.0, OPEN / 2, OPEN):
        s = np.linspace(0.15, leaf.length - 0.05, 12)
        pts = np.asarray(leaf.hinge) + s[:, None] * [math.cos(alpha), math.sin(alpha)]
        cells = m.world_to_cell(pts)
        assert np.all(m.occupancy[cells[:, 0], cells[:, 1]] < 65)
    i, j = m.world_to_cell(leaf.hinge)
    assert np.any(m.occupancy[i - 1:i + 2, j - 1:j + 2] >= 65)  # the hinge stays


def test_a_walking_person_leaves_no_occupied_cells_and_no_door() -> None:
    world, result = _run(-1, 0.0, OPEN, person=True)
    assert len(result.doors) == 1
    m = result.static_map
    xs, ys = np.meshgrid(np.arange(1.5, 12.5, 0.05), np.arange(0.8, 1.25, 0.05))
    pts = np.stack([xs.ravel(), ys.ravel()], axis=1)
    pts = pts[np.max(np.abs(pts - world.pillar_center), axis=1) > 0.35]  # not the pillar
    cells = m.world_to_cell(pts)
    assert np.all(m.occupancy[cells[:, 0], cells[:, 1]] < 65)
    assert result.n_dynamic_points > 0
