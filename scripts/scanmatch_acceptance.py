"""Scan matching against drifting odometry: ATE on the sample mapping run and on the real CARMEN logs.

The sample's odometry comes from the simulator (drifting, biased). The CARMEN logs are corrected logs whose
odometry equals the corrected poses, so their odometry is corrupted with the simulator's drift model
(default scenario noise, fixed seed) before scan matching. ATE is against the reference poses (simulator
ground truth / corrected poses) at the scan stamps, both trajectories starting at the same pose
(``ate_scanmatch_m``), and the standard ATE (Sturm et al. 2012, evo ``ape -a``): the RMSE after the SE(2)
Umeyama alignment of all positions (``ate_se2_m``, the project's ``umeyama_se2``).

How consistent the reference itself is with the scans: each scan is aligned by PLICP (no prior) to the previous
scan's lines, both placed at their reference poses and starting there; ``ref_pairwise_median_m`` / ``_deg`` are
the median distance and turn from the reference pose to where it converged. A front end without loop closure
that agrees with the scans step by step accumulates roughly that much per step in new territory.

Usage: ``python scripts/scanmatch_acceptance.py [--seed N] [--json] [--every K]`` (``--every K``: also the position
error, the reference position and the running sum of the pairwise turns of every K-th scan, to see where a log
drifts; ``--no-drift``: the CARMEN logs keep their own odometry, in orebro exactly the corrected poses);
``--seeds 1-8`` instead gives each CARMEN log's scan-matching ATE for each of those drift seeds, its median and
its worst (one seed's figure is one draw of the drift: a matcher that derails on another draw is not robust);
``--steps`` instead lists, per log at ``--seed``, the scans where the matched trajectory turns most differently
from the reference (where a run derails); ``--geometry`` instead compares beam geometries against the
corrected poses (see :func:`geometry_check`);
``--logs orebro,intel`` picks the CARMEN logs, ``--no-sample`` skips the sample run; ``--set key=value`` overrides
the configuration (e.g. ``--set scanmatch.loop_closure=false``: the front end alone).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, interpolate_poses, relative
from doorbatch.io.recording import Recording, load_recording
from doorbatch.pipeline.evaluate.trajectory_error import align_first_pose, ate_rmse, position_errors
from doorbatch.pipeline.evaluate.trajectory_metrics import umeyama_se2
from doorbatch.pipeline.poses import scan_match_trajectory
from doorbatch.pipeline.poses.correlative import build_likelihood_grid, correlative_match
from doorbatch.pipeline.poses.plicp import placed, plicp, scan_line_reference, scan_lines
from doorbatch.sim.scenario import load_scenario
from doorbatch.sim.simulate import scenario_drift

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "datasets" / "sample" / "logs"
CARMEN = REPO.parent / "shared" / "datasets" / "carmen"


def ate_se2_m(estimate: np.ndarray, reference: np.ndarray) -> float:
    """Standard ATE (Sturm et al. 2012, evo ``ape -a``): RMSE after the SE(2) Umeyama alignment of all positions."""
    transform = umeyama_se2(estimate[:, :2], reference[:, :2])
    return ate_rmse(compose(np.broadcast_to(transform, estimate.shape), estimate), reference)


def _at_scans(rec: Recording, series: str) -> tuple[np.ndarray, np.ndarray]:
    s = getattr(rec, series)
    return interpolate_poses(s.stamps_ns, s.poses, rec.scans.stamps_ns)


def _hits(rec: Recording, idx: np.ndarray) -> list[np.ndarray]:
    return [rec.scans.hits_base(int(i)) for i in idx]


def reference_consistency(scans: list[np.ndarray], ref: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Median (m, deg) of how far PLICP moves each scan from its reference pose against the previous scan, and
    the running sum of its signed turns (deg, one per scan): how far the scans alone would turn the reference."""
    moved = [np.zeros(3)]
    for k in range(1, len(scans)):
        fit = plicp(scan_line_reference(scans[k - 1], ref[k - 1]), scans[k], ref[k], min_step_m=1e-5,
                    min_step_rad=1e-6)
        moved.append(relative(ref[k], fit.pose))
    d = np.asarray(moved)[1:]
    turned = np.degrees(np.cumsum(np.asarray(moved)[:, 2]))
    return float(np.median(np.hypot(d[:, 0], d[:, 1]))), float(np.degrees(np.median(np.abs(d[:, 2])))), turned


# Beam geometries to compare with the reader's: (name, bearing scale, bearing shift deg, laser forward m).
GEOMETRIES = [("reader", 1.0, 0.0, 0.0), ("shift +0.5 deg (centred)", 1.0, 0.5, 0.0),
              ("shift -0.5 deg", 1.0, -0.5, 0.0), ("shift +0.25 deg", 1.0, 0.25, 0.0),
              ("shift -0.25 deg", 1.0, -0.25, 0.0),
              ("increment x0.995", 0.995, 0.0, 0.0), ("increment x1.005", 1.005, 0.0, 0.0),
              ("increment x0.99", 0.99, 0.0, 0.0), ("mirrored", -1.0, 0.0, 0.0),
              ("laser 0.1 m forward", 1.0, 0.0, 0.1), ("laser 0.1 m back", 1.0, 0.0, -0.1)]


def _hits_variant(rec: Recording, i: int, scale: float, shift_deg: float, forward_m: float) -> np.ndarray:
    """Hits of scan i in base_link, in beam order, with the bearings scaled and shifted and the laser moved."""
    s = rec.scans
    r = s.ranges[i].astype(np.float64)
    a = scale * (s.angle_min[i] + s.angle_increment[i] * np.arange(r.shape[0])) + np.radians(shift_deg)
    hit = np.isfinite(r) & (r >= s.range_min[i]) & (r < s.range_max[i])
    pts = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)[hit]
    pts = pts[::-1] if scale < 0 else pts
    return pts @ s.laser_to_base[i][:, :2].T + s.laser_to_base[i][:, 2] + np.array([forward_m, 0.0])


def occupied_cells(poses: np.ndarray, scans: list[np.ndarray], resolution_m: float = 0.05) -> int:
    """How many cells of ``resolution_m`` the scans' hits fill at ``poses`` (fewer: a sharper map; a reference-free
    measure of how well poses fit the scans)."""
    world = np.concatenate([compose(np.broadcast_to(p, (len(h), 3)), np.column_stack([h, np.zeros(len(h))]))[:, :2]
                            for p, h in zip(poses, scans, strict=True)])
    return int(np.unique(np.floor(world / resolution_m).astype(np.int64), axis=0).shape[0])


def geometry_check(name: str, rec: Recording) -> list[dict[str, object]]:
    """Per beam geometry: occupied 5 cm cells of all hits at the corrected poses (fewer: sharper), and the
    pairwise PLICP turns (scan k against k−1, both at their corrected poses): mean, std, median |turn| (deg),
    lag-1 autocorrelation, the least-squares slope against the reference's own turn (a beam increment off by a
    factor s gives s − 1) with its standard error, the sum over the west corridor scans 100–130 (orebro) and over
    the log."""
    ref, ok = _at_scans(rec, "reference")
    idx = np.flatnonzero(ok)
    rows = []
    for label, scale, shift, forward in GEOMETRIES:
        scans = [_hits_variant(rec, int(i), scale, shift, forward) for i in idx]
        cells = occupied_cells(ref[idx], scans)
        turned = reference_consistency(scans, ref[idx])[2]
        turns = np.diff(turned)
        x = turns - turns.mean()
        ref_turn = np.degrees(relative(ref[idx[:-1]], ref[idx[1:]])[:, 2])
        design = np.column_stack([ref_turn, np.ones_like(ref_turn)])
        (slope, offset), *_ = np.linalg.lstsq(design, turns, rcond=None)
        slope_se = np.sqrt(np.var(turns - design @ (slope, offset)) / np.sum((ref_turn - ref_turn.mean()) ** 2))
        rows.append({"log": name, "geometry": label, "cells_5cm": int(cells),
                     "turn_mean_deg": round(float(turns.mean()), 3),
                     "turn_slope": round(float(slope), 4), "turn_slope_se": round(float(slope_se), 4),
                     "turn_std_deg": round(float(turns.std()), 3),
                     "turn_median_abs_deg": round(float(np.median(np.abs(turns))), 3),
                     "turn_lag1_autocorr": round(float((x[1:] * x[:-1]).mean() / (x * x).mean()), 2),
                     "turn_sum_100_130_deg": round(float(turned[130] - turned[99]), 2) if len(turned) > 130 else None,
                     "turn_sum_all_deg": round(float(turned[-1]), 2)})
    return rows


def correlative_cross_check(rec: Recording, first: int = 101, last: int = 129) -> dict[str, object]:
    """The pairwise turns of scans first…last against the previous scan at the corrected poses, by PLICP and by an
    independent exhaustive correlative search (1 cm, 0.05° lattice, no normals, trimming or robust weights)."""
    ref = _at_scans(rec, "reference")[0]
    scans = _hits(rec, np.arange(len(rec.scans)))
    by_plicp, by_lattice = [], []
    for k in range(first, last + 1):
        lines = placed(scan_lines(scans[k - 1]), ref[k - 1])
        grid = build_likelihood_grid(lines.points, resolution_m=0.01, sigma_m=0.03, window_m=0.2, coarse_cells=4)
        lattice = correlative_match(grid, scans[k], ref[k], window_m=(0.15, 0.15), window_deg=2.0, step_deg=0.05)
        fit = plicp(scan_line_reference(scans[k - 1], ref[k - 1]), scans[k], ref[k], min_step_m=1e-5,
                    min_step_rad=1e-6)
        by_plicp.append(np.degrees(relative(ref[k], fit.pose)[2]))
        by_lattice.append(np.degrees(relative(ref[k], lattice.pose)[2]))
    return {"scans": [first, last], "correlation": round(float(np.corrcoef(by_plicp, by_lattice)[0, 1]), 2),
            "sum_plicp_deg": round(float(np.sum(by_plicp)), 2), "sum_lattice_deg": round(float(np.sum(by_lattice)), 2)}


def _inputs(recs: list[Recording], drift_seed: int | None) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Reference and odometry at the scan stamps (odometry drifted from the reference when a seed is given;
    first poses aligned) and the scans' hits, over the concatenated recordings."""
    refs, odoms, scans = [], [], []
    for rec in recs:
        ref, ok = _at_scans(rec, "reference")
        if drift_seed is None:
            odom, ok2 = _at_scans(rec, "odometry")
            ok &= ok2
        else:
            odom = np.zeros_like(ref)
        idx = np.flatnonzero(ok)
        refs.append(ref[idx])
        odoms.append(odom[idx])
        scans += _hits(rec, idx)
    ref = np.concatenate(refs)
    # drift: the default scenario's odometry (configs/scenarios/default.yaml) at its 50 Hz resolution
    odom = (np.concatenate(odoms) if drift_seed is None
            else scenario_drift(ref, load_scenario(None), np.random.default_rng(drift_seed)))
    return ref, align_first_pose(odom, ref), scans


def ate_over_seeds(name: str, recs: list[Recording], seeds: list[int], config: DoorbatchConfig) -> dict[str, object]:
    """Scan-matching ATE for each drift seed, with the median and the worst (how robust, not one draw)."""
    ates, ates_se2, cells = [], [], []
    ref = np.zeros((0, 3))
    scans: list[np.ndarray] = []
    for seed in seeds:
        ref, odom, scans = _inputs(recs, seed)
        est = align_first_pose(scan_match_trajectory(scans, odom, config.scanmatch).poses, ref)
        ates.append(ate_rmse(est, ref))
        ates_se2.append(ate_se2_m(est, ref))
        cells.append(occupied_cells(est, scans))
    return {"log": name, "seeds": seeds, "ate_scanmatch_m": [round(a, 3) for a in ates],
            "median_m": round(float(np.median(ates)), 3), "worst_m": round(max(ates), 3),
            "ate_se2_m": [round(a, 3) for a in ates_se2], "median_se2_m": round(float(np.median(ates_se2)), 3),
            "worst_se2_m": round(max(ates_se2), 3),
            # the map's sharpness at the matched poses against the reference's (5 cm cells of all hits)
            "cells_5cm_scanmatch": cells, "cells_5cm_reference": occupied_cells(ref, scans) if scans else None}


def evaluate(name: str, recs: list[Recording], drift_seed: int | None, config: DoorbatchConfig, every: int = 0
             ) -> dict[str, object]:
    """ATE of odometry and of scan matching over the concatenated recordings."""
    ref, odom, scans = _inputs(recs, drift_seed)
    t0 = time.perf_counter()
    matched = scan_match_trajectory(scans, odom, config.scanmatch)
    seconds = time.perf_counter() - t0
    est = align_first_pose(matched.poses, ref)
    err = position_errors(est, ref)
    worst = int(np.argmax(err))
    over = np.flatnonzero(err > 0.2)
    pair_m, pair_deg, turned = reference_consistency(scans, ref)
    return {
        "log": name, "scans": len(scans), "ate_odometry_m": round(ate_rmse(odom, ref), 4),
        "ate_scanmatch_m": round(ate_rmse(est, ref), 4), "ate_se2_m": round(ate_se2_m(est, ref), 4),
        "ate_odometry_se2_m": round(ate_se2_m(odom, ref), 4), "max_error_m": round(float(err[worst]), 3),
        "max_error_at_scan": worst, "max_error_at_xy": [round(float(v), 2) for v in ref[worst, :2]],
        "first_scan_over_0.2m": int(over[0]) if over.size else None, "fallbacks": int(matched.fallback.sum()),
        "weak": int(matched.weak.sum()), "loop_keyframes": int(matched.loop_closure.sum()),
        "scans_per_s": round(len(scans) / seconds, 1), "ref_pairwise_median_m": round(pair_m, 4),
        "ref_pairwise_median_deg": round(pair_deg, 3),
        **({"errors_every": [[k, round(float(err[k]), 2), round(float(ref[k, 0]), 1), round(float(ref[k, 1]), 1),
                              round(float(turned[k]), 2)]
                             for k in range(0, len(err), every)]} if every else {}),
    }


def worst_steps(name: str, recs: list[Recording], drift_seed: int, config: DoorbatchConfig, count: int = 8
                ) -> list[dict[str, object]]:
    """The ``count`` scans whose step (from the previous scan) turns most differently from the reference's step,
    with the odometry's step error there and the match's statistics: where a run derails."""
    ref, odom, scans = _inputs(recs, drift_seed)
    matched = scan_match_trajectory(scans, odom, config.scanmatch)
    ref_step = relative(ref[:-1], ref[1:])
    turn_err = np.degrees(wrap_angle(relative(matched.poses[:-1], matched.poses[1:])[:, 2] - ref_step[:, 2]))
    odom_err = np.degrees(wrap_angle(relative(odom[:-1], odom[1:])[:, 2] - ref_step[:, 2]))
    rows = []
    for j in sorted(np.argsort(-np.abs(turn_err))[:count]):
        k = int(j) + 1
        rows.append({"log": name, "seed": drift_seed, "scan": k, "step_turn_error_deg": round(float(turn_err[j]), 2),
                     "odometry_step_turn_error_deg": round(float(odom_err[j]), 1),
                     "reference_move_m": round(float(np.hypot(*ref_step[j, :2])), 2),
                     "reference_turn_deg": round(float(np.degrees(ref_step[j, 2])), 1),
                     "inliers": int(matched.n_inliers[k]), "hits": len(scans[k]),
                     "residual_cm": round(float(matched.residual_m[k]) * 100, 1), "weak": bool(matched.weak[k]),
                     "fallback": bool(matched.fallback[k]), "keyframe": bool(matched.keyframe[k])})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=7, help="drift seed for the CARMEN logs")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--every", type=int, default=0,
                        help="also list [scan, error m, x, y, pairwise turn so far deg] every K scans")
    parser.add_argument("--no-drift", action="store_true",
                        help="CARMEN logs keep their own odometry (in corrected logs: the corrected poses)")
    parser.add_argument("--seeds", type=str, default="",
                        help="instead: ATE of the CARMEN logs over these drift seeds, e.g. 1-8 (median, worst)")
    parser.add_argument("--logs", type=str, default="orebro,intel,aces", help="CARMEN logs to run, comma-separated")
    parser.add_argument("--no-sample", action="store_true", help="skip the sample mapping run")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="config override as for doorbatch --set, e.g. scanmatch.loop_closure=false")
    parser.add_argument("--steps", action="store_true",
                        help="instead: for each CARMEN log at --seed, the 8 scans whose step turn is furthest off")
    parser.add_argument("--geometry", action="store_true",
                        help="instead: beam-geometry variants against the corrected poses (map sharpness, pairwise "
                             "turns) and orebro's corridor turns by PLICP and by an exhaustive correlative search")
    args = parser.parse_args()
    names = [n for n in args.logs.split(",") if n]
    config = load_config(overrides=args.set)
    if args.steps:
        for name in names:
            path = CARMEN / f"{name}-corrected.log.gz"
            if path.exists():
                for row in worst_steps(name, [load_recording(path, config)], args.seed, config):
                    print(json.dumps(row), flush=True)
        return
    if args.geometry:
        for name in names:
            path = CARMEN / f"{name}-corrected.log.gz"
            if path.exists():
                rec = load_recording(path, config)
                for row in geometry_check(name, rec):
                    print(json.dumps(row), flush=True)
                if name == "orebro":
                    print(json.dumps({"log": name, **correlative_cross_check(rec)}), flush=True)
        return
    if args.seeds:
        first, _, last = args.seeds.partition("-")
        seeds = list(range(int(first), int(last or first) + 1))
        for name in names:
            path = CARMEN / f"{name}-corrected.log.gz"
            if path.exists():
                print(json.dumps(ate_over_seeds(name, [load_recording(path, config)], seeds, config)), flush=True)
        return
    rows = [] if args.no_sample else [
        evaluate("sample mapping run (3 passes)",
                 [load_recording(SAMPLE / f"map_pass{k}.mcap", config) for k in (1, 2, 3)], None, config, args.every)]
    for name in names:
        path = CARMEN / f"{name}-corrected.log.gz"
        if path.exists():
            seed = None if args.no_drift else args.seed
            rows.append(evaluate(name, [load_recording(path, config)], seed, config, args.every))
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    for row in rows:
        print("  ".join(f"{k}={v}" for k, v in row.items()))


if __name__ == "__main__":
    main()
