"""Fit the odometry motion model's α (localize.alpha1..alpha4, or ..alpha5) from logs with a reference pose topic.

Usage: ``python scripts/calibrate_odometry.py LOG [LOG ...] [--model differential|omnidirectional]`` — prints the
α and a ``--set`` line (``omnidirectional``: Nav2's OmniMotionModel, α1–α5, for holonomic bases).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from doorbatch.config import DoorbatchConfig
from doorbatch.geometry.odometry import sideways_share
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.localize.calibrate import estimate_alphas, estimate_omni_alphas


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("logs", nargs="+", type=Path)
    parser.add_argument("--model", choices=["differential", "omnidirectional"], default="differential",
                        help="localize.robot_model_type to fit")
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
    omni = args.model == "omnidirectional"
    lc = DoorbatchConfig().localize
    shares = [sideways_share(o[:, 0], o[:, 1], o[:, 2], lc.sideways_step_m) for o in odo_all]
    share = max((s for s in shares if not np.isnan(s)), default=0.0)  # NaN: a log that never moved a step
    if not omni and share > lc.omni_sideways_share:
        print(f"# the odometry moves sideways for {100 * share:.0f} % of its travel (a holonomic base): "
              "fit it with --model omnidirectional")
    fit = estimate_omni_alphas if omni else estimate_alphas
    fits = [fit(o, r) for o, r in zip(odo_all, ref_all, strict=True)]
    n = np.array([f.increments for f in fits], dtype=float)
    names = [f"alpha{i}" for i in range(1, 6 if omni else 5)]
    alphas = [float(np.average([getattr(f, a) for f in fits], weights=n)) for a in names]
    print(" ".join(f"{name}={a:.4g}" for name, a in zip(names, alphas, strict=True)), f"({int(n.sum())} increments)")
    sets = [f"--set localize.{name}={a:.4g}" for name, a in zip(names, alphas, strict=True)]
    print(" ".join(sets + (["--set localize.robot_model_type=omnidirectional"] if omni else [])))


if __name__ == "__main__":
    main()
