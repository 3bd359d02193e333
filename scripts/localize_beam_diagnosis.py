"""Where along a tracking run the RBPF's error exceeds MCL's, and how the two weigh the beams there.

Part 1 reads the run directories of ``scripts/localize_tracking.py`` (``OUT/runs/loc_<case>/<method>_s<seed>/``)
and prints the position error against ``<log>.truth.tum`` by the true x (``--bin-m`` bins), both methods.

Part 2 replays the log's scans at the *true* pose: a cloud of ``--particles`` poses around it (std ``--xy-std-m``,
``--yaw-std-deg``; equal weights, so the cloud is converged and beam skipping runs) with the RBPF run's door
estimate of that update (weighted mean and std, door_states.parquet). Per update it counts the beams that eq. (6)
associates with a door (at the true pose), the beams MCL's beam skipping drops and those the RBPF's drops, and
where each model's scan likelihood peaks along x and y (a sweep of ±``--sweep-m`` around the truth, each model
with its own kept beams): a model that peaks off the truth pulls the filter there. Printed by x bin.

Usage::

    python scripts/localize_tracking.py --map MAP --logs LOGS --cases partial --seeds 0 --out OUT
    python scripts/localize_beam_diagnosis.py --map MAP --logs LOGS --runs OUT --case partial --seed 0
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import interpolate_poses, transform_points
from doorbatch.io.parquet import read_table
from doorbatch.io.recording import Recording, load_recording
from doorbatch.io.sim_truth import read_truth
from doorbatch.io.tum import read_tum
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_geometry import leaf_directions
from doorbatch.pipeline.localize.door_likelihood import door_log_likelihood_at_poses
from doorbatch.pipeline.localize.door_observation import update_doors
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    beam_likelihood,
    combine_beams,
    endpoint_distances,
    skip_unexplained,
)
from doorbatch.pipeline.localize.mcl import beams_from_scan
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.run import laser_to_base_4x4, load_localization_map

FloatArray = npt.NDArray[np.float64]


def _errors(run_dir: Path, truth: FloatArray, truth_ns: npt.NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
    t = read_table("trajectory", run_dir / "trajectory.parquet")
    ns = np.asarray(t.column("stamp_ns").to_numpy(), dtype=np.int64)
    est = np.stack([t.column(c).to_numpy() for c in ("x", "y")], axis=1)
    ref, ok = interpolate_poses(truth_ns, truth, ns)
    err = np.hypot(*(est[ok] - ref[ok, :2]).T)
    return ref[ok, 0], err


def _bins(x: FloatArray, values: FloatArray, edges: FloatArray) -> list[str]:
    idx = np.digitize(x, edges) - 1
    return [f"{values[idx == i].mean():.3f}" if (idx == i).any() else "-" for i in range(len(edges) - 1)]


def _truth_door_angles(path: Path, doors: DoorSet, stamps_ns: npt.NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
    """(U, D) the true angles of the map's doors (nearest true hinge within 0.3 m) in the map doors' convention,
    std 0.5°; a map door without a true one keeps angle 0 with std 30°."""
    truth = read_truth(path)
    hinges = np.array([[t.hinge_x, t.hinge_y] for t in truth.doors])
    closed = np.array([t.closed_yaw for t in truth.doors])
    angles = truth.door_angles_at(stamps_ns)
    mean = np.zeros((len(stamps_ns), len(doors)))
    std = np.full_like(mean, np.radians(30.0))
    for k in range(len(doors)):
        gap = np.hypot(*(hinges - doors.hinge[k]).T)
        j = int(np.argmin(gap))
        if gap[j] < 0.3:
            mean[:, k] = wrap_angle(closed[j] + angles[:, j] - doors.closed_yaw[k])
            std[:, k] = np.radians(0.5)
    return mean, std


def _leaf_visibility(rec: Recording, truth_ns: npt.NDArray[np.int64], truth: FloatArray, doors: DoorSet,
                     truth_yaml: Path, config: DoorbatchConfig) -> None:
    """Per map door: scans whose hits put ≥ 10 points within 3 cm of the true leaf, their mean visible extent
    along the leaf (m), and the share of those scans in which :func:`update_doors` observes the door."""
    ok_scans = interpolate_poses(truth_ns, truth, rec.scans.stamps_ns)
    d = len(doors)
    seen = np.zeros(d)
    extent = np.zeros(d)
    observed = np.zeros(d)
    mean_all, _ = _truth_door_angles(truth_yaml, doors, rec.scans.stamps_ns)
    for i in range(len(rec.scans)):
        if not ok_scans[1][i]:
            continue
        pose = ok_scans[0][i]
        pts, hit = rec.scans.endpoints_base(i)
        pts = pts[hit]
        xy = transform_points(pose, pts)
        ux, uy = leaf_directions(doors, mean_all[i])
        v = xy[:, None, :] - doors.hinge[None]
        t = v[..., 0] * ux + v[..., 1] * uy
        e = np.abs(v[..., 1] * ux - v[..., 0] * uy)
        on = (e < 0.03) & (t > -0.03) & (t < doors.length + 0.03)
        vis = on.sum(axis=0) >= 10
        if not vis.any():
            continue
        one = ParticleSet(pose[None].copy(), np.ones(1), mean_all[i][None].copy(),
                          np.full((1, d), np.radians(config.localize.door_init_sigma_deg) ** 2))
        upd = update_doors(pts, one, doors, config.localize)
        for k in np.flatnonzero(vis):
            seen[k] += 1
            extent[k] += float(np.ptp(t[on[:, k], k]))
            observed[k] += float(upd.observed[0, k])
    print("door | hinge | scans leaf seen (>= 10 pts) | mean visible extent (m) | observed by the door update")
    for k in range(d):
        n = max(seen[k], 1)
        print(f"{k} | ({doors.hinge[k, 0]:.1f}, {doors.hinge[k, 1]:.1f}) | {seen[k]:.0f} | {extent[k] / n:.2f} | "
              f"{observed[k] / n:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", type=Path, required=True)
    ap.add_argument("--logs", type=Path, required=True)
    ap.add_argument("--runs", type=Path, required=True, help="--out of localize_tracking.py")
    ap.add_argument("--case", default="partial")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bin-m", type=float, default=3.0)
    ap.add_argument("--x-range", type=float, nargs=2, default=None, help="bin only this true-x range (m)")
    ap.add_argument("--particles", type=int, default=300)
    ap.add_argument("--xy-std-m", type=float, default=0.03)
    ap.add_argument("--yaw-std-deg", type=float, default=1.0)
    ap.add_argument("--sweep-m", type=float, default=0.2)
    ap.add_argument("--truth-doors", action="store_true",
                    help="door angles from <log>.truth.yaml (std 0.5 deg) instead of the RBPF run's estimate")
    ap.add_argument("--leaves", action="store_true",
                    help="part 3: per door, how often the true leaf is in the scan and how often the door update "
                         "observes it (one particle at the true pose, true angles)")
    ap.add_argument("--every", type=int, default=2, help="analyse every k-th RBPF update")
    args = ap.parse_args()

    config = load_config()
    lc = config.localize
    log_path = args.logs / f"loc_{args.case}.mcap"
    tum = read_tum(args.logs / f"loc_{args.case}.truth.tum")
    truth = np.stack([tum.x, tum.y, tum.yaw], axis=1)
    run_root = args.runs / "runs" / f"loc_{args.case}"
    xs: dict[str, FloatArray] = {}
    errs: dict[str, FloatArray] = {}
    for method in ("mcl", "rbpf"):
        xs[method], errs[method] = _errors(run_root / f"{method}_s{args.seed}", truth, tum.stamp_ns)
    lo, hi = args.x_range or (np.floor(min(x.min() for x in xs.values())), max(x.max() for x in xs.values()))
    edges = np.arange(lo, hi + args.bin_m, args.bin_m)
    print(f"# {args.case} seed {args.seed}: position error (m) by true x")
    print("x from | " + " | ".join(f"{e:.0f}" for e in edges[:-1]))
    for method in ("mcl", "rbpf"):
        print(f"{method} | " + " | ".join(_bins(xs[method], errs[method], edges)))

    lmap = load_localization_map(args.map, lc)
    rec = load_recording(log_path, config)
    ds = read_table("door_states", run_root / f"rbpf_s{args.seed}" / "door_states.parquet")
    d = len(lmap.doors)
    ds_ns = np.asarray(ds.column("stamp_ns").to_numpy(), dtype=np.int64).reshape(-1, d)[:, 0]
    ds_mean = np.asarray(ds.column("angle").to_numpy()).reshape(-1, d)
    ds_std = np.asarray(ds.column("angle_std").to_numpy()).reshape(-1, d)
    scan_ns = rec.scans.stamps_ns
    if args.truth_doors:
        ds_mean, ds_std = _truth_door_angles(args.logs / f"loc_{args.case}.truth.yaml", lmap.doors, ds_ns)
    if args.leaves:
        _leaf_visibility(rec, tum.stamp_ns, truth, lmap.doors, args.logs / f"loc_{args.case}.truth.yaml", config)
        return
    rng = np.random.default_rng(0)
    n = args.particles
    offsets = np.linspace(-args.sweep_m, args.sweep_m, 41)
    comb = BeamCombination(lc.beam_combination)
    rows: list[tuple[float, int, int, int, int, int, float, float, float, float]] = []
    for u in range(0, len(ds_ns), args.every):
        i = int(np.searchsorted(scan_ns, ds_ns[u]))
        if i >= len(scan_ns) or scan_ns[i] != ds_ns[u]:
            continue
        ref, ok = interpolate_poses(tum.stamp_ns, truth, scan_ns[i:i + 1])
        if not ok[0]:
            continue
        scan = rec.scans.scan(i)
        beams = beams_from_scan(scan, laser_to_base_4x4(rec.scans.laser_to_base[i]), lc)
        pose = ref[0] + rng.normal(0.0, 1.0, (n, 3)) * [args.xy_std_m, args.xy_std_m, np.radians(args.yaw_std_deg)]
        pose[0] = ref[0]
        w = np.full(n, 1.0 / n)
        mean = np.broadcast_to(ds_mean[u], (n, d)).copy()
        var = np.broadcast_to(ds_std[u] ** 2, (n, d)).copy()
        static = endpoint_distances(lmap.field, pose, beams.points_base)
        pz_m = beam_likelihood(static, lc.z_hit, lc.z_rand, lc.sigma_hit, beams.range_max_m)
        dl = door_log_likelihood_at_poses(static, pose, beams.points_base, lmap.doors, mean, var, lc,
                                          beams.range_max_m)
        kept_m, _ = skip_unexplained(pz_m, w, pose, lc, beams.range_max_m, comb)
        kept_r, _ = skip_unexplained(dl.beam_likelihood, w, pose, lc, beams.range_max_m, comb)
        skip_m = kept_m[0] == 1.0
        skip_r = kept_r[0] == 1.0
        door = dl.association[0] >= 0
        peaks = []
        for axis in (0, 1):
            sweep = np.repeat(ref, len(offsets), axis=0)
            sweep[:, axis] += offsets
            st = endpoint_distances(lmap.field, sweep, beams.points_base)
            lm = np.where(skip_m, 1.0, beam_likelihood(st, lc.z_hit, lc.z_rand, lc.sigma_hit, beams.range_max_m))
            lr_all = door_log_likelihood_at_poses(st, sweep, beams.points_base, lmap.doors,
                                                  np.broadcast_to(ds_mean[u], (len(offsets), d)),
                                                  np.broadcast_to(ds_std[u] ** 2, (len(offsets), d)), lc,
                                                  beams.range_max_m).beam_likelihood
            lr = np.where(skip_r, 1.0, lr_all)
            peaks += [offsets[int(np.argmax(combine_beams(np.nan_to_num(lm, nan=1.0), comb)))],
                      offsets[int(np.argmax(combine_beams(np.nan_to_num(lr, nan=1.0), comb)))]]
        rows.append((float(ref[0, 0]), len(beams.points_base), int(door.sum()), int(skip_m.sum()), int(skip_r.sum()),
                     int((skip_m & ~skip_r & door).sum()), *peaks))
    a = np.asarray(rows)
    idx = np.digitize(a[:, 0], edges) - 1
    print(f"\n# {args.case}: per update at the true pose (means over updates in each true-x bin)")
    print("x from | updates | beams | door-assoc | MCL skips | RBPF skips | door beams RBPF keeps, MCL skips | "
          "peak dx MCL | peak dx RBPF | peak dy MCL | peak dy RBPF")
    for b in range(len(edges) - 1):
        sel = a[idx == b]
        if not len(sel):
            continue
        m = sel[:, 1:].mean(axis=0)
        print(f"{edges[b]:.0f} | {len(sel)} | {m[0]:.1f} | {m[1]:.1f} | {m[2]:.1f} | {m[3]:.1f} | {m[4]:.1f} | "
              f"{m[5]:+.3f} | {m[6]:+.3f} | {m[7]:+.3f} | {m[8]:+.3f}")


if __name__ == "__main__":
    main()
