"""Known-geometry tests of the wall measurement in scripts/em_acceptance.py: which hits a truth wall produced
(ray cast, not proximity) and the ends of its observed parts."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np

from doorbatch.pipeline.objectmap.beams import BeamSet

SCRIPT = Path(__file__).resolve().parents[3] / "scripts" / "em_acceptance.py"


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("em_acceptance", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["em_acceptance"] = module  # dataclasses resolve their module by name
    spec.loader.exec_module(module)
    return module


def _beams(origins: np.ndarray, ends: np.ndarray) -> BeamSet:
    d = ends - origins
    r = np.linalg.norm(d, axis=1)
    n = r.size
    return BeamSet(np.zeros(n, dtype=np.int64), origins, d / r[:, None], r, np.full(n, 20.0), r < 20.0,
                   np.full((n, 3), np.nan), 1)


def test_a_corridor_hit_at_a_room_walls_foot_is_not_that_room_walls() -> None:
    ea = _script()
    corridor = np.array([[0.0, 1.1], [10.0, 1.1]])  # the corridor wall, seen from below (y < 1.1)
    room = np.array([[5.0, 1.1], [5.0, 4.5]])  # a room wall standing on it, seen from the room (x > 5)
    segments = np.stack([corridor, room])
    corridor_ends = np.column_stack([np.linspace(4.96, 5.04, 9), np.full(9, 1.1)])  # within 4 cm of (5, 1.1)
    room_ends = np.column_stack([np.full(20, 5.0), np.linspace(2.0, 3.9, 20)])
    origins = np.concatenate([np.tile([5.0, 0.0], (9, 1)), np.tile([6.0, 3.0], (20, 1))])
    beams = _beams(origins, np.concatenate([corridor_ends, room_ends]))
    own = ea.hits_by_truth_segment(beams, segments)
    np.testing.assert_allclose(own[0], corridor_ends, atol=1e-9)
    np.testing.assert_allclose(own[1], room_ends, atol=1e-9)
    # by proximity alone the corridor hits would make a second observed part at the room wall's foot
    near = ea.observed_ends(room, beams.points)
    assert np.min(np.abs(near[:, 1] - 1.1)) < 0.05
    np.testing.assert_allclose(ea.observed_ends(room, own[1]), [[5.0, 2.0], [5.0, 3.9]], atol=1e-9)


def test_a_hit_in_front_of_a_wall_is_not_that_walls() -> None:
    ea = _script()
    wall = np.array([[[0.0, 2.0], [4.0, 2.0]]])
    origins = np.tile([2.0, 0.0], (3, 1))
    ends = np.array([[2.0, 2.0], [2.0, 1.9], [2.0, 1.97]])  # on it, 10 cm short (a door leaf), 3 cm short
    own = ea.hits_by_truth_segment(_beams(origins, ends), wall)
    np.testing.assert_allclose(own[0], ends[[0, 2]], atol=1e-9)
