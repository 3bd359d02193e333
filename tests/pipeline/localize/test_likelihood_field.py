"""Likelihood field: distances on constructed maps, off-map / unknown rules, AMCL's beam rules and formula."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mcl_sim import LASER_TO_BASE, asymmetric_room, room_map, scan_beams

from doorbatch.config import LocalizeConfig
from doorbatch.maps import OccupancyMap
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    beam_likelihood,
    build_distance_field,
    combine_beams,
    endpoint_distances,
    endpoint_log_likelihood,
    endpoint_points,
    field_log_likelihood,
    free_cells,
    lookup,
    select_beams,
)
from doorbatch.pipeline.localize.mcl import scan_log_likelihood

RES = 0.05


def wall_map(unknown_block: bool = False) -> OccupancyMap:
    """40 × 60 free cells with one occupied row (row 10, y = −2 + 10.5·0.05 = −1.475 at the centres)."""
    occ = np.zeros((40, 60), dtype=np.int8)
    occ[10, :] = 100
    if unknown_block:
        occ[20:30, 10:20] = -1
    return OccupancyMap(occ, RES, -1.0, -2.0)


def test_distance_to_a_single_wall_is_the_distance_between_rows() -> None:
    field = build_distance_field(wall_map(), 0.4)
    rows = np.arange(40)
    expected = np.minimum(np.abs(rows - 10) * RES, 0.4)
    assert field.dist.dtype == np.float32
    assert np.allclose(field.dist, expected[:, None], atol=1e-6)
    # world points: the cell containing them; at cell centres that is |y − y_wall| capped
    y = -2.0 + (rows + 0.5) * RES
    xy = np.stack([np.full(40, 0.37), y], axis=1)
    assert np.allclose(lookup(field, xy), np.minimum(np.abs(y - (-2.0 + 10.5 * RES)), 0.4), atol=1e-6)


def test_points_off_the_map_count_as_max_distance() -> None:
    field = build_distance_field(wall_map(), 0.4)
    # just inside / outside each edge, and far away (the wall row itself runs into the left and right edges)
    inside = np.array([[-0.999, -1.475], [1.999, -1.475], [0.5, -1.999], [0.5, -0.001]])
    outside = np.array([[-1.001, -1.475], [2.001, -1.475], [0.5, -2.001], [0.5, 0.001], [1e6, -1e6], [np.inf, 0.0]])
    assert np.allclose(lookup(field, inside), [0.0, 0.0, 0.4, 0.4])
    assert np.all(lookup(field, outside) == np.float32(0.4))


def test_unknown_cells_get_their_distance_like_amcl_or_max_when_asked() -> None:
    amcl = build_distance_field(wall_map(unknown_block=True), 1.0)
    strict = build_distance_field(wall_map(unknown_block=True), 1.0, unknown_as_max=True)
    assert np.allclose(amcl.dist[20:30, 10:20], (np.arange(20, 30) - 10)[:, None] * RES)
    assert np.all(strict.dist[20:30, 10:20] == np.float32(1.0))
    assert np.array_equal(strict.dist[:20], amcl.dist[:20])


def test_a_map_without_obstacles_is_max_distance_everywhere() -> None:
    field = build_distance_field(OccupancyMap(np.zeros((5, 7), dtype=np.int8), RES), 2.0)
    assert np.all(field.dist == 2.0)


def test_occupied_threshold_is_map_servers() -> None:
    occ = np.zeros((3, 3), dtype=np.int8)
    occ[0, 0], occ[2, 2] = 64, 65
    field = build_distance_field(OccupancyMap(occ, 1.0), 10.0)
    assert field.dist[2, 2] == 0.0 and field.dist[0, 0] == pytest.approx(math.sqrt(8))


def test_fast_endpoint_distances_equal_lookup_of_transformed_points() -> None:
    rng = np.random.default_rng(5)
    occ = np.where(rng.random((80, 100)) < 0.05, 100, 0).astype(np.int8)
    grid = OccupancyMap(occ, RES, 1.3, -0.7, 0.4)  # a rotated map origin
    field = build_distance_field(grid, 0.5)
    pose = np.column_stack([rng.uniform(0, 6, 3000), rng.uniform(-1, 5, 3000), rng.uniform(-4, 4, 3000)])
    pts = rng.uniform(-4, 4, (37, 2))
    fast = endpoint_distances(field, pose, pts, chunk=700)
    world = endpoint_points(pose, pts)
    reference = lookup(field, world)
    # float32 may put a point within 1e-3 cell of a cell border on the other side: compare the others
    g = field.to_grid(np.concatenate([world, np.zeros((*world.shape[:2], 1))], axis=-1))[..., :2]
    frac = g - np.floor(g)
    clear = np.all((frac > 1e-3) & (frac < 1 - 1e-3), axis=-1)
    assert clear.mean() > 0.99
    assert np.array_equal(fast[clear], reference[clear])
    assert (fast == np.float32(0.5)).any() and (fast < 0.5).any()  # both off-map / far and near points


@pytest.mark.parametrize("combination", list(BeamCombination))
def test_fused_log_likelihood_equals_distances_then_model(combination: BeamCombination) -> None:
    field = build_distance_field(room_map(), 2.0)
    rng = np.random.default_rng(19)
    pose = np.column_stack([rng.uniform(-1, 9, 2500), rng.uniform(-1, 6, 2500), rng.uniform(-4, 4, 2500)])
    pts = rng.uniform(-6, 6, (61, 2))
    reference = endpoint_log_likelihood(endpoint_distances(field, pose, pts), 0.95, 0.05, 0.1, 12.0, combination)
    for chunk in (1, 333, 1024, 5000):
        fused = field_log_likelihood(field, pose, pts, 0.95, 0.05, 0.1, 12.0, combination, chunk=chunk)
        assert np.allclose(fused, reference, rtol=1e-6, atol=1e-9)
    assert field_log_likelihood(field, pose[:0], pts, 0.95, 0.05, 0.1, 12.0).shape == (0,)
    assert np.all(field_log_likelihood(field, pose, pts[:0], 0.95, 0.05, 0.1, 12.0) == 0.0)


def test_free_cells_sample_free_space() -> None:
    grid = room_map()
    free = free_cells(grid)
    assert len(free) == int((grid.occupancy == 0).sum())
    poses = free.sample_poses(5000, np.random.default_rng(6))
    ij = grid.world_to_cell(poses[:, :2])
    assert np.all(grid.occupancy[ij[:, 0], ij[:, 1]] == 0)
    assert poses[:, 2].min() >= -np.pi and poses[:, 2].max() < np.pi
    with pytest.raises(ValueError, match="no free cell"):
        free_cells(OccupancyMap(np.full((2, 2), 100, dtype=np.int8), 1.0)).sample_poses(1, np.random.default_rng())


def test_beam_selection_follows_amcl() -> None:
    n = 181
    ranges = np.full(n, 4.0)
    angles = np.linspace(-np.pi / 2, np.pi / 2, n)
    ranges[3], ranges[6], ranges[9], ranges[12], ranges[15] = np.nan, np.inf, 30.0, 0.05, 0.1
    beams = select_beams(ranges, angles, 0.1, 30.0, np.eye(4), max_beams=60)
    step = (n - 1) // (60 - 1)  # 3: 61 beams, of which 5 are skipped
    assert step == 3
    expected = [i for i in range(0, n, step) if i not in (3, 6, 9, 12, 15)]
    assert beams.beam_index.tolist() == expected
    assert beams.range_max_m == 30.0
    assert np.allclose(np.hypot(*beams.points_base.T), 4.0)
    # overrides: laser_max_range shortens range_max (and drops longer beams); laser_min_range raises range_min
    ranges[30] = 6.0
    short = select_beams(ranges, angles, 0.1, 30.0, np.eye(4), 60, laser_min_range=0.2, laser_max_range=5.0)
    assert short.range_max_m == 5.0 and 30 not in short.beam_index
    assert select_beams(ranges, angles, 0.1, 30.0, np.eye(4), 1000).beam_index.size == n - 5  # step 1
    with pytest.raises(ValueError, match="max_beams"):
        select_beams(ranges, angles, 0.1, 30.0, np.eye(4), 1)


@pytest.mark.parametrize("stated", [np.inf, np.nan])
def test_a_scan_without_a_finite_range_max_gets_the_fallback(stated: float) -> None:
    # some drivers publish range_max = inf: z_rand / inf = 0, and one end point far from every wall (a person,
    # a glass door) gave every particle log p = −inf under the product of the beams
    ranges = np.array([4.0, np.inf, 12.0, np.nan])
    angles = np.linspace(-1.0, 1.0, 4)
    beams = select_beams(ranges, angles, 0.1, stated, np.eye(4), 60, range_max_fallback_m=25.0)
    assert beams.range_max_m == 25.0 and beams.beam_index.tolist() == [0, 2]
    assert select_beams(ranges, angles, 0.1, stated, np.eye(4), 60, laser_max_range=10.0).range_max_m == 10.0
    field = build_distance_field(room_map(), 2.0)
    pose = np.array([[50.0, 50.0, 0.0]])  # every end point off the map: the field's maximum distance
    ll = field_log_likelihood(field, pose, beams.points_base, 0.8, 0.2, 0.1, beams.range_max_m,
                              BeamCombination.PRODUCT)
    assert np.isfinite(ll).all()


def test_upside_down_laser_mirrors_the_beams() -> None:
    flipped = np.diag([1.0, -1.0, -1.0, 1.0])  # 180° about x
    flipped[0, 3] = 0.2
    beams = select_beams([1.0, 2.0], [np.pi / 2, 0.0], 0.0, 10.0, flipped, 2)
    assert np.allclose(beams.points_base, [[0.2, -1.0], [2.2, 0.0]])
    assert np.allclose(beams.origin_base, [0.2, 0.0])


def test_beam_likelihood_and_combinations_are_amcls_formula() -> None:
    d = np.array([[0.0, 0.1, 0.3, 2.0], [0.05, 0.05, 0.05, 0.05]])
    z_hit, z_rand, sigma, rmax = 0.95, 0.05, 0.1, 20.0
    pz = z_hit * np.exp(-d**2 / (2 * sigma**2)) + z_rand / rmax
    assert np.allclose(beam_likelihood(d, z_hit, z_rand, sigma, rmax), pz, rtol=1e-6)
    assert np.allclose(combine_beams(pz), np.log(1.0 + np.sum(pz**3, axis=1)), rtol=1e-6)
    assert np.allclose(combine_beams(pz, BeamCombination.PRODUCT), np.sum(np.log(pz), axis=1), rtol=1e-6)
    assert np.allclose(endpoint_log_likelihood(d, z_hit, z_rand, sigma, rmax), np.log1p(np.sum(pz**3, axis=1)))
    assert combine_beams(np.zeros((3, 0))).tolist() == [0.0, 0.0, 0.0]


@pytest.mark.parametrize("combination", list(BeamCombination))
def test_scan_likelihood_peaks_at_the_true_pose(combination: BeamCombination) -> None:
    config = LocalizeConfig()
    field = build_distance_field(room_map(), config.laser_likelihood_max_dist)
    truth = np.array([4.03, 2.11, 0.3])
    beams = scan_beams(asymmetric_room(), truth)
    assert len(beams) >= 55
    offsets = np.arange(-0.3, 0.3001, RES / 2)
    dyaw = np.radians(np.arange(-6.0, 6.01, 1.0))
    gx, gy, gt = np.meshgrid(offsets, offsets, dyaw, indexing="ij")
    poses = truth + np.stack([gx.ravel(), gy.ravel(), gt.ravel()], axis=1)
    ll = scan_log_likelihood(poses, beams, field, config, combination)
    best = poses[int(np.argmax(ll))]
    assert np.hypot(*(best[:2] - truth[:2])) <= RES
    assert abs(best[2] - truth[2]) <= math.radians(1.0) + 1e-9


def test_laser_offset_is_honoured() -> None:
    """A scan taken 20 cm ahead of base_link scores best with the offset applied (LASER_TO_BASE)."""
    config = LocalizeConfig()
    field = build_distance_field(room_map(), config.laser_likelihood_max_dist)
    truth = np.array([3.0, 2.5, 0.0])
    beams = scan_beams(asymmetric_room(), truth)
    assert np.allclose(beams.origin_base, LASER_TO_BASE[:2, 3])
    poses = truth + np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [-0.2, 0.0, 0.0]])
    ll = scan_log_likelihood(poses, beams, field, config)
    assert int(np.argmax(ll)) == 0


def test_which_map_cells_are_walls_and_free_follows_the_config() -> None:
    """A probability map (Cartographer's): a wall of 81, floor of 10. map_server's thresholds (the default) make
    the 81s walls and the 10s free; AMCL's convertMap (an AMCL parameter file) takes only 100 and 0, so it sees no
    wall and no free cell there."""
    from doorbatch.config import load_config
    from doorbatch.maps import DoorSet, OccupancyMap
    from doorbatch.pipeline.localize.run import LocalizationMap

    occ = np.full((20, 20), 10, dtype=np.int8)
    occ[:, 10] = 81
    grid = OccupancyMap(occ, 0.05, 0.0, 0.0)
    ours = LocalizationMap.of(grid, DoorSet.empty(), LocalizeConfig())
    amcl_like = LocalizationMap.of(grid, DoorSet.empty(), load_config(
        None, ["localize.map_occupied_at_least=100", "localize.map_free_at_most=0"]).localize)
    assert float(ours.field.dist[5, 10]) == 0.0 and len(ours.free) == 20 * 19
    assert float(amcl_like.field.dist[5, 10]) == pytest.approx(LocalizeConfig().laser_likelihood_max_dist)
    assert len(amcl_like.free) == 0
