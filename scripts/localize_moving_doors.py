"""How fast does the RBPF's door filter take a door that somebody moves while the robot drives?

Tracks a simulated log (``--init reference``) with the RBPF on the log's truth map (static map and every door, so
that map doors and truth doors are the same). For every door the truth moves during the log (its angle changes by
more than 0.5° between updates), it prints, over the ``--window-s`` seconds after the move ends: the mean |angle
error| of the door's weighted mean, the share of updates in which the scan observed the door, and how long after
the move the error first stays below 5° for five updates. And the position RMSE / max of the run.

Usage::

    doorbatch simulate datasets/sample/worlds/office_corridor.yaml -o /tmp/mv/loc_moving.mcap \\
        --scenario loc_moving --seed 21
    python scripts/localize_moving_doors.py /tmp/mv/loc_moving.mcap [--set localize.door_moved_gate_chi2=1e12]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.recording import load_recording
from doorbatch.io.sim_truth import read_truth
from doorbatch.pipeline.evaluate.trajectory_metrics import ape_translation
from doorbatch.pipeline.localize.run import localize_recording, truth_localization_map

MOVING_RAD = math.radians(0.5)  # a true angle change between two updates larger than this: the door is moving
SETTLED_DEG = 5.0


def move_ends(angle_rad: np.ndarray) -> list[int]:
    """Indices of the updates at which a door's movements end (the first still update after a moving one)."""
    moving = np.abs(np.diff(angle_rad)) > MOVING_RAD
    return [int(i) + 1 for i in np.flatnonzero(moving[:-1] & ~moving[1:])]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--window-s", type=float, default=3.0)
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override key=value")
    args = ap.parse_args()
    config = load_config(overrides=args.overrides)
    truth_path = args.log.with_suffix(".truth.yaml")
    rec = load_recording(args.log, config)
    if rec.reference is None:
        ap.error(f"{args.log} has no reference poses")
    truth = read_truth(truth_path)
    res = localize_recording(rec, truth_localization_map(truth_path, config.localize), config, "rbpf", "reference")
    t = (res.stamps_ns - res.stamps_ns[0]) / 1e9
    true_angle = truth.door_angles_at(res.stamps_ns)
    print(f"{args.log.name}, overrides {args.overrides or 'none'}")
    for k, door in enumerate(truth.doors):
        err = np.degrees(np.abs(wrap_angle(res.door_mean[:, k] - true_angle[:, k])))
        for end in move_ends(true_angle[:, k]):
            window = (t >= t[end]) & (t < t[end] + args.window_s)
            settled = [i for i in range(end, len(t) - 4) if np.all(err[i:i + 5] < SETTLED_DEG)]
            settle = f"{t[settled[0]] - t[end]:.1f} s" if settled else "never"
            print(f"  {door.name} moved until {t[end]:.1f} s: error {err[window].mean():.1f}° over the next "
                  f"{args.window_s:g} s (observed in {res.door_observed[window, k].mean():.0%} of the updates), "
                  f"below {SETTLED_DEG:g}° after {settle}")
    ref, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, res.stamps_ns,
                                round(config.evaluate.global_success_max_reference_gap_s * 1e9))
    err_xy = ape_translation(res.pose[ok], ref[ok])
    print(f"  position RMSE {np.sqrt(np.mean(err_xy ** 2)):.3f} m, max {err_xy.max():.3f} m")


if __name__ == "__main__":
    main()
