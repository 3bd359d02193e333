"""The global-localization convergence detector: tight, unimodal, held over time and travel."""

from __future__ import annotations

import numpy as np

from doorbatch.config import LocalizeConfig
from doorbatch.pipeline.localize.convergence import ConvergenceMonitor, multimodal, multimodal_note
from doorbatch.pipeline.localize.particles import ParticleSet

CONFIG = LocalizeConfig(converged_hold_s=2.0, converged_min_travel_m=1.0)


def cloud(centres: list[tuple[float, float, float]], weights: list[float], n: int = 400,
          seed: int = 0) -> ParticleSet:
    """Tight clusters (0.05 m, 1°) around ``centres`` holding ``weights`` of the weight."""
    rng = np.random.default_rng(seed)
    k = len(centres)
    pose = np.repeat(np.asarray(centres, dtype=np.float64), n // k, axis=0)
    pose += rng.normal(0.0, [0.05, 0.05, np.radians(1.0)], pose.shape)
    w = np.repeat(np.asarray(weights, dtype=np.float64) / (n // k), n // k)
    return ParticleSet(pose, w / w.sum(), np.zeros((len(w), 0)), np.zeros((len(w), 0)))


def run(particles: ParticleSet, speed_m_s: float, seconds: float = 5.0) -> int | None:
    """Feed the same cloud at 10 Hz while the odometry moves at ``speed_m_s``; the claimed stamp (ns)."""
    monitor = ConvergenceMonitor()
    for k in range(int(seconds * 10) + 1):
        monitor = monitor.update(k * 100_000_000, (speed_m_s * k / 10, 0.0, 0.0), particles, CONFIG)
    return monitor.converged_ns


def test_a_tight_unimodal_cloud_converges_after_the_hold_time_and_travel() -> None:
    # 0.5 m/s: 2 s of hold and 1 m of travel are both met at t = 2 s
    assert run(cloud([(1.0, 2.0, 0.3)], [1.0]), 0.5) == 2_000_000_000
    # 0.25 m/s: the travel decides (1 m at 4 s)
    assert run(cloud([(1.0, 2.0, 0.3)], [1.0]), 0.25) == 4_000_000_000


def test_a_standing_robot_never_claims_convergence() -> None:
    assert run(cloud([(1.0, 2.0, 0.3)], [1.0]), 0.0) is None


def test_two_clusters_with_substantial_weight_are_ambiguous_not_converged() -> None:
    mirrored = cloud([(1.0, 2.0, 0.0), (9.0, 2.0, np.pi)], [0.7, 0.3])
    assert multimodal(mirrored, CONFIG)
    assert run(mirrored, 0.5) is None
    # a second cluster with little weight is not an ambiguity; nor is a cluster within the radius
    assert not multimodal(cloud([(1.0, 2.0, 0.0), (9.0, 2.0, np.pi)], [0.97, 0.03]), CONFIG)
    assert not multimodal(cloud([(1.0, 2.0, 0.0), (1.5, 2.0, 0.0)], [0.5, 0.5]), CONFIG)
    # apart in position alone (a door spacing along a corridor), or in heading alone (turned in place)
    assert multimodal(cloud([(1.0, 2.0, 0.3), (6.0, 2.0, 0.3)], [0.6, 0.4]), CONFIG)
    assert multimodal(cloud([(1.0, 2.0, 0.0), (1.0, 2.0, np.pi)], [0.5, 0.5]), CONFIG)


def test_a_multimodal_cloud_is_reported_with_both_hypotheses() -> None:
    """A tracked run's `ambiguous` came with no word (an outside user's skid-steer base under Nav2's α = 0.2): the
    warning names where the strongest hypothesis and the next lie, and the weight each holds."""
    note = multimodal_note(cloud([(1.0, 2.0, 0.0), (9.0, 2.0, np.pi), (1.2, 2.1, 0.0)], [0.5, 0.3, 0.2], n=600),
                           CONFIG)
    assert "70% of its weight" not in note and "30% of its weight away" in note
    assert "hypothesis (1.0" in note and "(70%)" in note  # the two clusters within 1 m of each other are one
    assert "the next is (9.0" in note or "the next is (8.9" in note
    assert "180°" in note and note.endswith("(localize.alpha1 … alpha4)")
    assert "alpha" not in multimodal_note(cloud([(1.0, 2.0, 0.0), (9.0, 2.0, np.pi)], [0.6, 0.4]), CONFIG,
                                          tracked=False)  # a global start: the map's symmetry, not the odometry


def test_the_strongest_hypothesis_is_the_heaviest_mode_not_the_heaviest_particle() -> None:
    """A mode of many light particles (92 % of the weight near (-2.45, 0.34)) beside one heavy particle (3 %) and a
    third mode (5 %): the note names the 92 % mode as the strongest (orebro's named the 3 % particle), and the
    cloud is not ambiguous (8 % away from it; 97 % away from the heavy particle flagged it)."""
    light = cloud([(-2.45, 0.34, 0.0), (5.0, 0.3, 0.0)], [0.92, 0.05], n=600)
    pose = np.vstack([light.pose, [[-0.64, 0.52, -0.33]]])
    w = np.append(light.weight * 0.97, 0.03)
    cloud_ = ParticleSet(pose, w, np.zeros((w.size, 0)), np.zeros((w.size, 0)))
    note = multimodal_note(cloud_, CONFIG)
    assert "8% of its weight away from its strongest hypothesis (-2.4" in note and "(92%)" in note
    assert not multimodal(cloud_, CONFIG)  # 8 % away, under ambiguity_min_weight (10 %): the flag agrees


def test_a_streak_broken_by_a_wide_cloud_starts_over() -> None:
    tight, wide = cloud([(1.0, 2.0, 0.3)], [1.0]), cloud([(1.0, 2.0, 0.3), (6.0, 2.0, 0.3)], [0.5, 0.5])
    monitor = ConvergenceMonitor()
    for k in range(41):  # tight for 1.5 s, wide once, then tight again
        p = wide if k == 15 else tight
        monitor = monitor.update(k * 100_000_000, (0.5 * k / 10, 0.0, 0.0), p, CONFIG)
    assert monitor.converged_ns == 3_600_000_000  # 2 s after the streak restarted at 1.6 s
    monitor = ConvergenceMonitor()
    for k in range(61):  # slower, 1/32 m a step (exact in binary): the 1 m of travel decides, from the restart only
        p = wide if k == 15 else tight
        monitor = monitor.update(k * 100_000_000, (k / 32, 0.0, 0.0), p, CONFIG)
    assert monitor.converged_ns == 4_800_000_000  # 1.6 s + 32 steps of 0.1 s


def test_a_claim_is_withdrawn_when_the_cloud_later_splits() -> None:
    tight, split = cloud([(1.0, 2.0, 0.3)], [1.0]), cloud([(1.0, 2.0, 0.3), (6.0, 2.0, 0.3)], [0.6, 0.4])
    monitor = ConvergenceMonitor()
    for k in range(31):
        monitor = monitor.update(k * 100_000_000, (0.5 * k / 10, 0.0, 0.0), tight, CONFIG)
    assert monitor.converged_ns == 2_000_000_000
    monitor = monitor.update(3_100_000_000, (1.55, 0.0, 0.0), split, CONFIG)
    assert monitor.converged_ns is None


def _fed(fits: list[float], through: list[float] | None = None) -> list[ConvergenceMonitor]:
    """A tight cloud moving at 0.5 m/s at 10 Hz whose scans fit the map as ``fits`` and ``through`` (the share of
    beams through its walls; none by default) say, one per update."""
    tight, monitor, states = cloud([(1.0, 2.0, 0.3)], [1.0]), ConvergenceMonitor(), []
    for k, fit in enumerate(fits):
        monitor = monitor.update(k * 100_000_000, (0.05 * k, 0.0, 0.0), tight, CONFIG, fit,
                                 0.0 if through is None else through[k])
        states.append(monitor)
    return states


def test_a_claim_on_a_pose_whose_scans_stop_fitting_the_map_is_withdrawn_as_lost() -> None:
    """Criterion 4 (an outside tester's world: the turned pose of a symmetric corridor fitted for 40 s, then drove
    through the end wall with the claim standing). Under lost_min_fit for lost_after_s (2 s): lost, no claim."""
    states = _fed([0.9] * 31 + [0.2] * 21)
    assert states[30].converged_ns == 2_000_000_000 and not any(s.lost for s in states[:51])
    assert states[51].lost and states[51].converged_ns is None  # 2.0 s after the first poor fit at 3.1 s
    # a dip shorter than that (a person in front of the laser) leaves the claim standing
    dipped = _fed([0.9] * 31 + [0.2] * 19 + [0.9] * 5)
    assert not any(s.lost for s in dipped) and dipped[-1].converged_ns == 2_000_000_000


def test_no_claim_is_made_while_the_scans_fit_poorly() -> None:
    states = _fed([0.3] * 19 + [0.9] * 41)  # poor for 1.9 s (not yet lost), then fitting
    assert not any(s.lost for s in states)
    assert states[-1].converged_ns == 2_000_000_000  # the streak from t = 0, but claimed only once fitting
    # fitting, then poor from 1.0 to 2.8 s: hold and travel are met at 2.0 s, the claim waits for the fit at 2.9 s
    states = _fed([0.9] * 10 + [0.3] * 19 + [0.9] * 31)
    assert not any(s.lost for s in states) and states[28].converged_ns is None
    assert states[-1].converged_ns == 2_900_000_000


def test_scan_fit_counts_the_hits_near_the_maps_walls() -> None:
    from doorbatch.maps import OccupancyMap
    from doorbatch.pipeline.localize.convergence import scan_fit
    from doorbatch.pipeline.localize.likelihood_field import build_distance_field

    occ = np.zeros((40, 40), dtype=np.int8)
    occ[:, 20] = 100  # a wall x = 1.0 m (0.05 m cells from the origin)
    field = build_distance_field(OccupancyMap(occ, 0.05, 0.0, 0.0), 2.0)
    on_wall = np.stack([np.full(6, 1.02), np.linspace(-0.5, 0.5, 6)], 1)
    off_wall = np.stack([np.full(6, 0.4), np.linspace(-0.5, 0.5, 6)], 1)  # 0.6 m off
    hits = np.concatenate([on_wall, off_wall])
    assert scan_fit(field, (0.0, 0.5, 0.0), hits, 0.3) == 0.5
    assert np.isnan(scan_fit(field, (0.0, 0.5, 0.0), hits[:2], 0.3))  # too few hits to tell: no evidence


def test_scans_without_evidence_neither_end_nor_start_a_run_of_poor_fits() -> None:
    """An open space the laser sees nothing in (fit NaN) does not reset the lost timer, nor start it."""
    states = _fed([0.9] * 31 + [0.2] * 10 + [float("nan")] * 5 + [0.2] * 6)
    assert not any(s.lost for s in states[:51]) and states[51].lost  # 2 s after the first poor fit, NaNs included
    assert not any(s.lost for s in _fed([0.9] * 31 + [float("nan")] * 40))


def test_a_spread_cloud_is_never_lost_whatever_its_mean_fits() -> None:
    """A uniform start's mean is no pose: its poor fit must not restart a cloud that is still converging."""
    wide = cloud([(1.0, 2.0, 0.3), (6.0, 2.0, 0.3)], [0.5, 0.5])
    monitor = ConvergenceMonitor()
    for k in range(60):
        monitor = monitor.update(k * 100_000_000, (0.05 * k, 0.0, 0.0), wide, CONFIG, 0.0)
        assert not monitor.lost and monitor.converged_ns is None


def test_a_pose_whose_beams_pass_through_walls_is_lost_though_its_hits_fit() -> None:
    """Criterion 4's second half: hits near walls (0.9) but 30 % of the beams through them for lost_after_s."""
    states = _fed([0.9] * 52, [0.0] * 31 + [0.3] * 21)
    assert states[30].converged_ns == 2_000_000_000 and not any(s.lost for s in states[:51])
    assert states[51].lost and states[51].converged_ns is None
    assert not any(s.lost for s in _fed([0.9] * 52, [0.0] * 31 + [0.1] * 21))  # under lost_max_see_through


def _doorway_corridor() -> np.ndarray:
    """An outside tester's office: a 2 m wide corridor along x ∈ [0, 24] with a 1 m doorway every 4 m on both
    walls, each into a 1 m deep alcove; away from the ends every 4 m looks alike."""
    from mcl_sim import polyline

    walls = [polyline((0.0, -1.0), (0.0, 1.0)), polyline((24.0, -1.0), (24.0, 1.0))]
    for side in (-1.0, 1.0):
        x = 0.0
        for k in range(6):
            c = 2.0 + 4.0 * k  # a doorway's centre
            walls.append(polyline((x, side), (c - 0.5, side)))
            walls.append(polyline((c - 0.5, side), (c - 0.5, 2 * side), (c + 0.5, 2 * side), (c + 0.5, side)))
            x = c + 0.5
        walls.append(polyline((x, side), (24.0, side)))
    return np.concatenate(walls)


def test_beams_of_a_pose_shifted_along_a_doorway_corridor_pass_through_its_walls() -> None:
    """An outside tester's kidnap: 2 m along a corridor with doorways every 4 m, the hits still lie on walls
    (the hit test's fit stays above 0.5) but the beams into the alcoves now cross the walls between them."""
    from mcl_sim import LASER_X, rasterize, scan_ranges

    from doorbatch.pipeline.localize.convergence import scan_fit, see_through_share
    from doorbatch.pipeline.localize.likelihood_field import build_distance_field

    segments = _doorway_corridor()
    occ = rasterize(segments, (0.0, 24.0), (-2.0, 2.0))
    field = build_distance_field(occ, 2.0)
    truth = np.array([10.0, 0.0, 0.0])  # in a doorway pair (elsewhere in the 4 m period 0.08-0.18 pass through)
    r, a = scan_ranges(segments, truth, n_beams=360, noise_m=0.01, rng=np.random.default_rng(0))
    ok = np.isfinite(r)
    hits = np.stack([LASER_X + r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])], axis=1)  # base_link
    origin = np.array([LASER_X, 0.0])

    def measures(pose: np.ndarray) -> tuple[float, float]:
        return (scan_fit(field, pose, hits, 0.3), see_through_share(occ, field, pose, origin, hits, 0.3, 65, 180))

    fit, through = measures(truth)
    assert fit > 0.95 and through == 0.0
    fit, through = measures(truth + np.array([2.0, 0.0, 0.0]))
    assert fit > 0.5 and through > 0.2  # the hits alone would not tell; the beams do
    fit, through = measures(truth + np.array([4.0, 0.0, 0.0]))  # a whole doorway spacing: no beam can tell
    assert through < 0.05


def test_see_through_share_counts_beams_that_cross_a_wall_and_end_where_the_map_has_nothing() -> None:
    from doorbatch.maps import OccupancyMap
    from doorbatch.pipeline.localize.convergence import see_through_share
    from doorbatch.pipeline.localize.likelihood_field import build_distance_field

    occ = np.zeros((40, 120), dtype=np.int8)
    occ[:, 20] = 100  # a wall at x = 1.0-1.05 m
    occ[:, 100] = 100  # another at x = 5.0-5.05 m
    occ[:, 60] = -1  # an unknown column at x = 3 m holds nothing
    grid = OccupancyMap(occ, 0.05, 0.0, 0.0)
    field = build_distance_field(grid, 2.0)
    ys = np.linspace(-0.5, 0.5, 10)
    beyond = np.stack([np.full(10, 2.0), ys], 1)  # hits 1 m behind the first wall, far from both
    at_wall = np.stack([np.full(10, 1.1), ys], 1)  # within the margin past the wall
    on_next = np.stack([np.full(10, 5.0), ys], 1)  # through the first wall onto the next: a door mapped closed
    pose = (0.0, 1.0, 0.0)

    def share(p: tuple[float, float, float], hits: np.ndarray, beams: int = 180) -> float:
        return see_through_share(grid, field, p, (0.0, 0.0), hits, 0.3, 65, beams)

    assert share(pose, np.concatenate([beyond, at_wall])) == 0.5
    assert share(pose, on_next) == 0.0  # the crossed wall is not there now; the pose may well be right
    assert share((2.0, 1.0, 0.0), beyond) == 0.0  # from past the wall
    assert share(pose, beyond, beams=4) == 1.0  # at most 4 beams cast
    assert np.isnan(share(pose, beyond[:3]))  # too few hits to tell


def test_the_lost_warning_names_the_criterion_and_what_a_poor_fit_without_beams_through_walls_means() -> None:
    from doorbatch.pipeline.localize.run import lost_note

    through = lost_note(3.0, [(k, 0.9, 0.3) for k in range(20)], CONFIG)
    assert through.startswith("lost at 3.0 s: over 15% of the scans' beams passed through the map's walls to end")
    short = lost_note(3.0, [(k, 0.2, 0.01) for k in range(20)], CONFIG)
    assert short.startswith("lost at 3.0 s: under 50% of the scans' hits") and "or the map lacks what it sees" in short
    both = lost_note(3.0, [(k, 0.2, 0.4) for k in range(20)], CONFIG)  # hits off walls, beams through them
    assert both.startswith("lost at 3.0 s: under 50%") and "map lacks" not in both
    assert not any("similar places" in note for note in (through, short, both))  # a tracked run's
    for recent in ([(k, 0.9, 0.3) for k in range(20)], [(k, 0.2, 0.01) for k in range(20)]):  # a global start's
        assert "the wrong one of similar places" in lost_note(3.0, recent, CONFIG, global_start=True)


def _moving(k: int, offset_m: float = 0.0, wide: bool = False) -> ParticleSet:
    """The cloud at update k of a robot driving 0.05 m an update along x from (1, 2), ``offset_m`` further along;
    split into two clusters 5 m apart when ``wide``."""
    x = 1.0 + 0.05 * k + offset_m
    return cloud([(x, 2.0, 0.0), (x + 5.0, 2.0, 0.0)], [0.5, 0.5]) if wide else cloud([(x, 2.0, 0.0)], [1.0])


def test_a_claim_the_cloud_comes_back_to_after_a_break_keeps_its_time() -> None:
    """A sparse log's long odometry step spreads a right cloud for an update (intel from a global start: claimed at
    36 s, split for two updates at 2,264 s, and reported as converged at 2,272 s)."""
    monitor = ConvergenceMonitor()
    for k in range(61):  # claimed at 2 s; split at 3.0-3.1 s; tight again where the odometry carried it
        monitor = monitor.update(k * 100_000_000, (0.05 * k, 0.0, 0.0), _moving(k, wide=k in (30, 31)), CONFIG)
        if k in (30, 31):
            assert monitor.converged_ns is None and monitor.suspended_ns == 2_000_000_000
    assert monitor.converged_ns == 2_000_000_000
    # back 3 m further along (another door of a corridor): a new streak, claimed 2 s after it starts
    monitor = ConvergenceMonitor()
    for k in range(71):
        monitor = monitor.update(k * 100_000_000, (0.05 * k, 0.0, 0.0),
                                 _moving(k, 3.0 if k >= 32 else 0.0, wide=k in (30, 31)), CONFIG)
    assert monitor.converged_ns == 5_200_000_000
    # never back: the claim is withdrawn at the end
    monitor = ConvergenceMonitor()
    for k in range(41):
        monitor = monitor.update(k * 100_000_000, (0.05 * k, 0.0, 0.0), _moving(k, wide=k >= 30), CONFIG)
    assert monitor.converged_ns is None
