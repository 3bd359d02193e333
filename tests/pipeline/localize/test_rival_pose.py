"""The rival search: a world symmetric under a 180° turn has a rival to every pose; an asymmetric room has none."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest
from mcl_sim import LASER_X, FloatArray, asymmetric_room, polyline, rasterize, room_recording, scan_ranges

from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, transform_points
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.likelihood_field import DistanceField
from doorbatch.pipeline.localize.rival_pose import RivalSearch, find_rival, scan_cloud
from doorbatch.pipeline.localize.run import LocalizationMap, _Track, localize_recording, rival_tested_claim

SETTINGS = RivalSearch(resolution_m=0.1, sigma_m=0.1, search_ratio=0.8, search_points=600, min_evidence_m=1.0,
                       max_candidates=2_000_000, radius_m=1.0, yaw_rad=math.radians(45.0))


def symmetric_room() -> FloatArray:
    """A 10 m × 4 m room, an alcove on each long wall and two pillars, unchanged by the 180° turn about (5, 2):
    (x, y, yaw) and (10 − x, 4 − y, yaw + π) see the same scan."""
    outer = polyline((0, 0), (2, 0), (2, -0.8), (3, -0.8), (3, 0), (10, 0), (10, 4), (8, 4), (8, 4.8), (7, 4.8),
                     (7, 4), (0, 4), (0, 0))
    pillars = [polyline((3.3, 1.0), (3.7, 1.0), (3.7, 1.4), (3.3, 1.4), (3.3, 1.0)),
               polyline((6.3, 2.6), (6.7, 2.6), (6.7, 3.0), (6.3, 3.0), (6.3, 2.6))]
    return np.concatenate([outer, *pillars])


def mirrored(pose: FloatArray) -> FloatArray:
    return np.array([10.0 - pose[0], 4.0 - pose[1], float(wrap_angle(pose[2] + math.pi))])


def placed(segments: FloatArray, world: FloatArray) -> FloatArray:
    """Segments (S, 2, 2) moved by the rigid motion ``world`` (x, y, yaw)."""
    return transform_points(world, segments.reshape(-1, 2)).reshape(-1, 2, 2)


def field_and_free(segments: FloatArray) -> tuple[DistanceField, npt.NDArray[np.bool_]]:
    lo, hi = segments.reshape(-1, 2).min(axis=0), segments.reshape(-1, 2).max(axis=0)
    occ = rasterize(segments, (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])))
    lmap = LocalizationMap.of(occ, DoorSet.empty(), DoorbatchConfig().localize)
    return lmap.field, lmap.free.free_mask


def path_cloud(segments: FloatArray, path: FloatArray, rng: np.random.Generator) -> FloatArray:
    """Hits of 360° scans (1 cm noise) from each pose of ``path``, in the last pose's frame."""
    hits = []
    for pose in path:
        r, a = scan_ranges(segments, pose, noise_m=0.01, rng=rng)
        ok = np.isfinite(r)
        hits.append(np.stack([LASER_X + r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])], axis=1))
    return scan_cloud(path, hits, path[-1], 0.1, 5000)


PATH = np.stack([np.linspace(1.5, 4.5, 16), np.full(16, 2.0), np.zeros(16)], axis=1)


@pytest.mark.parametrize("world", [[0.0, 0.0, 0.0], [0.013, 0.031, math.radians(17.3)],
                                   [-0.47, 0.26, math.radians(-131.0)], [0.08, -0.02, math.radians(61.7)]])
def test_a_symmetric_room_has_a_rival_at_the_turned_pose_wherever_the_lattice_falls(world: list[float]) -> None:
    w = np.asarray(world)
    segments = placed(symmetric_room(), w)
    path = np.array([compose(w, p) for p in PATH])
    field, free = field_and_free(segments)
    cloud = path_cloud(segments, path, np.random.default_rng(1))
    for estimate, rival in ((path[-1], compose(w, mirrored(PATH[-1]))), (compose(w, mirrored(PATH[-1])), path[-1])):
        found = find_rival(field, free, estimate, cloud, SETTINGS)
        assert found.rival is not None and not found.undecided
        assert found.rival.evidence_m < SETTINGS.min_evidence_m and found.rival.ratio > 0.97
        assert np.hypot(*(found.rival.pose[:2] - rival[:2])) < 0.2
        assert abs(float(wrap_angle(found.rival.pose[2] - rival[2]))) < math.radians(3.0)


def test_one_niche_breaks_the_symmetry() -> None:
    """The symmetric room with a 1 m × 0.5 m niche in the south wall's east half, which the turned pose would put
    in the north wall's west half: its few metres of wall refute the turned pose though the rest fits it."""
    segments = symmetric_room()
    south = segments[4]  # (3, 0) → (10, 0)
    assert np.allclose(south, [[3, 0], [10, 0]])
    niche = polyline((3, 0), (8, 0), (8, -0.5), (9, -0.5), (9, 0), (10, 0))
    segments = np.concatenate([segments[:4], niche, segments[5:]])
    field, free = field_and_free(segments)
    cloud = path_cloud(segments, PATH, np.random.default_rng(5))
    found = find_rival(field, free, PATH[-1], cloud, SETTINGS)
    assert found.rival is None and found.nearest is not None
    assert np.hypot(*(found.nearest.pose[:2] - mirrored(PATH[-1])[:2])) < 0.2
    assert found.nearest.ratio > 0.9 and found.nearest.evidence_m >= SETTINGS.min_evidence_m
    # from the turned pose (a cloud that settled on the wrong one of the two) the truth is a rival the scans prefer
    wrong = find_rival(field, free, mirrored(PATH[-1]), cloud, SETTINGS).rival
    assert wrong is not None and np.hypot(*(wrong.pose[:2] - PATH[-1][:2])) < 0.2
    assert wrong.evidence_m < SETTINGS.min_evidence_m <= wrong.counter_m and wrong.ratio > 1.0


def test_an_asymmetric_room_has_no_rival() -> None:
    segments = asymmetric_room()
    path = np.stack([np.linspace(1.5, 6.0, 16), np.full(16, 2.2), np.zeros(16)], axis=1)
    field, free = field_and_free(segments)
    found = find_rival(field, free, path[-1], path_cloud(segments, path, np.random.default_rng(2)), SETTINGS)
    assert found.rival is None and not found.undecided and found.points > 100
    # with a low search bar candidates come up, away from the estimate; each leaves metres of wall only it explains
    low = find_rival(field, free, path[-1], path_cloud(segments, path, np.random.default_rng(2)),
                     RivalSearch(**{**SETTINGS.__dict__, "search_ratio": 0.3}))
    assert low.rival is None and low.nearest is not None
    assert low.nearest.evidence_m > 3.0 * SETTINGS.min_evidence_m
    far = np.hypot(*(low.nearest.pose[:2] - path[-1][:2])) > SETTINGS.radius_m
    assert far or abs(float(wrap_angle(low.nearest.pose[2] - path[-1][2]))) > SETTINGS.yaw_rad


def test_a_global_start_in_a_symmetric_room_reports_ambiguity_instead_of_a_claim() -> None:
    segments = symmetric_room()
    n = 80  # 8 s at 10 Hz, 0.05 m a scan: 4 m down the room and a turn back
    x = np.concatenate([np.linspace(1.5, 5.5, 60), np.full(20, 5.5)])
    yaw = np.concatenate([np.zeros(60), np.linspace(0.0, 1.5, 20)])
    truth = np.stack([x, np.full(n, 2.0), yaw], axis=1)
    rng = np.random.default_rng(3)
    rec = room_recording(truth, truth - truth[0], rng, segments=segments)
    occ = rasterize(segments, (0.0, 10.0), (-0.8, 4.8))
    config = load_config(None, ["localize.seed=0", "localize.converged_hold_s=1.0"])
    lmap = LocalizationMap.of(occ, DoorSet.empty(), config.localize)
    result = localize_recording(rec, lmap, config, "mcl", "global")
    end = result.pose[-1]
    assert min(np.hypot(*(end[:2] - truth[-1][:2])), np.hypot(*(end[:2] - mirrored(truth[-1])[:2]))) < 0.3
    assert result.ambiguous and result.converged_ns is None
    assert any(w.startswith("ambiguous: the scans from when the cloud became tight") for w in result.warnings)
    off = load_config(None, ["localize.seed=0", "localize.converged_hold_s=1.0", "localize.rival_check=false"])
    assert localize_recording(rec, lmap, off, "mcl", "global").converged_ns is not None


def test_a_search_that_outgrows_its_bound_is_undecided_not_a_rival() -> None:
    segments = symmetric_room()
    field, free = field_and_free(segments)
    cloud = path_cloud(segments, PATH, np.random.default_rng(4))
    tight = RivalSearch(**{**SETTINGS.__dict__, "max_candidates": 10})
    found = find_rival(field, free, PATH[-1], cloud, tight)
    assert found.undecided and found.rival is None
    assert find_rival(field, free, PATH[-1], cloud, SETTINGS).rival is not None


def test_the_cloud_keeps_one_point_per_cell_in_the_last_pose_frame() -> None:
    poses = np.array([[1.0, 0.0, 0.0], [2.0, 0.0, math.pi / 2]])
    hits = [np.array([[1.05, -0.05], [1.07, -0.02]]), np.array([[1.0, 0.0]])]
    cloud = scan_cloud(poses, hits, poses[-1], 0.1, 100)
    # world (2.05, −0.05), (2.07, −0.02) and (2, 1): in the last pose's frame (−0.05, −0.05) and (−0.02, −0.07), one
    # cell, the first kept, and (1, 0)
    assert sorted(map(tuple, np.round(cloud, 6))) == [(-0.05, -0.05), (1.0, 0.0)]
    assert len(scan_cloud(poses, hits, poses[-1], 0.1, 1)) == 1


def _niche_room() -> FloatArray:
    """The symmetric room with a 1 m × 0.5 m niche in the south wall at x = 8–9 (turned: the north wall at x = 1–2)."""
    segments = symmetric_room()
    niche = polyline((3, 0), (8, 0), (8, -0.5), (9, -0.5), (9, 0), (10, 0))
    return np.concatenate([segments[:4], niche, segments[5:]])


@pytest.mark.parametrize(("niche", "claim_i", "expected"), [(True, 20, (55, 70)), (True, 68, (68, 68)),
                                                             (False, 20, None)])
def test_a_claim_moves_to_when_the_scans_first_tell_the_pose(niche: bool, claim_i: int,
                                                            expected: tuple[int, int] | None) -> None:
    """A 2.5 m laser driven east from x = 4 to 8.5 m, 0.064 m an update: the niche comes into view near its corner
    (8, 0) (2.5 m from x ≈ 6.5 m; enough of it for a metre of evidence at x = 7.5 m, update 55, or a little later). A
    claim before that moves there; one after stays; without the niche the turned pose stays a rival, and the run is
    ambiguous."""
    segments = _niche_room() if niche else symmetric_room()
    truth = np.stack([np.linspace(4.0, 8.5, 71), np.full(71, 2.0), np.zeros(71)], axis=1)
    rec = room_recording(truth, truth, np.random.default_rng(6), segments=segments, max_range=2.5)
    config = load_config(None, [])
    lmap = LocalizationMap.of(rasterize(segments, (0.0, 10.0), (-0.8, 4.8)), DoorSet.empty(), config.localize)
    track = _Track()
    track.stamps.extend(int(t) for t in rec.scans.stamps_ns)
    track.pose.extend(truth)
    stamps = rec.scans.stamps_ns
    tested = rival_tested_claim(rec, lmap, track, list(range(71)), int(stamps[0]), int(stamps[claim_i]),
                                config.localize)
    if expected is None:
        assert tested.converged_ns is None and tested.ambiguous and tested.note is not None
        return
    assert tested.converged_ns is not None and not tested.ambiguous
    moved_to = int(np.searchsorted(stamps, tested.converged_ns))
    assert expected[0] <= moved_to <= expected[1]
    assert (tested.note is None) == (moved_to == claim_i)
