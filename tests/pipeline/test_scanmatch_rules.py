"""Scan matching's small rules, each on a case worked out by hand: the search window's floors and clamps, the
constant-velocity prediction, the acceptance test, when a match is trusted, and which beams judge free space."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scanmatch_sim import room_segments, simulate_scan

from doorbatch.pipeline.poses import ScanMatchConfig
from doorbatch.pipeline.poses import scanmatch as sm
from doorbatch.pipeline.poses.correlative import (
    CorrelativeResult,
    build_likelihood_grid,
    correlative_match,
    sigma_window,
)
from doorbatch.pipeline.poses.free_space import RangeProfile
from doorbatch.pipeline.poses.plicp import GaussianPrior, PlicpResult
from doorbatch.pipeline.poses.scanmatch import (
    Submap,
    _accept,
    constant_velocity_increment,
    match_scan,
    start_submap,
)


def _plicp_result(pose: list[float], n_inliers: int) -> PlicpResult:
    """A converged, well-constrained ICP outcome at ``pose`` (only what the rules under test read matters)."""
    return PlicpResult(pose=np.array(pose), covariance=np.eye(3) * 1e-4, n_inliers=n_inliers, residual_m=0.01,
                       data_cost=0.0, prior_cost=0.0, sigma_m=0.01, degeneracy=1.0, iterations=3, converged=True,
                       outside_gate=np.zeros(0, dtype=bool))


def test_a_certain_pose_is_still_searched_over_the_window_floors() -> None:
    """A zero covariance has zero σ on every axis: each half-width is its floor (0.1 m, 2°), on yaw as on x, y."""
    assert sigma_window(np.zeros((3, 3)), 3.0, 0.1, 1.0, 2.0, 20.0) == ((0.1, 0.1), 2.0)
    # and a huge one is clipped to the ceilings (1 m, 20°)
    assert sigma_window(np.diag([100.0, 100.0, 100.0]), 3.0, 0.1, 1.0, 2.0, 20.0) == ((1.0, 1.0), 20.0)


def test_a_window_that_is_no_multiple_of_the_coarse_block_returns_a_pose_inside_it() -> None:
    """An L of points along both axes (cell centres, 5 cm cells), the scan the same L seen from (0.3, 0.3): six
    cells off. Searched ±0.25 m = ±5 cells with 4-cell coarse blocks, the last block spans shifts 3-6; shift 6
    (the truth, score 1) lies outside the window and must not be returned. Inside it the best is 5 cells on both
    axes, each arm's points one cell across their wall (the window's corner nearest the truth)."""
    arm = np.arange(0.0, 2.0, 0.05) + 0.025
    ref = np.concatenate([np.column_stack([arm, np.full_like(arm, 0.025)]),
                          np.column_stack([np.full_like(arm, 0.025), arm])])
    grid = build_likelihood_grid(ref, resolution_m=0.05, sigma_m=0.05, window_m=0.5, coarse_cells=4)
    scan = ref - 0.3
    inside = correlative_match(grid, scan, np.zeros(3), window_m=0.25, window_deg=0.0)
    np.testing.assert_allclose(inside.pose, [0.25, 0.25, 0.0], atol=1e-9)
    assert inside.score < 1.0
    wide = correlative_match(grid, scan, np.zeros(3), window_m=0.5, window_deg=0.0)  # truth inside: found
    np.testing.assert_allclose(wide.pose, [0.3, 0.3, 0.0], atol=1e-9)
    assert wide.score == 1.0


def test_the_constant_velocity_prediction_scales_the_last_increment_to_the_next_interval() -> None:
    """0.1 m forward and 0.01 rad over 0.1 s (heading +y, so the map step is along y): over the next 0.2 s the
    prediction is twice that increment, over 0.05 s half of it."""
    before = np.array([1.0, 2.0, math.pi / 2])
    last = np.array([1.0, 2.1, math.pi / 2 + 0.01])
    np.testing.assert_allclose(constant_velocity_increment(before, last, 0.1, 0.2), [0.2, 0.0, 0.02], atol=1e-12)
    np.testing.assert_allclose(constant_velocity_increment(before, last, 0.1, 0.05), [0.05, 0.0, 0.005],
                               atol=1e-12)


@pytest.mark.parametrize(("turn_deg", "accepted"), [(10.5, True), (11.5, False)])
def test_a_match_may_turn_one_yaw_step_past_the_window(turn_deg: float, accepted: bool) -> None:
    """Window ±10°, 1° steps: ICP refining a lattice pose on the window's edge may move it up to one step
    farther (10.5° accepted, half a step past the edge); beyond that (11.5°) it left the search window and is
    rejected."""
    cfg = ScanMatchConfig()
    assert cfg.correlative_step_deg == 1.0
    fine = _plicp_result([0.0, 0.0, math.radians(turn_deg)], cfg.min_inliers)
    assert _accept(fine, np.zeros(3), (0.25, 0.25), 10.0, cfg) is accepted


def test_a_match_with_half_its_points_on_submap_lines_is_trusted_after_trimming() -> None:
    """60 hits of the mapped room plus 50 points 20 m away where the submap has nothing: 59 of the 110 points
    find a line within the gate (54 %), and trimming keeps ⌈0.9 · 59⌉ = 54 of them. The trust threshold is
    min_overlap (0.5) of the points after the same trimming, 0.5 · 0.9 · 110 = 49.5: trusted, not weak (without
    the trimming the 55 needed would call the match weak)."""
    rng = np.random.default_rng(3)
    cfg = ScanMatchConfig()
    assert (cfg.min_overlap_fraction, cfg.trim_fraction) == (0.5, 0.9)
    start = np.array([3.0, 2.5, 0.3])
    submap = start_submap(simulate_scan(room_segments(), start, rng), start, cfg)
    truth = np.array([3.1, 2.45, 0.32])
    own = simulate_scan(room_segments(), truth, rng)[::6][:60]
    scan = np.concatenate([own, own[:50] + np.array([20.0, 0.0])])
    covariance = np.diag([0.03**2, 0.03**2, math.radians(1.0) ** 2])
    match = match_scan(submap, scan, truth, covariance, cfg)
    assert match.n_inliers == 54
    assert not match.weak and not match.fallback
    assert np.abs(match.pose[:2] - truth[:2]).max() < 0.02


@pytest.mark.parametrize(("wide_cost", "wide_wins"), [(5.0, False), (0.5, True)])
def test_a_wider_trusted_basin_replaces_the_weak_one_only_with_a_lower_basin_cost(
        monkeypatch: pytest.MonkeyPatch, wide_cost: float, wide_wins: bool) -> None:
    """The narrowest window finds a weak basin at the prediction (40 of 100 points inliers, under the 45 of
    min_overlap · trim · n); the wider windows find one a cell away that 90 points fit. It replaces the weak match
    only when its basin cost (here stubbed: 1 for the weak basin) is lower; otherwise the weak match is returned.
    The search and ICP are stubbed so that only match_scan's choice between the two is under test."""
    cfg = ScanMatchConfig()
    prior = np.zeros(3)
    narrow = sm.search_window(np.eye(3) * 1e-8, cfg)[0]
    weak_fit, wide_fit = _plicp_result([0.0, 0.0, 0.0], 40), _plicp_result([0.05, 0.0, 0.0], 90)

    def coarse(*_: object, window_m: tuple[float, float], **__: object) -> CorrelativeResult:
        return CorrelativeResult(prior if window_m == narrow else np.array([0.05, 0.0, 0.0]), 0.5)

    def refine(_submap: Submap, _scan: np.ndarray, start: np.ndarray, _prior: GaussianPrior,
               _cfg: ScanMatchConfig) -> PlicpResult:
        return weak_fit if start[0] == 0.0 else wide_fit

    def cost(_submap: Submap, _scan: np.ndarray, result: PlicpResult, _sigma_m: float, _cfg: ScanMatchConfig
             ) -> float:
        return 1.0 if result is weak_fit else wide_cost

    monkeypatch.setattr(sm, "correlative_match", coarse)
    monkeypatch.setattr(sm, "_refine", refine)
    monkeypatch.setattr(sm, "basin_cost", cost)
    submap = start_submap(simulate_scan(room_segments(), np.array([3.0, 2.5, 0.0]), np.random.default_rng(0)),
                          np.array([3.0, 2.5, 0.0]), cfg)
    scan = np.zeros((100, 2))
    match = match_scan(submap, scan, prior, np.eye(3) * 1e-8, cfg)
    assert not match.fallback
    assert match.weak is not wide_wins
    assert match.n_inliers == (90 if wide_wins else 40)


def test_a_point_just_outside_the_first_or_last_beam_is_judged_by_that_beam_alone() -> None:
    """A 90° scan of the wall x = 5 (1° beams from −45° to 45°, tolerance 1.5°). A point at −45.5° or 45.5° has one
    neighbouring beam within the tolerance (the other side's is the scan's far end, 90° away): 3 m out it lies
    in front of that beam's hit (7.07 m), so it is free; 9 m out it is behind it."""
    a = np.radians(np.linspace(-45.0, 45.0, 91))
    profile = RangeProfile.of_scan(np.stack([5.0 * np.ones_like(a), 5.0 * np.tan(a)], axis=1))
    bearings = np.radians([-45.5, 45.5])
    direction = np.stack([np.cos(bearings), np.sin(bearings)], axis=1)
    free, behind, on_surface = profile.verdicts(np.concatenate([3.0 * direction, 9.0 * direction]), margin_m=0.3)
    assert free.tolist() == [True, True, False, False]
    assert behind.tolist() == [False, False, True, True]
    assert not on_surface.any()
