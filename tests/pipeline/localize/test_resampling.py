"""Resampling: low-variance counts, AMCL's KLD bound and adaptive draw, random-particle recovery."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcl_sim import room_map
from scipy import stats

from doorbatch.pipeline.localize.likelihood_field import free_cells
from doorbatch.pipeline.localize.resampling import (
    RecoveryState,
    bin_ids,
    cumulative_bins,
    kld_resample,
    kld_sample_count,
    kld_sample_counts,
    low_variance_resample,
    occupied_bins,
)

BIN_YAW = math.radians(10.0)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=60).filter(lambda w: sum(w) > 1e-6),
       st.integers(1, 500), st.integers(0, 2**32 - 1))
def test_low_variance_counts_are_within_one_of_expectation(weights: list[float], n_out: int, seed: int) -> None:
    w = np.asarray(weights)
    idx = low_variance_resample(w, n_out, np.random.default_rng(seed))
    counts = np.bincount(idx, minlength=w.size)
    assert idx.size == n_out
    assert np.all(np.abs(counts - n_out * w / w.sum()) <= 1.0 + 1e-9)
    assert np.all(counts[w == 0.0] == 0)
    assert np.all(np.diff(idx) >= 0)


def test_low_variance_rejects_bad_weights() -> None:
    rng = np.random.default_rng()
    for bad in ([], [0.0, 0.0], [1.0, -0.1], [np.nan, 1.0], [np.inf]):
        with pytest.raises(ValueError):
            low_variance_resample(bad, 3, rng)


def test_kld_bound_known_values() -> None:
    # (k − 1)/(2ε) · (1 − 2/(9(k − 1)) + √(2/(9(k − 1)))·z)³, ε = 0.01, computed by hand
    assert kld_sample_count(2, 0.01, 0.99, 1, 100_000) == 97
    assert kld_sample_count(10, 0.01, 0.99, 1, 100_000) == 651
    assert kld_sample_count(100, 0.01, 3.0, 1, 100_000) == 7332
    assert kld_sample_count(10, 0.01, 0.99, 700, 5000) == 700  # clamped to min
    assert kld_sample_count(100, 0.01, 3.0, 500, 5000) == 5000  # clamped to max


def test_kld_one_bin_takes_max_particles_as_amcl() -> None:
    """AMCL's pf_resample_limit returns max_samples for k ≤ 1 (Fox's formula would give 0 → min)."""
    assert kld_sample_count(1, 0.01, 0.99, 500, 5000) == 5000
    assert kld_sample_count(0, 0.01, 0.99, 500, 5000) == 5000


def test_kld_bound_is_monotone_and_approximates_the_chi_square_quantile() -> None:
    k = np.arange(2, 2000)
    n = kld_sample_counts(k, 0.05, 2.0, 1, 10**9)
    assert np.all(np.diff(n) >= 0)
    # Fox 2003: n = χ²_{k−1, 1−δ} / (2ε); Wilson–Hilferty with z = Φ⁻¹(1 − δ) is within 1 % from k = 10
    z = stats.norm.ppf(0.99)
    for kk in (10, 50, 500):
        exact = stats.chi2.ppf(0.99, kk - 1) / (2 * 0.05)
        assert kld_sample_count(kk, 0.05, float(z), 1, 10**9) == pytest.approx(exact, rel=0.01)


def test_bins_are_counted_like_amclss_kdtree_keys() -> None:
    pose = np.array([[0.1, 0.1, 0.01], [0.4, 0.2, 0.1], [0.6, 0.1, 0.01], [0.1, -0.1, 0.01], [0.1, 0.1, -0.01],
                     [0.49, 0.49, 0.17]])
    # bins: (0,0,0) ×2 and the last; x=1 bin; y=−1 bin; yaw −1 bin
    assert occupied_bins(pose, 0.5, BIN_YAW) == 4
    ids = bin_ids(pose, 0.5, BIN_YAW)
    assert ids[0] == ids[1] == ids[5] and len(set(ids.tolist())) == 4
    assert cumulative_bins(ids).tolist() == [1, 1, 2, 3, 4, 4]
    assert occupied_bins(np.zeros((0, 3)), 0.5, BIN_YAW) == 0


def test_a_lattice_of_bins_is_counted_bin_by_bin() -> None:
    """3 × 3 × 3 bin centres: 27 bins, one id each (a key that mixes the axes wrongly merges some)."""
    centres = np.stack(np.meshgrid(*(np.arange(3) + 0.5,) * 3, indexing="ij"), -1).reshape(-1, 3)
    pose = centres * np.array([0.5, 0.5, BIN_YAW])
    assert occupied_bins(pose, 0.5, BIN_YAW) == 27
    assert len(set(bin_ids(pose, 0.5, BIN_YAW).tolist())) == 27


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.05, 2.0))
def test_bins_equal_the_distinct_floored_keys(seed: int, spread_m: float) -> None:
    """Two particles share an id exactly when their floored (x / bin, y / bin, yaw / bin) keys are equal."""
    rng = np.random.default_rng(seed)
    pose = np.column_stack([rng.normal(0, spread_m, 300), rng.normal(3, spread_m, 300),
                            rng.uniform(-np.pi, np.pi, 300)])
    keys = [tuple(k) for k in np.floor(pose / np.array([0.5, 0.5, BIN_YAW])).astype(int).tolist()]
    ids = bin_ids(pose, 0.5, BIN_YAW).tolist()
    assert occupied_bins(pose, 0.5, BIN_YAW) == len(set(keys))
    assert len(set(zip(keys, ids, strict=True))) == len(set(keys)) == len(set(ids))


def test_kld_draw_stops_at_amcls_limit() -> None:
    rng = np.random.default_rng(7)
    spread = np.column_stack([rng.uniform(0, 3, 4000), rng.uniform(0, 3, 4000), rng.uniform(-np.pi, np.pi, 4000)])
    draw = kld_resample(spread, np.ones(4000), rng, min_particles=100, max_particles=20_000, pf_err=0.05, pf_z=0.99,
                        bin_xy_m=0.5, bin_yaw_rad=BIN_YAW)
    n = len(draw)
    assert n == kld_sample_count(draw.n_bins, 0.05, 0.99, 100, 20_000) + 1  # AMCL: stop when count > limit
    assert n < 20_000
    assert draw.n_bins == len({tuple(k) for k in np.floor(draw.pose / np.array([0.5, 0.5, BIN_YAW])).tolist()})
    assert np.array_equal(draw.pose, spread[draw.index]) and not draw.random.any()


def test_kld_draw_of_a_tight_cloud_takes_min_or_max_as_amcl() -> None:
    rng = np.random.default_rng(8)
    one_bin = np.tile([0.25, 0.25, 0.05], (1000, 1)) + rng.normal(0, 0.01, (1000, 3))
    assert len(kld_resample(one_bin, np.ones(1000), rng, min_particles=200, max_particles=3000, pf_err=0.01,
                            pf_z=0.99, bin_xy_m=0.5, bin_yaw_rad=BIN_YAW)) == 3000
    two_bins = one_bin + np.array([0.25, 0.0, 0.0])  # straddles x = 0.5
    assert len(kld_resample(two_bins, np.ones(1000), rng, min_particles=200, max_particles=3000, pf_err=0.01,
                            pf_z=0.99, bin_xy_m=0.5, bin_yaw_rad=BIN_YAW)) == 201


def test_kld_draw_follows_the_weights() -> None:
    rng = np.random.default_rng(9)
    pose = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [0.0, 5.0, 0.0]])
    draw = kld_resample(pose, [0.0, 0.75, 0.25], rng, min_particles=400, max_particles=400, pf_err=0.01,
                        pf_z=0.99, bin_xy_m=0.5, bin_yaw_rad=BIN_YAW)
    assert np.bincount(draw.index, minlength=3).tolist() == [0, 300, 100]


def test_recovery_injects_random_particles_when_w_fast_drops_below_w_slow() -> None:
    state = RecoveryState()
    assert state.random_fraction() == 0.0  # not initialized: AMCL's 1 − 0/0 injects nothing
    for _ in range(50):
        state = state.update(math.log(0.8), 0.001, 0.1)
    assert state.w_slow == pytest.approx(0.8) and state.random_fraction() == pytest.approx(0.0, abs=1e-12)
    for _ in range(10):  # kidnapped: the scan fits no particle
        state = state.update(math.log(0.01), 0.001, 0.1)
    expected_fast = 0.01 + (0.8 - 0.01) * 0.9**10
    expected_slow = 0.01 + (0.8 - 0.01) * 0.999**10
    assert state.w_fast == pytest.approx(expected_fast) and state.w_slow == pytest.approx(expected_slow)
    fraction = state.random_fraction()
    assert fraction == pytest.approx(1 - expected_fast / expected_slow)
    assert fraction > 0.5
    grid = room_map()
    free = free_cells(grid)
    rng = np.random.default_rng(10)
    pose = np.tile([1.0, 1.0, 0.0], (2000, 1))
    draw = kld_resample(pose, np.ones(2000), rng, min_particles=2000, max_particles=2000, pf_err=0.01, pf_z=0.99,
                        bin_xy_m=0.5, bin_yaw_rad=BIN_YAW, random_fraction=fraction, free=free)
    assert draw.random.mean() == pytest.approx(fraction, abs=0.04)
    ij = grid.world_to_cell(draw.pose[draw.random, :2])
    assert np.all(grid.occupancy[ij[:, 0], ij[:, 1]] == 0)
    assert np.all(draw.pose[~draw.random] == pose[0])
    with pytest.raises(ValueError, match="free cells"):
        kld_resample(pose, np.ones(2000), rng, min_particles=10, max_particles=10, pf_err=0.01, pf_z=0.99,
                     bin_xy_m=0.5, bin_yaw_rad=BIN_YAW, random_fraction=0.5)


def test_recovery_disabled_with_zero_alphas() -> None:
    state = RecoveryState().update(math.log(0.8), 0.0, 0.0)
    for _ in range(10):
        state = state.update(math.log(1e-6), 0.0, 0.0)
    assert state.random_fraction() == 0.0


def test_recovery_survives_likelihoods_below_float_range() -> None:
    state = RecoveryState().update(-2000.0, 0.01, 0.5).update(-2100.0, 0.01, 0.5)
    assert 0.49 < state.random_fraction() < 0.51
