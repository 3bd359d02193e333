"""Scan matching without odometry (a handheld lidar, a bag without /odom): ATE against each log's reference.

For each log, the scans are matched twice with the odometry left out: at constant velocity (what doorbatch does
without odometry: ``scan_match_trajectory(scans, None, config, stamps)``) and from a constant position (all-zero
odometry: the robot predicted where it was). The first pose is aligned to the reference's; also printed: the share
of scans that left a direction unobserved (``degenerate``: a featureless corridor).

Usage: ``python scripts/scanmatch_no_odometry.py [LOG ...] [--set scanmatch.KEY=VALUE ...]`` (default: the sample's
mapping and localization logs).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.evaluate.trajectory_error import align_first_pose, ate_rmse, position_errors
from doorbatch.pipeline.poses import scan_match_trajectory

SAMPLE = Path("datasets/sample/logs")
DEFAULT_LOGS = [SAMPLE / f"map_pass{k}.mcap" for k in (1, 2, 3)] + [SAMPLE / f"loc_{c}.mcap"
                                                                      for c in ("closed", "open", "partial")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("logs", nargs="*", type=Path, default=DEFAULT_LOGS)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    config = load_config(overrides=args.set)
    print("| log | scans | constant velocity: ATE / max (m) | degenerate | constant position: ATE / max (m) |")
    print("| --- | --- | --- | --- | --- |")
    for path in args.logs:
        rec = load_recording(path, config)
        if rec.reference is None:
            raise SystemExit(f"{path}: needs a reference pose topic to score against")
        stamps = rec.scans.stamps_ns
        ref, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, stamps)
        idx = np.flatnonzero(ok)
        scans = [rec.scans.hits_base(int(i)) for i in idx]
        moving = scan_match_trajectory(scans, None, config.scanmatch, stamps[idx])
        standing = scan_match_trajectory(scans, np.zeros((idx.size, 3)), config.scanmatch)
        cells = []
        for result in (moving, standing):
            est = align_first_pose(result.poses, ref[idx])
            cells.append(f"{ate_rmse(est, ref[idx]):.3f} / {position_errors(est, ref[idx]).max():.3f}")
        print(f"| {path.name} | {idx.size} | {cells[0]} | {np.mean(moving.degenerate):.0%} | {cells[1]} |", flush=True)


if __name__ == "__main__":
    main()
