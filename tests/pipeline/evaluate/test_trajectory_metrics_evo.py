"""APE and RPE equal evo's on the same TUM files (issue #6 acceptance), and the metrics' invariants."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.se2 import compose
from doorbatch.io.tum import read_tum, write_tum
from doorbatch.pipeline.evaluate.trajectory_metrics import (
    STATISTICS,
    Alignment,
    associate,
    rpe_pairs,
    statistics,
    trajectory_errors,
    umeyama_se2,
)

evo_metrics = pytest.importorskip("evo.core.metrics")
from evo.core import sync  # noqa: E402
from evo.tools import file_interface  # noqa: E402


def _corridor(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A robot driving down a corridor, turning round at the end (yaw through ±π), stamps at ~10 Hz."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.08, 0.12, n))
    s = np.linspace(0.0, 1.0, n)
    x = np.where(s < 0.6, 40.0 * s / 0.6, 40.0 - 25.0 * (s - 0.6) / 0.4)
    y = 1.5 * np.sin(6 * s) + np.where(s < 0.6, 0.0, 1.0)
    yaw = np.where(s < 0.6, 0.05 * np.cos(6 * s), np.pi - 0.02)
    return (1_700_000_000_000_000_000 + (t * 1e9).astype(np.int64)), np.stack([x, y, yaw], axis=1)


def _noisy_estimate(stamps: np.ndarray, ref: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Estimate: a rigid offset, noise, some poses dropped, stamps jittered by a few ms (and some by 30 ms)."""
    rng = np.random.default_rng(seed)
    keep = rng.random(len(stamps)) > 0.15
    est = compose(np.array([0.3, -0.2, 0.04]), ref[keep])
    est[:, :2] += rng.normal(0.0, 0.08, (keep.sum(), 2))
    est[:, 2] += rng.normal(0.0, 0.03, keep.sum())
    jitter = rng.integers(-4_000_000, 4_000_000, keep.sum())
    jitter[::11] = 30_000_000
    return stamps[keep] + jitter, est


def _evo_stats(ref_file: Path, est_file: Path, align: bool, all_pairs: bool) -> dict[str, dict[str, float]]:
    traj_ref = file_interface.read_tum_trajectory_file(str(ref_file))
    traj_est = file_interface.read_tum_trajectory_file(str(est_file))
    traj_ref, traj_est = sync.associate_trajectories(traj_ref, traj_est, max_diff=0.01)
    if align:
        traj_est.align(traj_ref, correct_scale=False)
    rel = evo_metrics.PoseRelation
    out = {}
    for name, relation in [("trans", rel.translation_part), ("deg", rel.rotation_angle_deg),
                           ("rad", rel.rotation_angle_rad)]:
        ape = evo_metrics.APE(relation)
        ape.process_data((traj_ref, traj_est))
        out[f"ape_{name}"] = ape.get_all_statistics()
        rpe = evo_metrics.RPE(relation, delta=1.0, delta_unit=evo_metrics.Unit.meters, all_pairs=all_pairs)
        rpe.process_data((traj_ref, traj_est))
        out[f"rpe_{name}"] = rpe.get_all_statistics()
    return out


@pytest.mark.parametrize(("align", "all_pairs", "seed"), [(False, False, 0), (True, False, 1), (False, True, 2),
                                                           (True, True, 3)])
def test_ape_and_rpe_statistics_equal_evo(tmp_path: Path, align: bool, all_pairs: bool, seed: int) -> None:
    stamps, ref = _corridor(600, seed)
    est_stamps, est = _noisy_estimate(stamps, ref, seed + 100)
    write_tum(tmp_path / "ref.tum", stamps, *ref.T)
    write_tum(tmp_path / "est.tum", est_stamps, *est.T)
    r, e = read_tum(tmp_path / "ref.tum"), read_tum(tmp_path / "est.tum")
    ours = trajectory_errors(e.stamp_ns, np.stack([e.x, e.y, e.yaw], axis=1), r.stamp_ns,
                             np.stack([r.x, r.y, r.yaw], axis=1), max_diff_s=0.01,
                             align=Alignment.SE2 if align else Alignment.NONE, rpe_delta_m=1.0,
                             rpe_all_pairs=all_pairs)
    evo = _evo_stats(tmp_path / "ref.tum", tmp_path / "est.tum", align, all_pairs)
    ours_stats = {"ape_trans": statistics(ours.ape_m), "ape_rad": statistics(ours.ape_rad),
                  "ape_deg": statistics(np.degrees(ours.ape_rad)), "rpe_trans": statistics(ours.rpe_m),
                  "rpe_rad": statistics(ours.rpe_rad), "rpe_deg": statistics(np.degrees(ours.rpe_rad))}
    assert 0.7 * len(e.stamp_ns) < len(ours.ape_m) < len(e.stamp_ns)  # the 30 ms stamps are not associated
    for metric, stats in ours_stats.items():
        for name in STATISTICS:
            assert stats[name] == pytest.approx(evo[metric][name], abs=1e-6), (metric, name)


def test_association_takes_the_nearest_stamp_within_the_tolerance() -> None:
    ref = np.array([0, 100, 200, 300], dtype=np.int64) * 1_000_000
    est = np.array([4, 96, 150, 211, 305], dtype=np.int64) * 1_000_000
    pairs = associate(ref, est, max_diff_s=0.01)  # est longer: each reference stamp finds its estimate
    assert pairs.ref_index.tolist() == [0, 1, 3]
    assert pairs.est_index.tolist() == [0, 1, 4]


def test_rpe_pairs_are_one_delta_apart_along_the_path() -> None:
    poses = np.stack([np.arange(0.0, 10.01, 0.25), np.zeros(41), np.zeros(41)], axis=1)
    first, second = rpe_pairs(poses, 1.0)
    assert first.tolist() == list(range(0, 37, 4))
    assert second.tolist() == list(range(4, 41, 4))


@settings(max_examples=30, deadline=None)
@given(st.floats(-50, 50), st.floats(-50, 50), st.floats(-math.pi, math.pi), st.integers(0, 2**31))
def test_metrics_are_unchanged_when_both_trajectories_move_rigidly(dx: float, dy: float, dyaw: float,
                                                                   seed: int) -> None:
    stamps, ref = _corridor(200, seed % 1000)
    est = compose(np.array([0.1, 0.05, 0.02]), ref) + np.random.default_rng(seed).normal(0, 0.05, ref.shape)
    moved = np.array([dx, dy, dyaw])
    a = trajectory_errors(stamps, est, stamps, ref)
    b = trajectory_errors(stamps, compose(moved, est), stamps, compose(moved, ref))
    np.testing.assert_allclose(a.ape_m, b.ape_m, atol=1e-9)
    np.testing.assert_allclose(a.rpe_m, b.rpe_m, atol=1e-9)
    np.testing.assert_allclose(a.ape_rad, b.ape_rad, atol=1e-9)


def test_se2_alignment_recovers_a_known_rigid_offset() -> None:
    stamps, ref = _corridor(300, 5)
    offset = np.array([2.0, -1.0, 0.7])
    est = compose(offset, ref)
    t = umeyama_se2(est[:, :2], ref[:, :2])
    np.testing.assert_allclose(compose(t, offset), np.zeros(3), atol=1e-9)
    errs = trajectory_errors(stamps, est, stamps, ref, align=Alignment.SE2)
    assert errs.ape_m.max() < 1e-9 and errs.ape_rad.max() < 1e-9
    assert trajectory_errors(stamps, est, stamps, ref).ape_m.min() > 0.5


def test_trajectories_on_two_clocks_are_an_error_that_says_so() -> None:
    from doorbatch.errors import PipelineError
    from doorbatch.pipeline.evaluate.trajectory_metrics import associate

    sim = np.arange(10) * 100_000_000 + 500_000_000  # sim time from 0.5 s
    wall = sim + 1_700_000_000 * 10**9  # the same instants on the wall clock
    with pytest.raises(PipelineError, match="another clock"):
        associate(wall, sim, 0.01)
    with pytest.raises(PipelineError) as near:  # overlapping spans, no pair within the tolerance: no such hint
        associate(sim + 50_000_000, sim, 0.01)
    assert "another clock" not in str(near.value)
