"""Tracking accuracy of MCL and the RBPF on simulated logs with closed, open and partially open doors.

For each log ``loc_{closed,open,partial}.mcap`` in ``--logs`` (and each seed of ``--seeds``: the filter's seed),
localize with ``--init reference`` on the map directory ``--map`` and compare the estimated positions with the
log's reference (ground truth) at the update stamps. Door angles (RBPF): per update, the mean absolute angle
error over the doors observed in the last 2 s, map doors matched to truth doors (``<log>.truth.yaml``) by
hinge distance ≤ 0.3 m, angles compared in the global leaf direction (closed_yaw + angle).

Usage::

    doorbatch map datasets/sample/logs/map_pass*.mcap -o /tmp/lm/map
    python scripts/localize_tracking.py --map /tmp/lm/map --logs datasets/sample/logs [--seeds 0 1] \
        [--methods mcl rbpf] [--set localize.sigma_hit=0.1 ...] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.recording import load_recording
from doorbatch.io.sim_truth import read_truth
from doorbatch.pipeline.localize.run import load_localization_map, localize, truth_localization_map

CASES = ("closed", "open", "partial")
WINDOW_NS = 2_000_000_000


def door_angle_error(result, lmap, truth_path: Path) -> float:  # type: ignore[no-untyped-def]
    """Mean over updates of the mean |angle error| (deg) over the doors observed in the last 2 s."""
    if not truth_path.exists() or result.door_mean.shape[1] == 0:
        return math.nan
    truth = read_truth(truth_path)
    doors = lmap.doors
    t_hinge = np.array([[d.hinge_x, d.hinge_y] for d in truth.doors]).reshape(-1, 2)
    match: dict[int, int] = {}
    used: set[int] = set()
    for k in range(len(doors)):
        dist = np.linalg.norm(t_hinge - doors.hinge[k], axis=1)
        for j in np.argsort(dist):
            if dist[j] <= 0.3 and int(j) not in used:
                match[k] = int(j)
                used.add(int(j))
                break
    if not match:
        return math.nan
    stamps = result.stamps_ns
    true_angle = truth.door_angles_at(stamps)
    obs = result.door_observed
    last_seen = np.full(obs.shape[1], np.iinfo(np.int64).min // 2)
    per_update: list[float] = []
    for i, t in enumerate(stamps):
        last_seen[obs[i]] = t
        errs = []
        for k, j in match.items():
            if t - last_seen[k] <= WINDOW_NS:
                est = doors.closed_yaw[k] + result.door_mean[i, k]
                ref = truth.doors[j].closed_yaw + true_angle[i, j]
                errs.append(abs(float(wrap_angle(est - ref))))
        if errs:
            per_update.append(float(np.mean(errs)))
    return math.degrees(float(np.mean(per_update))) if per_update else math.nan


def run_case(log: Path, map_dir: Path | None, method: str, seed: int, overrides: list[str]
             ) -> dict[str, float | str | int]:
    config = load_config(overrides=[*overrides, f"seed={seed}"])
    lmap = (truth_localization_map(log.with_suffix(".truth.yaml"), config.localize) if map_dir is None
            else load_localization_map(map_dir, config.localize))
    t0 = time.perf_counter()
    result = localize(log, lmap, config, method, "reference")
    wall = time.perf_counter() - t0
    rec = load_recording(log, config)
    assert rec.reference is not None
    ref, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, result.stamps_ns)
    err = np.hypot(*(result.pose[ok, :2] - ref[ok, :2]).T)
    yaw = np.abs(wrap_angle(result.pose[ok, 2] - ref[ok, 2]))
    return {"log": log.stem, "method": method, "seed": seed, "mean_m": float(err.mean()), "max_m": float(err.max()),
            "over_015": int((err > 0.15).sum()), "yaw_mean_deg": math.degrees(float(yaw.mean())),
            "door_deg": door_angle_error(result, lmap, log.with_suffix(".truth.yaml")),
            "particles": float(result.n_particles.mean()), "updates": len(result), "wall_s": wall}


def _deg(value: object) -> str:
    return "–" if not isinstance(value, float) or math.isnan(value) else f"{value:.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", type=Path, default=None, help="map directory (doorbatch map)")
    ap.add_argument("--logs", type=Path, default=Path("datasets/sample/logs"))
    ap.add_argument("--cases", nargs="+", default=list(CASES))
    ap.add_argument("--methods", nargs="+", default=["mcl", "rbpf"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0])
    ap.add_argument("--truth-map", action="store_true",
                    help="instead of --map, each log's truth: static map and all doors (<log>.truth.yaml)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override key=value")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if (args.map is None) == (not args.truth_map):
        ap.error("give exactly one of --map and --truth-map")
    rows = [run_case(args.logs / f"loc_{case}.mcap", None if args.truth_map else args.map, method, seed,
                     args.overrides)
            for case in args.cases for seed in args.seeds for method in args.methods]
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print("| log | method | seed | mean err (m) | max err (m) | updates > 0.15 m | mean yaw err (°) | "
          "door angle err (°) | mean particles | wall (s) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['log']} | {r['method']} | {r['seed']} | {r['mean_m']:.3f} | {r['max_m']:.3f} | "
              f"{r['over_015']}/{r['updates']} | {r['yaw_mean_deg']:.2f} | {_deg(r['door_deg'])} | "
              f"{r['particles']:.0f} | {r['wall_s']:.1f} |")


if __name__ == "__main__":
    main()
