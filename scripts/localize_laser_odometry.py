"""Localization with laser odometry: the sample's localization logs with their wheel odometry, and without it
(the scans matched at constant velocity are the motion input, as for a robot without wheel encoders).

Usage: ``doorbatch map datasets/sample/logs/map_pass*.mcap -o MAP --stages grid`` then
``python scripts/localize_laser_odometry.py MAP``; prints the mean / max position error against the reference.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.localize.run import load_localization_map, localize_recording


def main() -> None:
    config = load_config()
    lmap = load_localization_map(Path(sys.argv[1]), config.localize)
    for case in ("closed", "open", "partial"):
        rec = load_recording(Path(f"datasets/sample/logs/loc_{case}.mcap"), config)
        for method in ("mcl", "rbpf"):
            for name, r in (("wheel odometry", rec), ("laser odometry", dataclasses.replace(rec, odometry=None))):
                res = localize_recording(r, lmap, config, method, "reference")
                ref, _ = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, res.stamps_ns)
                e = np.hypot(*(res.pose[:, :2] - ref[:, :2]).T)
                print(f"{case:8s} {method:5s} {name:15s} mean {e.mean():.3f} max {e.max():.3f} m", flush=True)


if __name__ == "__main__":
    main()
