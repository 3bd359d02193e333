"""How much do the first seconds of a simulated log tell its true start from a shifted or mirrored one?

For each time window, the summed log-likelihood (product of the max_beams beams, the configured endpoint
model) of the true trajectory (the log's ground truth at every scan where the robot moved ≥ update_min_d or
turned ≥ update_min_a) is compared with the same trajectory moved along the x axis by dx (heading kept) and
with it turned by 180° about the point (c/2, 0) (x → c − x, y → −y, yaw → yaw + π), for every dx and c on a
5 cm grid. A positive margin means that a wrong pose explains the scans better than the truth: no filter using
this map can then settle on the truth within that window. Global localization on a straight corridor
(docs/results.md, "Localization (issue #5)").

Usage::

    python scripts/localize_evidence.py LOG --map MAP.yaml|MAPDIR [--doors-closed] [--windows 5 10 20 30]
        [--min-shift 0.3] [--bin-m 4]
    python scripts/localize_evidence.py LOG --truth-map [--bin-m 4]

``--doors-closed`` (a map directory): the RBPF's model instead of the static one, every door of
``doors.parquet`` at its closed angle (the truth of a ``loc_closed`` log). ``--truth-map``: the same with the
simulator's truth (static map and every door, ``<log>.truth.yaml``). ``--bin-m B``: also how well the scans
pin the pose along x where the robot is: per B-metre stretch of the true x, the summed log-likelihood of the
truth shifted by −0.4…+0.4 m relative to the truth itself (a flat row: that stretch does not resolve x).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from doorbatch.config import LocalizeConfig, load_config
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.map_server import read_map
from doorbatch.io.mapdir import read_door_set
from doorbatch.io.recording import load_recording
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_likelihood import door_log_likelihood_at_poses
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    BeamSet,
    DistanceField,
    beam_likelihood,
    build_distance_field,
    endpoint_distances,
    field_log_likelihood,
)
from doorbatch.pipeline.localize.mcl import beams_from_scan
from doorbatch.pipeline.localize.run import laser_to_base_4x4, truth_localization_map

SHIFTS_M = np.arange(-30.0, 38.0, 0.05)
CENTERS_M = np.arange(0.0, 80.0, 0.05)


def scan_log_likelihoods(poses: np.ndarray, beams: BeamSet, field: DistanceField, doors: DoorSet | None,
                         lc: LocalizeConfig) -> np.ndarray:
    """log p(z | x) (N,) of each pose, with the static model or with every door closed (RBPF model)."""
    if doors is None:
        return field_log_likelihood(field, poses, beams.points_base, lc.z_hit, lc.z_rand, lc.sigma_hit,
                                    beams.range_max_m, BeamCombination.PRODUCT)
    n, d = poses.shape[0], len(doors)
    static = endpoint_distances(field, poses, beams.points_base)
    return door_log_likelihood_at_poses(static, poses, beams.points_base, doors, np.zeros((n, d)),
                                        np.full((n, d), 1e-4), lc, beams.range_max_m).log_likelihood


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--map", type=Path, help="map_server YAML or map directory")
    ap.add_argument("--doors-closed", action="store_true")
    ap.add_argument("--truth-map", action="store_true", help="the log's simulator truth instead of --map")
    ap.add_argument("--bin-m", type=float, default=0.0, help="per-stretch x profile (m; 0: off)")
    ap.add_argument("--windows", nargs="+", type=float, default=[5.0, 10.0, 20.0, 30.0])
    ap.add_argument("--min-shift", type=float, default=0.3, help="m; shifts at most this far count as the truth")
    args = ap.parse_args()
    config = load_config()
    lc = config.localize
    if args.truth_map:
        lmap = truth_localization_map(args.log.with_suffix(".truth.yaml"), lc)
        field, doors = lmap.field, lmap.doors
    elif args.map is not None:
        yaml_path = args.map / "map.yaml" if args.map.is_dir() else args.map
        field = build_distance_field(read_map(yaml_path), lc.laser_likelihood_max_dist, lc.unknown_as_max_dist)
        doors = read_door_set(yaml_path.parent) if args.doors_closed else None
    else:
        ap.error("give --map or --truth-map")
    near = np.abs(SHIFTS_M) <= 0.4 + 1e-9
    stretches: dict[int, np.ndarray] = {}
    rec = load_recording(args.log, config)
    assert rec.reference is not None
    ref, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, rec.scans.stamps_ns)
    t = (rec.scans.stamps_ns - rec.scans.stamps_ns[0]) / 1e9
    total_shift = np.zeros(SHIFTS_M.size)
    total_mirror = np.zeros(CENTERS_M.size)
    floor_beams: list[int] = []  # per update: beams at the truth within 1.5x of the per-beam floor (unexplained)
    beam_counts: list[int] = []
    cap = 0.0
    last: int | None = None
    windows = sorted(args.windows)
    w = 0
    for i in np.flatnonzero(ok):
        while w < len(windows) and t[i] > windows[w]:
            report(windows[w], total_shift, total_mirror, args.min_shift)
            w += 1
        if w == len(windows):
            break
        if last is not None and np.hypot(*(ref[i, :2] - ref[last, :2])) < lc.update_min_d \
                and abs(ref[i, 2] - ref[last, 2]) < lc.update_min_a:
            continue
        last = int(i)
        beams = beams_from_scan(rec.scans.scan(int(i)), laser_to_base_4x4(rec.scans.laser_to_base[i]), lc)
        p = ref[i]
        shifted = np.tile(p, (SHIFTS_M.size, 1))
        shifted[:, 0] += SHIFTS_M
        mirrored = np.column_stack([CENTERS_M - p[0], np.full(CENTERS_M.size, -p[1]),
                                    np.full(CENTERS_M.size, p[2] + math.pi)])
        ll = scan_log_likelihoods(shifted, beams, field, doors, lc)
        total_shift += ll
        if args.bin_m > 0:
            key = int(p[0] // args.bin_m)
            stretches[key] = stretches.get(key, 0.0) + ll[near] - ll[np.argmin(np.abs(SHIFTS_M))]
        floor = lc.z_rand / beams.range_max_m
        cap = math.log((lc.z_hit + floor) / floor)
        pz = beam_likelihood(endpoint_distances(field, p[None, :], beams.points_base), lc.z_hit, lc.z_rand,
                             lc.sigma_hit, beams.range_max_m)
        floor_beams.append(int(np.sum(pz < 1.5 * floor)))
        beam_counts.append(len(beams))
        total_mirror += scan_log_likelihoods(mirrored, beams, field, doors, lc)
    for window in windows[w:]:
        report(window, total_shift, total_mirror, args.min_shift)
    if stretches:
        print("x stretch (m) | summed log-likelihood of the truth shifted by " +
              " ".join(f"{s:+.1f}" for s in SHIFTS_M[near][::2]) + " m, minus the truth's")
        for key in sorted(stretches):
            print(f"{key * args.bin_m:5.1f}-{(key + 1) * args.bin_m:<5.1f} | " +
                  " ".join(f"{v:+.1f}" for v in stretches[key][::2]))
    print(f"static model at the truth, {len(floor_beams)} updates: {np.mean(floor_beams):.1f} of "
          f"{np.mean(beam_counts):.0f} beams per update at "
          f"the per-beam floor (max {max(floor_beams)}), each capped at {cap:.2f} nats below a perfect fit")


def report(window_s: float, total_shift: np.ndarray, total_mirror: np.ndarray, min_shift_m: float) -> None:
    truth = total_shift[np.argmin(np.abs(SHIFTS_M))]
    away = np.abs(SHIFTS_M) > min_shift_m
    best_shift = int(np.argmax(np.where(away, total_shift, -np.inf)))
    best_mirror = int(np.argmax(total_mirror))
    print(f"first {window_s:g} s: truth {truth:.1f} nats; best shift {SHIFTS_M[best_shift]:+.2f} m: "
          f"{total_shift[best_shift] - truth:+.1f}; best mirror c = {CENTERS_M[best_mirror]:.2f} m: "
          f"{total_mirror[best_mirror] - truth:+.1f}")


if __name__ == "__main__":
    main()
