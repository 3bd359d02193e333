"""The doors a map directory lists (doors.parquet): the em stage's, and the grid stage's in doorways where
the em stage has none or one it never saw move.

The two stages judge a door by different evidence. The grid stage (paper 000 Sec. III) keeps a leaf seen at
two or more distinguishable angles about one hinge: motion, whatever the number of beams. The em stage
(paper 001) keeps a door when the log posterior pays for it: the data's gain against a fixed prior cost per
door (ρS per hinge coordinate, ρD per pass angle, ρL per metre; the first door also pays the width and the
door colours). With a sparse or short-range laser a door gets few beams, and a door that plainly swung loses
to that cost: on the sample world seen by a 3.5 m, 360-beam, 5 Hz laser (a TurtleBot-like one) the em stage
listed 2 doors, one of them right, where the grid stage found all 7 that moved (docs/results.md, "A
short-range laser").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.io.preview import PreviewDoor
from doorbatch.pipeline.gridmap.doors import DetectedDoor
from doorbatch.pipeline.objectmap.stage import EmDoor

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DoorRow:
    """One row of doors.parquet, with the angle it stood at in each pass (NaN where the stage did not see
    the leaf; the grid stage keeps no per-pass angle)."""

    door: PreviewDoor
    n_observations: int
    source: str  # "grid" or "em"
    pass_angles: FloatArray  # (passes,) relative to closed_yaw, rad


def grid_rows(doors: Sequence[DetectedDoor], n_passes: int) -> list[DoorRow]:
    """The grid stage's doors as rows."""
    return [DoorRow(PreviewDoor(d.hinge_x, d.hinge_y, d.length, d.closed_yaw, d.angle_min, d.angle_max, d.moved),
                    d.n_observations, "grid", np.full(n_passes, np.nan)) for d in doors]


def em_rows(doors: Sequence[EmDoor]) -> list[DoorRow]:
    """The em stage's doors as rows."""
    rows = []
    for d in doors:
        angles = np.full(d.pass_yaws.shape[0], np.nan)
        angles[d.pass_observed] = wrap_angle(d.pass_yaws[d.pass_observed] - d.preview.closed_yaw)
        rows.append(DoorRow(d.preview, d.n_observations, "em", angles))
    return rows


def closed_leaf_middle(door: PreviewDoor) -> FloatArray:
    """The middle of the closed leaf: the doorway's centre."""
    half = 0.5 * door.length
    return np.array([door.hinge_x + half * np.cos(door.closed_yaw), door.hinge_y + half * np.sin(door.closed_yaw)])


def _same_door(a: PreviewDoor, b: PreviewDoor, hinge_radius_m: float) -> bool:
    """One doorway: hinges within ``hinge_radius_m`` (an em door that never moved may have its closed
    direction wrong), or closed-leaf middles within half the longer leaf (a door hinged at the other jamb).
    Two leaves of a double door, or doors facing each other across a corridor, stay apart."""
    hinges = float(np.hypot(a.hinge_x - b.hinge_x, a.hinge_y - b.hinge_y))
    middles = float(np.linalg.norm(closed_leaf_middle(a) - closed_leaf_middle(b)))
    return hinges <= hinge_radius_m or middles <= 0.5 * max(a.length, b.length)


def with_grid_doors(em: Sequence[DoorRow], grid: Sequence[DoorRow], hinge_radius_m: float) -> list[DoorRow]:
    """The em stage's rows, and each grid door whose doorway no em door holds (:func:`_same_door`), appended
    in the grid stage's order. A doorway both hold keeps the em door, unless the em stage never saw it move
    and the grid stage did: the grid door's hinge and range then come from the leaf's motion, the em door's
    from one angle and the walls (stage.describe_doors)."""
    rows = list(em)
    extra = []
    for g in grid:  # against the em doors only, the nearest hinge first; an em door is replaced at most once
        same = [i for i, r in enumerate(em) if _same_door(r.door, g.door, hinge_radius_m)]
        if not same:
            extra.append(g)
            continue
        k = min(same, key=lambda i: np.hypot(em[i].door.hinge_x - g.door.hinge_x, em[i].door.hinge_y - g.door.hinge_y))
        if g.door.moved and not em[k].door.moved and rows[k] is em[k]:
            rows[k] = g
    return rows + extra
