"""Hand-computed checks of the object-map rules of paper 001: which walls merge, which wall the M-step keeps,
the map prior's parameter counts, the colour variance floor, the door-angle search and the width procedure."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from doorbatch.config import DoorbatchConfig
from doorbatch.pipeline.objectmap import em
from doorbatch.pipeline.objectmap.beams import BeamSet
from doorbatch.pipeline.objectmap.colors import class_color_loglik, ml_class_colors
from doorbatch.pipeline.objectmap.doors import best_width, initial_angles, leaf_support
from doorbatch.pipeline.objectmap.em import MapState, evaluate, m_step_walls, merge_collinear, run_em
from doorbatch.pipeline.objectmap.model import WALL, ClassParams, Door, ObjectMap, Wall
from doorbatch.pipeline.objectmap.prior import log_prior, parameter_counts
from doorbatch.pipeline.objectmap.sensor import first_objects
from doorbatch.pipeline.objectmap.walls import wall_segments


def _beams_from(origins: np.ndarray, ends: np.ndarray, hit: np.ndarray | None = None) -> BeamSet:
    """One pass of beams from ``origins`` (N, 2) (or one (2,) origin) to ``ends`` (N, 2), dmax 20 m, no colour."""
    origins = np.broadcast_to(origins, ends.shape).astype(np.float64)
    d = ends - origins
    r = np.linalg.norm(d, axis=1)
    n = r.size
    return BeamSet(np.zeros(n, dtype=np.int64), origins, d / r[:, None], r, np.full(n, 20.0),
                   np.ones(n, dtype=bool) if hit is None else hit, np.full((n, 3), np.nan), 1)


# --- merge_collinear (em.py): a wall is a set of collinear segments (Sec. II) ---------------------------------


def test_parallel_walls_on_either_side_of_the_origin_are_not_merged() -> None:
    """y = 2 (n = (0, 1), β = 2) and y = −2 (n = (0, −1), β = 2): equal offsets, but n·p = β gives lines 4 m
    apart, so they stay two walls."""
    top = Wall(np.array([0.0, 1.0]), 2.0, np.array([[0.0, 1.0]]))
    bottom = Wall(np.array([0.0, -1.0]), 2.0, np.array([[0.0, 1.0]]))
    merged = merge_collinear([top, bottom], 2.0, 0.15)
    assert len(merged) == 2


def test_one_line_written_with_opposite_normals_is_merged_into_the_first_wall() -> None:
    """n = (0, 1), β = 2 and n = (0, −1), β = −2 are both the line y = 2. The first has tangent τ = (−1, 0), so
    s = −x: its segment [1, 2] is x ∈ [−2, −1]. The second has τ = (1, 0), s = x: its [0, 1] is x ∈ [0, 1],
    i.e. s ∈ [−1, 0] on the first line. Union: [[−1, 0], [1, 2]] on n = (0, 1), β = 2."""
    first = Wall(np.array([0.0, 1.0]), 2.0, np.array([[1.0, 2.0]]))
    flipped = Wall(np.array([0.0, -1.0]), -2.0, np.array([[0.0, 1.0]]))
    (merged,) = merge_collinear([first, flipped], 2.0, 0.15)
    np.testing.assert_allclose(merged.normal, [0.0, 1.0])
    assert merged.offset == 2.0
    np.testing.assert_allclose(merged.segments, [[-1.0, 0.0], [1.0, 2.0]], atol=1e-12)


# --- m_step_walls (em.py): a wall must pay for its line too -------------------------------------------------


def _hit_gain(lam: float, sigma: float, dmax: float) -> float:
    """Eq. (9)'s Δ for a beam ending exactly on a line with nothing behind it (Sec. III sensor model): present,
    log[λ/(σ√2π) + (1 − λ)/dmax] (α = 1 as the mean is far from 0 and dmax); absent (μ = dmax, z ≈ −360),
    the valid term vanishes and only log[(1 − λ)/dmax] is left."""
    invalid = np.log1p(-lam) - np.log(dmax)
    valid = np.log(lam) - np.log(sigma * np.sqrt(2.0 * np.pi))
    return float(np.logaddexp(valid, invalid) - invalid)


@pytest.mark.parametrize(("n_hits", "kept"), [(20, False), (40, True)])
def test_a_wall_is_kept_only_if_its_hits_pay_for_its_line_segment_and_length(n_hits: int, kept: bool) -> None:
    """Wall y = 2 seen by n hits spread over x ∈ [0, 0.1] from the origin. Its DP cost is −n·Δ + ρL·0.1 m + 2ρS
    (one segment), and the line costs 2ρS more (prior.py: 2 per line + 2 per segment). With the paper's ρS = 35,
    ρL = 70/m and Δ ≈ 5.92: 20 hits give a cost of −41.4, within (−2ρS, 0): dropped; 40 hits give −159.9: kept."""
    config = DoorbatchConfig().em
    xs = np.linspace(0.0, 0.1, n_hits)
    beams = _beams_from(np.zeros(2), np.stack([xs, np.full(n_hits, 2.0)], 1))
    wall = Wall(np.array([0.0, 1.0]), 2.0, np.array([[-0.1, 0.0]]))  # τ = (−1, 0): s = −x
    obj_map = ObjectMap([wall], [], ClassParams(0.9), 1)
    _, cost = wall_segments(beams, first_objects(beams, obj_map), obj_map, 0, wall.normal, wall.offset,
                            config.validity_prior, config.sigma_m, config.rho_length_per_m, 2.0 * config.rho_static)
    delta = _hit_gain(config.validity_prior, config.sigma_m, 20.0)
    expected = -n_hits * delta + config.rho_length_per_m * 0.1 + 2.0 * config.rho_static
    assert cost == pytest.approx(expected, abs=1e-6)
    if not kept:
        assert -2.0 * config.rho_static < cost < 0.0
    new_map = m_step_walls(beams, evaluate(beams, obj_map, config), config)
    assert len(new_map.walls) == (1 if kept else 0)


def test_a_wall_whose_hits_all_have_zero_expectation_keeps_its_line() -> None:
    """A wall whose hits the E-step gives weight 0 (all outliers) has no line to fit: eq. (8)'s weights summed
    to 0, the fit divided by it (a helper's 100 m floor: RuntimeWarning, NaN) and the wall's line became NaN. It
    now keeps its line, and the segment DP judges it as before."""
    config = DoorbatchConfig().em
    xs = np.linspace(0.0, 2.0, 60)
    beams = _beams_from(np.zeros(2), np.stack([xs, np.full(60, 2.0)], 1))
    wall = Wall(np.array([0.0, 1.0]), 2.0, np.array([[-2.0, 0.0]]))
    obj_map = ObjectMap([wall], [], ClassParams(0.9), 1)
    state = evaluate(beams, obj_map, config)
    state = replace(state, e=np.zeros_like(state.e))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new_map = m_step_walls(beams, state, config)
    for w in new_map.walls:
        assert np.isfinite(w.normal).all() and np.isfinite(w.offset)


# --- run_em (em.py): a wall M-step that lowers the log posterior is undone ---------------------------------


def test_a_wall_step_that_lowers_the_log_posterior_is_undone(monkeypatch: pytest.MonkeyPatch) -> None:
    """Wall y = 2 with 41 hits on it. A wall M-step that moves it to y = 2.5 puts every hit at least 10σ short of it,
    so the log posterior drops; run_em must keep y = 2 and its log posterior."""
    config = DoorbatchConfig().em
    xs = np.linspace(-1.0, 1.0, 41)
    beams = _beams_from(np.zeros(2), np.stack([xs, np.full(41, 2.0)], 1))
    wall = Wall(np.array([0.0, 1.0]), 2.0, np.array([[-1.0, 1.0]]))
    obj_map = ObjectMap([wall], [], ClassParams(0.9), 1)
    before = evaluate(beams, obj_map, config).log_posterior

    def shifted_walls(beams: BeamSet, state: MapState, config: object) -> ObjectMap:
        w = state.obj_map.walls[0]
        return replace(state.obj_map, walls=[Wall(w.normal, w.offset + 0.5, w.segments)])

    monkeypatch.setattr(em, "m_step_walls", shifted_walls)
    assert evaluate(beams, shifted_walls(beams, evaluate(beams, obj_map, config), config), config).log_posterior \
        < before
    state = run_em(beams, obj_map, config, learn_classes=False, iterations=1)
    assert state.obj_map.walls[0].offset == 2.0
    assert state.log_posterior >= before


# --- prior.py: p(M) ∝ exp(−ρG·MG − ρS·MS − ρD·MD − ρL·L[M]) (Sec. IV) --------------------------------------


def _one_wall_one_door_map(has_color: bool) -> ObjectMap:
    """One wall of two segments (1 m + 0.5 m) and one door of class width 0.9 m over 3 passes."""
    wall = Wall(np.array([0.0, 1.0]), 2.0, np.array([[0.0, 1.0], [2.0, 2.5]]))
    door = Door(np.array([3.0, 2.0]), np.zeros(3))
    return ObjectMap([wall], [door], ClassParams(0.9, has_color=has_color), 3)


def test_parameter_counts_of_a_wall_of_two_segments_and_a_door_over_three_passes() -> None:
    """By hand: MG = 1 (the door width; no colours); MS = 2 (line) + 2·2 (segments) + 2 (hinge) = 8;
    MD = 1 door · 3 passes = 3. With colours MG gains 6 per class present (walls and doors): 13."""
    assert parameter_counts(_one_wall_one_door_map(False), per_door_width=False) == (1, 8, 3)
    assert parameter_counts(_one_wall_one_door_map(True), per_door_width=False) == (13, 8, 3)
    assert parameter_counts(_one_wall_one_door_map(False), per_door_width=True) == (0, 9, 3)


def test_log_prior_of_a_wall_of_two_segments_and_a_door_over_three_passes() -> None:
    """log p(M) = −(ρG·1 + ρS·8 + ρD·3 + ρL·L) with L = 1 + 0.5 + 0.9 = 2.4 m, and the defaults ρG = ρS = 35,
    ρD = 45.5, ρL = 70/m: −(35 + 280 + 136.5 + 168) = −619.5."""
    config = DoorbatchConfig().em
    assert log_prior(_one_wall_one_door_map(False), config) == pytest.approx(-619.5, abs=1e-9)


# --- colors.py: the class colour variance is floored ---------------------------------------------------------


def test_class_colours_of_identical_colours_get_the_variance_floor() -> None:
    """Ten wall beams of colour (100, 150, 200), e = 1: the ML mean is that colour and the ML variance 0,
    floored at color_var_floor = 4 so that log N stays finite (log N(µ; µ, 4) = −1.5·log(8π) per beam);
    the door class has no beams and keeps its values."""
    config = DoorbatchConfig().em
    color = np.tile([100.0, 150.0, 200.0], (10, 1))
    classes = ml_class_colors(ClassParams(0.9), color, np.full(10, WALL, dtype=np.int64), np.ones(10),
                              config.color_var_floor, 1)
    np.testing.assert_allclose(classes.color_mean[WALL], [100.0, 150.0, 200.0])
    np.testing.assert_allclose(classes.color_var[WALL], [4.0, 4.0, 4.0])
    np.testing.assert_allclose(classes.color_var[1], [400.0, 400.0, 400.0])
    ll = class_color_loglik(color, WALL, classes)
    np.testing.assert_allclose(ll, np.full(10, -1.5 * np.log(8.0 * np.pi)))


# --- doors.py: the leaf-angle search that initialises a proposed door (Sec. VI) -----------------------------


def test_points_beyond_the_free_end_of_a_leaf_do_not_support_it() -> None:
    """Hinge (0, 0), leaf 1 m along +x. Five hits on the leaf (x = 0.2…0.8, y = 0) each add exp(0) = 1; five on
    the wall beyond its free end (x = 1.5…2.5) and one behind the hinge (x = −0.5) lie outside [−σ, w + σ]
    along it and add nothing: support 5."""
    on_leaf = np.stack([np.linspace(0.2, 0.8, 5), np.zeros(5)], 1)
    beyond = np.stack([np.linspace(1.5, 2.5, 5), np.zeros(5)], 1)
    behind = np.array([[-0.5, 0.0]])
    support = leaf_support(np.concatenate([on_leaf, beyond, behind]), np.zeros(2), np.array([0.0]), 1.0, 0.05)
    np.testing.assert_allclose(support, [5.0], atol=1e-12)


def test_a_leaf_direction_that_rays_pass_through_is_not_chosen() -> None:
    """Doorway x ∈ [0, 1] in the wall y = 0, hinge (0, 0), closed along +x; robot at (0.5, −2). A threshold
    along the doorway gives 12 hits on y = 0 (support ≈ 12 near the closed direction), the open leaf along +y 9
    hits on x = 0, y = 0.1…0.9 (support ≈ 9 near 90°). But 15 rays pass through the doorway and end at y = 3,
    and the rays to the open leaf at y ≥ 0.3 cross y = 0 more than through_margin (0.3 m) before their end: 22
    rays cross a leaf at ±1°, which scores 12 − 22 < 0. No ray crosses x = 0 for y ∈ [0, 1] (they cross y = 0
    at x ≥ 0.1 heading away from it). The candidates are −135° + 2k°, so 89° and 91°, equally supported and
    crossed by no ray, are best; of the two the nearer to closed: 89°."""
    config = DoorbatchConfig().em
    threshold = np.stack([np.linspace(0.1, 0.9, 12), np.zeros(12)], 1)
    leaf = np.stack([np.zeros(9), np.linspace(0.1, 0.9, 9)], 1)
    x0 = np.linspace(0.2, 0.8, 15)  # where the through rays cross y = 0
    through = np.stack([0.5 + (x0 - 0.5) * 2.5, np.full(15, 3.0)], 1)
    beams = _beams_from(np.array([0.5, -2.0]), np.concatenate([threshold, leaf, through]))
    (yaw,) = initial_angles(beams, np.zeros(2), 1.0, 0.0, config)
    assert np.rad2deg(yaw) == pytest.approx(89.0, abs=1e-9)


def test_of_near_tied_leaf_directions_the_one_nearest_closed_is_chosen() -> None:
    """Hinge (0, 0), closed along +x, directions every 15° (−135°…135°: 0°, 30° and 90° among them). 10 hits
    on the 30° line and 12 on the 90° line, each seen from 0.5 m off its own line on the side no other candidate
    leaf lies (no ray crosses either leaf): scores 10 and 12 (exp(0) per hit; the other line's hits are
    ≥ 0.2 m = 4σ off). 10 ≥ 0.8·12, a near tie, so the rule picks the one nearest the closed direction: 30°,
    not the best-supported 90°."""
    config = DoorbatchConfig().em.model_copy(update={"angle_search_step_deg": 15.0})
    u30 = np.linspace(0.25, 0.95, 10)
    d30, n30 = np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)]), np.array([-np.sin(np.pi / 6), np.cos(np.pi / 6)])
    on30 = u30[:, None] * d30
    u90 = np.linspace(0.25, 0.95, 12)
    on90 = np.stack([np.zeros(12), u90], 1)
    origins = np.concatenate([on30 - 0.5 * n30, on90 + np.array([-0.5, 0.0])])
    beams = _beams_from(origins, np.concatenate([on30, on90]))
    (yaw,) = initial_angles(beams, np.zeros(2), 1.0, 0.0, config)
    assert np.rad2deg(yaw) == pytest.approx(30.0, abs=1e-9)


# --- doors.py: the width procedure (Sec. V) ---------------------------------------------------------------


def test_the_width_procedure_charges_the_length_once_per_door() -> None:
    """Three doors' crossings pooled: gain 200 at u = 0.6 m and 40 at 0.9 m. Cost −ΣΔ + ρL·w·3 with ρL = 70/m:
    w = 0.6 → −200 + 126 = −74; w = 0.9 → −240 + 189 = −51, so 0.6 m (extending three leaves by 0.3 m costs 63 >
    40). Charged once (one door) it would be −158 against −177, i.e. 0.9 m."""
    u = np.array([0.6, 0.9])
    gain = np.array([200.0, 40.0])
    assert best_width(u, gain, 3, 70.0, 0.5, 1.3, 0.8) == pytest.approx(0.6)
    assert best_width(u, gain, 1, 70.0, 0.5, 1.3, 0.8) == pytest.approx(0.9)
