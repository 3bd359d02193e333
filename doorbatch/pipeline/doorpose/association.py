"""Matching an estimated door (two edges in the map frame) to the mapped doors of doors.parquet.

An estimated leaf starts at a mapped hinge: for door k with hinge h, leaf length L and closed direction ψ,
the estimated edge nearer the hinge is e_n and the farther e_f. Its current angle is
a = wrap(atan2(e_f − h) − ψ) (CCW positive, doors.parquet's convention), and the cost is
|e_n − h| + |c − (h + L/2·(cos(ψ + a), sin(ψ + a)))|, the hinge gap plus the centre's distance from that
leaf's centre (a leaf of another length or elsewhere costs more). The cheapest door within
``max_distance_m`` is the match (its doors.parquet door_id); else −1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.maps import DoorSet

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DoorMatch:
    """The mapped door an estimate belongs to (−1: none), its current angle (NaN if none), and the cost."""

    door_id: int
    angle: float
    cost_m: float


def associate(left: FloatArray, right: FloatArray, doors: DoorSet, max_distance_m: float) -> DoorMatch:
    """The mapped door of an estimate with edges ``left`` and ``right`` (map frame; module docstring)."""
    if len(doors) == 0:
        return DoorMatch(-1, float("nan"), float("inf"))
    h = doors.hinge
    d_left, d_right = np.linalg.norm(left - h, axis=1), np.linalg.norm(right - h, axis=1)
    near = np.where((d_left <= d_right)[:, None], left, right)
    far = np.where((d_left <= d_right)[:, None], right, left)
    direction = np.arctan2(far[:, 1] - h[:, 1], far[:, 0] - h[:, 0])
    angle = wrap_angle(direction - doors.closed_yaw)
    leaf_center = h + (doors.length / 2)[:, None] * np.stack([np.cos(direction), np.sin(direction)], axis=1)
    center = (left + right) / 2
    cost = np.linalg.norm(near - h, axis=1) + np.linalg.norm(center - leaf_center, axis=1)
    k = int(np.argmin(cost))
    if cost[k] > max_distance_m:
        return DoorMatch(-1, float("nan"), float(cost[k]))
    return DoorMatch(int(doors.ids[k]), float(angle[k]), float(cost[k]))
