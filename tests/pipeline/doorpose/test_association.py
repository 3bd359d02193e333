"""Association of a door estimate with the mapped doors: known answers from the leaf geometry by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from doorbatch.maps import DoorSet
from doorbatch.pipeline.doorpose.association import associate

HINGE = np.array([2.0, 1.0])
# Two doors hinged at one wall corner: door 0 is 0.6 m closing along +x, door 1 is 0.9 m closing along +y.
CORNER_DOORS = DoorSet(np.stack([HINGE, HINGE]), np.array([0.6, 0.9]), np.array([0.0, math.pi / 2]),
                       np.full(2, -math.pi / 2), np.full(2, math.pi / 2))


def test_estimate_at_a_shared_hinge_goes_to_the_door_of_its_length() -> None:
    """The hinge gap is 0 for both doors; only the leaf-centre term tells the 0.9 m leaf from the 0.6 m one."""
    direction = math.radians(60.0)
    unit = np.array([math.cos(direction), math.sin(direction)])
    # a 0.9 m leaf from the hinge at 60°: its centre is 0.45 m out, door 1's leaf centre exactly (cost 0);
    # door 0's leaf centre on the same direction is 0.3 m out, so door 0 costs 0.45 − 0.3 = 0.15 m
    wide = associate(HINGE + 0.9 * unit, HINGE.copy(), CORNER_DOORS, max_distance_m=0.5)
    assert wide.door_id == 1
    assert wide.angle == pytest.approx(math.radians(60.0 - 90.0), abs=1e-12)  # 60° minus door 1's closed 90°
    assert wide.cost_m == pytest.approx(0.0, abs=1e-12)
    # the 0.6 m leaf at the same place is door 0's, at 60° from its closed direction along +x
    narrow = associate(HINGE + 0.6 * unit, HINGE.copy(), CORNER_DOORS, max_distance_m=0.5)
    assert narrow.door_id == 0
    assert narrow.angle == pytest.approx(math.radians(60.0), abs=1e-12)
    assert narrow.cost_m == pytest.approx(0.0, abs=1e-12)
    # a map whose doors.parquet numbers them otherwise: the match is named by its door_id, not its row
    numbered = DoorSet(*(getattr(CORNER_DOORS, f) for f in ("hinge", "length", "closed_yaw", "angle_min",
                                                              "angle_max")), door_id=np.array([17, 4], np.int32))
    assert associate(HINGE + 0.9 * unit, HINGE.copy(), numbered, max_distance_m=0.5).door_id == 4
