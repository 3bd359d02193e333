"""Fit the odometry motion model's α1–α4 (localize.alpha1..alpha4) from a log with a reference pose topic.

Usage: ``python scripts/calibrate_odometry.py LOG [LOG ...]`` — prints the α and a ``--set`` line.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from doorbatch.config import DoorbatchConfig
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.localize.calibrate import estimate_alphas


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("logs", nargs="+", type=Path)
    args = parser.parse_args()
    odo_all, ref_all = [], []
    for path in args.logs:
        rec = load_recording(path, DoorbatchConfig())
        if rec.odometry is None or rec.reference is None:
            raise SystemExit(f"{path}: needs both odometry and a reference pose topic")
        stamps = rec.scans.stamps_ns  # the filter sees odometry at scan times
        odo, ok1 = interpolate_poses(rec.odometry.stamps_ns, rec.odometry.poses, stamps)
        ref, ok2 = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, stamps)
        ok = ok1 & ok2
        odo_all.append(odo[ok])
        ref_all.append(ref[ok])
    fits = [estimate_alphas(o, r) for o, r in zip(odo_all, ref_all, strict=True)]
    n = np.array([f.increments for f in fits], dtype=float)
    alphas = [float(np.average([getattr(f, a) for f in fits], weights=n)) for a in ("alpha1", "alpha2", "alpha3",
                                                                                    "alpha4")]
    print(" ".join(f"alpha{i + 1}={a:.4g}" for i, a in enumerate(alphas)), f"({int(n.sum())} increments)")
    print(" ".join(f"--set localize.alpha{i + 1}={a:.4g}" for i, a in enumerate(alphas)))


if __name__ == "__main__":
    main()
