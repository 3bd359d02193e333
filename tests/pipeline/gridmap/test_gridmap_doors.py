"""Door detection pieces: eq. (1) clusters, eq. (2) line objects, leaves with a common hinge, leaf removal."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.config import DoorDetectionConfig, GridConfig
from doorbatch.pipeline.gridmap.doors import (
    SOURCE_FALLEN,
    SOURCE_TRANSIENT,
    DetectedDoor,
    Leaves,
    angle_modes,
    cluster_points,
    extract_leaves,
    fit_leaf,
    group_doors,
    remove_leaves,
    swept_cells,
)
from doorbatch.pipeline.gridmap.occupancy import new_grid

CFG = DoorDetectionConfig()


def _line(a: tuple[float, float], b: tuple[float, float], n: int, sigma: float = 0.0, seed: int = 0) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)[:, None]
    pts = (1 - t) * np.asarray(a) + t * np.asarray(b)
    return pts + np.random.default_rng(seed).normal(0.0, sigma, pts.shape)


def _leaf(hinge: tuple[float, float], length: float, yaw: float, cut: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    u = np.array([math.cos(yaw), math.sin(yaw)])
    return np.asarray(hinge) + cut * u, np.asarray(hinge) + length * u


def _leaves(segs: list[tuple[np.ndarray, np.ndarray]], passes: list[int] | None = None) -> Leaves:
    """Set-1 leaves; by default the first half seen in pass 0, the rest in pass 1."""
    n = len(segs)
    pass_index = np.asarray(passes if passes is not None else [2 * k // n for k in range(n)], dtype=np.int64)
    return Leaves(np.array([s[0] for s in segs]), np.array([s[1] for s in segs]), np.arange(n),
                  pass_index, np.ones(n, np.int64))


def test_clusters_link_chains_of_close_points_eq1() -> None:
    pts = np.array([[0, 0], [0.1, 0], [0.2, 0], [0.5, 0], [0.6, 0.05], [3, 3]], dtype=float)
    labels = cluster_points(pts, eps=0.15)
    assert labels[0] == labels[1] == labels[2]
    assert labels[3] == labels[4] != labels[0]
    assert len(set(labels.tolist())) == 3


def _single_linkage_by_pairs(pts: np.ndarray, eps: float) -> np.ndarray:
    """Eq. (1) from first principles: every pair closer than ε linked (all n² distances), components numbered in
    the order of their first point."""
    from scipy.sparse.csgraph import connected_components

    d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
    return connected_components(d < eps, directed=False)[1]


@settings(max_examples=25, deadline=None)
@given(st.integers(600, 1500), st.integers(1, 12), st.floats(0.005, 0.4), st.floats(0.05, 0.5), st.integers(0, 10**6))
def test_large_point_sets_cluster_as_all_pairs_would_eq1(n: int, k: int, spread_m: float, eps: float,
                                                          seed: int) -> None:
    """Beyond DENSE_CLUSTER_MAX points (the leaf ends of a long log, piled at hinges) clustering goes through cells
    of side ε/√2: the same clusters, numbered alike, as linking every pair closer than ε."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-5, 5, (k, 2))[rng.integers(0, k, n)] + rng.normal(0.0, spread_m, (n, 2))
    np.testing.assert_array_equal(cluster_points(pts, eps), _single_linkage_by_pairs(pts, eps))


def test_a_straight_cluster_gives_the_mean_line_with_the_longest_length_eq2() -> None:
    seg = fit_leaf(_line((1.0, 1.0), (1.0 + 0.9 * math.cos(0.5), 1.0 + 0.9 * math.sin(0.5)), 30, 0.005), CFG)
    assert seg is not None
    d = seg[1] - seg[0]
    assert np.hypot(*d) == pytest.approx(0.9, abs=0.02)
    assert abs(math.sin(math.atan2(d[1], d[0]) - 0.5)) < math.radians(1.0)
    assert np.min(np.hypot(*(seg - [1.0, 1.0]).T)) < 0.02


def test_an_l_shaped_cluster_is_a_non_line_object() -> None:
    pts = np.vstack([_line((0, 0), (0.6, 0), 13), _line((0.6, 0.05), (0.6, 0.6), 12)])
    assert fit_leaf(pts, CFG) is None


def test_a_cluster_shorter_than_delta_has_no_line() -> None:
    assert fit_leaf(_line((0, 0), (0.3, 0), 8), CFG) is None


def test_only_lines_of_leaf_length_become_leaves() -> None:
    pts = np.vstack([_line((0, 0), (0.9, 0), 20), _line((0, 2), (2.5, 2), 50), _line((0, 4), (0.45, 4), 10)])
    leaves = extract_leaves(pts, CFG, instance=4, pass_index=1)
    assert len(leaves) == 1
    assert leaves.lengths()[0] == pytest.approx(0.9, abs=0.01)
    assert (leaves.instance[0], leaves.pass_index[0]) == (4, 1)


def test_angle_modes_split_at_gaps_and_not_across_zero() -> None:
    yaw = np.radians([-2.0, 1.0, 359.0 - 360.0, 60.0, 61.0, 62.0])
    labels = angle_modes(yaw, math.radians(6.0))
    assert labels[0] == labels[1] == labels[2] != labels[3]
    assert labels[3] == labels[4] == labels[5]


def test_leaves_rotating_about_a_common_hinge_make_a_door() -> None:
    hinge = (2.0, 3.0)
    segs = [_leaf(hinge, 0.9, 0.0, cut=0.05)] * 3 + [_leaf(hinge, 0.88, math.radians(60), cut=0.1)] * 5
    (door,) = group_doors(_leaves(segs, [0, 0, 0, 1, 1, 1, 1, 1]), CFG)
    assert math.hypot(door.hinge_x - 2.0, door.hinge_y - 3.0) < 0.01
    assert door.length == pytest.approx(0.9, abs=0.03)
    assert door.closed_yaw == pytest.approx(0.0, abs=1e-6)
    assert (door.angle_min, math.degrees(door.angle_max)) == (pytest.approx(0.0, abs=1e-6), pytest.approx(60.0))
    assert door.n_observations == 8 and door.moved


def test_a_closed_leaf_chained_to_a_wall_seen_moving_beyond_its_door_stop_keeps_its_hinge() -> None:
    """A helper's door (20°, 0°, 40° into a room; 40° static) was missed: in the first pass the wall beyond its door
    stop was seen moving (grazing beams through the doorway clear a wall on a cell border), and single linkage
    chained those lines to the closed leaf. The densest end, the door stop, was taken for the hinge. The hinge is
    now where the leaf's angles meet; the wall lines, which start a leaf's length from it, leave the group."""
    hinge = (2.0, 3.0)
    pieces = [(0.04, 0.9), (0.25, 0.9), (0.04, 0.6), (0.4, 0.9), (0.04, 0.75)]  # ends every ≤ 0.21 m: one chain
    closed = [(np.array([2.0 + a, 3.0]), np.array([2.0 + b, 3.0])) for a, b in pieces] * 6
    wall = [(np.array([2.92, 3.0]), np.array([3.6, 3.0]))] * 40  # from the door stop at x = 2.9 on
    open_20 = [_leaf(hinge, 0.9, math.radians(20), cut=0.1)]
    (door,) = group_doors(_leaves(closed + wall + open_20, [1] * 30 + [0] * 40 + [0]), CFG)
    assert math.hypot(door.hinge_x - 2.0, door.hinge_y - 3.0) < 0.02
    assert door.length == pytest.approx(0.9, abs=0.03)
    assert sorted(round(math.degrees(a)) for a in (door.angle_min, door.angle_max)) == [0, 20]
    assert door.n_observations == 31


def test_leaves_seen_at_one_angle_or_indistinguishable_angles_make_no_door() -> None:
    hinge = (2.0, 3.0)
    assert group_doors(_leaves([_leaf(hinge, 0.9, 0.3)] * 4), CFG) == []
    assert group_doors(_leaves([_leaf(hinge, 0.9, 0.3), _leaf(hinge, 0.9, 0.3 + math.radians(8))]), CFG) == []


def test_a_leaf_that_turns_within_one_pass_is_no_door() -> None:
    hinge = (2.0, 3.0)
    segs = [_leaf(hinge, 0.9, 0.0), _leaf(hinge, 0.9, math.radians(60))]
    assert group_doors(_leaves(segs, [1, 1]), CFG) == []
    assert len(group_doors(_leaves(segs, [1, 1]), CFG.model_copy(update={"require_distinct_passes": False}))) == 1
    # Set 2 found in pass 1, of cells last hit in pass 0: the leaf stood there in pass 0.
    fallen = Leaves(np.array([s[0] for s in segs]), np.array([s[1] for s in segs]), np.array([1, 7]),
                    np.array([0, 1]), np.array([2, 1]))
    assert len(group_doors(fallen, CFG)) == 1


def test_leaves_without_a_common_end_make_no_door() -> None:
    segs = [_leaf((2.0, 3.0), 0.9, 0.0), _leaf((2.6, 3.0), 0.9, math.radians(70))]
    assert group_doors(_leaves(segs), CFG) == []


def test_rotation_beyond_180_degrees_needs_allow_swinging() -> None:
    hinge = (0.0, 0.0)
    segs = [_leaf(hinge, 0.8, math.radians(a)) for a in (0.0, 100.0, 200.0, 200.0)]
    assert group_doors(_leaves(segs), CFG) == []
    (door,) = group_doors(_leaves(segs), CFG.model_copy(update={"allow_swinging": True, "max_rotation_deg": 360}))
    assert math.degrees(door.angle_max - door.angle_min) == pytest.approx(200.0, abs=0.5)


def test_removing_a_leaf_clears_the_swept_cells_and_keeps_the_hinge_occupied() -> None:
    gcfg = GridConfig(resolution_m=0.05, initial_size_m=4.0)
    grid = new_grid(gcfg, (0.0, 0.0))
    grid.log_odds[:] = gcfg.l_min
    door = DetectedDoor(0.0, 0.0, 0.9, 0.0, 0.0, math.radians(60.0), 2)
    for a in (0.0, math.radians(30.0), math.radians(60.0)):
        pts = np.stack([np.linspace(0.05, 0.9, 30) * math.cos(a), np.linspace(0.05, 0.9, 30) * math.sin(a)], 1)
        grid.log_odds.reshape(-1)[grid.flat_index(pts)] = gcfg.l_max
    outside = grid.flat_index([[0.6 * math.cos(1.4), 0.6 * math.sin(1.4)], [-0.5, 0.0]])
    grid.log_odds.reshape(-1)[outside] = gcfg.l_max
    swept = swept_cells(grid, door, 0.04)
    remove_leaves(grid, [door], CFG, gcfg)
    assert swept.sum() > 0.9 * (math.pi / 6 * 0.9**2) / 0.05**2
    (hinge,) = grid.flat_index([[0.0, 0.0]])
    flat = grid.log_odds.reshape(-1)
    assert flat[hinge] == pytest.approx(gcfg.l_max)
    assert np.all(grid.log_odds[swept] <= gcfg.l_max) and np.sum(grid.log_odds[swept] > 0) == 1
    assert np.all(flat[outside] == np.float32(gcfg.l_max))


def test_a_small_rotation_is_hinged_at_the_hinge_not_at_the_free_end() -> None:
    """Turned by 16°, a 0.9 m leaf's free ends are 0.25 m apart: they form a group of close end points too.
    The lines cross at the hinge, so that group makes no door and the hinge group does."""
    hinge = (2.0, 3.0)
    segs = [_leaf(hinge, 0.9, 0.0)] * 3 + [_leaf(hinge, 0.9, math.radians(16.0))] * 3
    (door,) = group_doors(_leaves(segs), CFG)
    assert math.hypot(door.hinge_x - 2.0, door.hinge_y - 3.0) < 0.02
    assert math.degrees(door.angle_max - door.angle_min) == pytest.approx(16.0, abs=0.5)


def test_a_door_shorter_than_a_leaf_from_its_hinge_is_no_door() -> None:
    """Set-2 lines may be shorter than λmin (cut at the hinge); the door's length, from its hinge, is gated."""
    hinge = (2.0, 3.0)
    segs = [_leaf(hinge, 0.5, 0.0)] * 2 + [_leaf(hinge, 0.5, math.radians(60.0))] * 2
    assert group_doors(_leaves(segs), CFG) == []
    segs = [_leaf(hinge, 0.75, 0.0, cut=0.2)] * 2 + [_leaf(hinge, 0.75, math.radians(60.0))] * 2  # 0.55 m line
    (door,) = group_doors(_leaves(segs), CFG)
    assert door.length == pytest.approx(0.75, abs=0.02)


def test_a_fallen_line_shorter_than_a_leaf_is_kept_a_dynamic_one_is_not() -> None:
    pts = _line((0, 0), (0.5, 0), 12)
    assert len(extract_leaves(pts, CFG, source=SOURCE_FALLEN)) == 1
    assert len(extract_leaves(pts, CFG, source=SOURCE_TRANSIENT)) == 0


def test_a_cluster_cut_short_is_completed_along_its_line_by_support_points() -> None:
    """The transient neighbourhood rule leaves only the middle of a leaf dynamic; the rest of the leaf's
    points of the same scan (in seen-free cells) complete the line — across gaps shorter than ε only."""
    dynamic = _line((0.3, 0), (0.6, 0), 8)
    support = np.vstack([_line((0.0, 0.01), (0.27, 0.01), 7), _line((0.63, 0), (0.9, 0), 7),
                         _line((1.2, 0), (1.5, 0), 7),  # beyond a 0.3 m gap: another object
                         _line((0.1, 0.3), (0.4, 0.3), 7)])  # off the line
    assert len(extract_leaves(dynamic, CFG)) == 0
    (seg,) = np.stack([*extract_leaves(dynamic, CFG, support=support).p0[:1],
                       *extract_leaves(dynamic, CFG, support=support).p1[:1]])[None]
    xs = sorted(seg[:, 0].tolist())
    assert xs[0] == pytest.approx(0.0, abs=0.02) and xs[1] == pytest.approx(0.9, abs=0.02)


def _chained_door_leaves(swap: list[bool]) -> Leaves:
    """A door at the origin seen at 0°, 10°, …, 90° (one pass each) whose free ends lie 0.16 m apart on an
    arc, two short pieces along 30° that bridge hinge and arc (ends within ``hinge_distance_m`` of each
    other: single linkage joins them all), and the leaf at 60° once more from pass 10, written free end
    first (as a set-2 leaf may be). ``swap``: which leaves have their end points exchanged."""
    segs = [_leaf((0.0, 0.0), 0.9, math.radians(a), cut=0.05) for a in range(0, 100, 10)]
    u = np.array([math.cos(math.radians(30)), math.sin(math.radians(30))])
    segs += [(0.2 * u, 0.4 * u), (0.6 * u, 0.8 * u)]
    near, far = _leaf((0.0, 0.0), 0.88, math.radians(60), cut=0.2)
    segs.append((far, near))
    segs = [(b, a) if s else (a, b) for (a, b), s in zip(segs, swap, strict=True)]
    return _leaves(segs, [*range(10), 3, 3, 10])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.booleans(), min_size=13, max_size=13))
def test_a_door_does_not_depend_on_which_end_of_a_leaf_comes_first(swap: list[bool]) -> None:
    assert group_doors(_chained_door_leaves([False] * 13), CFG) == group_doors(_chained_door_leaves(swap), CFG)
    (door,) = group_doors(_chained_door_leaves(swap), CFG)
    assert math.hypot(door.hinge_x, door.hinge_y) < 0.05
    assert math.degrees(door.closed_yaw + door.angle_min) == pytest.approx(0.0, abs=1.0)
    assert math.degrees(door.angle_max - door.angle_min) == pytest.approx(90.0, abs=1.0)


def test_a_thick_leaf_seen_from_one_side_leaves_nothing_at_the_ends_of_its_swing() -> None:
    """A 4 cm leaf standing open at 90° (an outside tester's world), fitted on the face the robot saw: hits on its
    other face (4.2 cm away with noise) fall in cells whose centres lie 6.5 cm from the fitted line, beyond
    ``sweep_margin_m``. All of them leave the static map; the wall it hangs in, across it at the hinge, and
    the far jamb of the doorway stay."""
    gcfg, dcfg = GridConfig(), DoorDetectionConfig()
    grid = new_grid(gcfg, (0.0, 0.0), 6.0)
    grid.log_odds[:] = gcfg.l_min
    wall = np.stack([np.concatenate([np.arange(-2.0, -0.02, 0.02), np.arange(0.96, 2.0, 0.02)]), np.zeros(151)], 1)
    faces = [np.stack([np.full(45, x), np.linspace(0.1, 0.9, 45)], 1) for x in (0.01, 0.052)]  # fitted on x = 0.01
    flat = grid.log_odds.reshape(-1)
    flat[grid.flat_index(wall)] = gcfg.l_max
    leaf = np.unique(grid.flat_index(np.concatenate(faces)))
    flat[leaf] = gcfg.l_max
    door = DetectedDoor(0.01, 0.0, 0.9, 0.0, 0.0, math.pi / 2, 3)  # seen closed and at 90°
    remove_leaves(grid, [door], dcfg, gcfg)
    assert np.all(flat[leaf] <= 0)  # free where seen free, else unknown: not occupied
    assert np.all(flat[grid.flat_index(wall)] > 0)
