"""The doors a map directory lists: the em stage's, and the grid stage's in doorways the em stage left without
a door it saw move (pipeline/door_rows.py)."""

from __future__ import annotations

import math

import numpy as np

from doorbatch.io.preview import PreviewDoor
from doorbatch.pipeline.door_rows import DoorRow, with_grid_doors


def _row(x: float, y: float, closed_yaw: float, source: str, moved: bool = True) -> DoorRow:
    door = PreviewDoor(x, y, 0.9, closed_yaw, 0.0, 1.2 if moved else 0.0, moved)
    return DoorRow(door, 10, source, np.full(3, np.nan))


def test_grid_doors_fill_the_doorways_the_em_stage_left_empty_or_never_saw_move() -> None:
    em = [_row(3.0, 1.1, 0.0, "em"),  # the doorway of grid door a, seen moving by both: the em door stays
          _row(6.4, -1.1, math.pi, "em", moved=False),  # hinged at the free end, never seen moving
          _row(12.0, 1.1, -math.pi / 2, "em", moved=False)]  # right hinge, closed direction across the wall
    grid = [_row(3.02, 1.1, 0.0, "grid"),
            _row(5.5, -1.1, 0.0, "grid"),  # the same doorway as em door 2, hinged where it swung
            _row(12.02, 1.1, math.pi, "grid"),  # the same door as em door 3
            _row(3.0, -1.1, 0.0, "grid"),  # across the corridor from a: its own doorway
            _row(3.9, 1.1, 0.0, "grid")]  # the second leaf of a double door beside a: its own doorway
    rows = with_grid_doors(em, grid, 0.25)
    assert [(r.source, r.door.hinge_x, r.door.hinge_y) for r in rows] == [
        ("em", 3.0, 1.1), ("grid", 5.5, -1.1), ("grid", 12.02, 1.1), ("grid", 3.0, -1.1), ("grid", 3.9, 1.1)]


def test_without_em_doors_every_grid_door_is_listed_and_without_grid_doors_the_em_ones() -> None:
    grid = [_row(3.0, 1.1, 0.0, "grid"), _row(8.0, 1.1, math.pi, "grid")]
    assert with_grid_doors([], grid, 0.25) == grid
    em = [_row(3.0, 1.1, 0.0, "em", moved=False)]
    assert with_grid_doors(em, [], 0.25) == em


def test_the_grid_doors_order_does_not_matter_and_an_em_door_is_replaced_once() -> None:
    """Each grid door is matched against the em doors, not against grid doors that already replaced one."""
    em = [_row(5.0, 0.0, 0.0, "em", moved=False)]
    g1, g2 = _row(5.1, 0.0, 0.0, "grid"), _row(5.3, 0.0, math.pi / 2, "grid")
    for grid in ([g1, g2], [g2, g1]):
        rows = with_grid_doors(em, grid, 0.25)
        assert sorted((r.source, r.door.hinge_x) for r in rows) == [("grid", 5.1), ("grid", 5.3)]
    g0 = _row(4.98, 0.0, 0.0, "grid")  # two grid doors at the em door's hinge: one door, listed once
    assert [r.source for r in with_grid_doors(em, [g1, g0], 0.25)] == ["grid"]
