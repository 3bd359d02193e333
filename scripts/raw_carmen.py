"""Raw CARMEN logs, mapped with ``doorbatch map``'s default pose source: RMSE against the corrected poses.

Most Radish logs are raw: their FLASER laser poses are the odometry. The corrected logs in
``../shared/datasets/carmen/`` become raw ones here: every pose field (FLASER laser pose and odometry, ODOM lines)
replaced by one trajectory drifted with the simulator's model (the default scenario, seed ``--seed``;
:func:`doorbatch.io.carmen_rewrite.rewrite_carmen_poses`). Each is mapped with ``build_map`` and the default
config (``mapping.pose_source: auto``). Printed per log: the pose source chosen, and the RMSE of the mapping
poses and of the log's own laser poses (its odometry) against the corrected poses, both started at the first
corrected pose.

Usage: ``PYTHONPATH=. python scripts/raw_carmen.py [--logs orebro intel aces] [--seeds 7] [--work DIR]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from doorbatch.config import DoorbatchConfig
from doorbatch.io.carmen_rewrite import rewrite_carmen_poses
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.evaluate.trajectory_error import align_first_pose, ate_rmse
from doorbatch.pipeline.mapping import build_map
from doorbatch.sim.scenario import load_scenario
from doorbatch.sim.simulate import scenario_drift

CARMEN = Path(__file__).resolve().parents[2] / "shared" / "datasets" / "carmen"


def measure(name: str, seed: int, work: Path) -> dict[str, object]:
    corrected = CARMEN / f"{name}-corrected.log.gz"
    raw = work / f"{name}-raw-seed{seed}.log"
    rng = np.random.default_rng(seed)
    rewrite_carmen_poses(corrected, raw, lambda poses: scenario_drift(poses, load_scenario(None), rng))
    config = DoorbatchConfig()
    t0 = time.perf_counter()
    door_map = build_map([raw], config)
    seconds = time.perf_counter() - t0
    truth = load_recording(corrected, config).reference
    own = load_recording(raw, config).reference
    assert truth is not None and own is not None
    mapped = door_map.passes[0]
    at_scans = np.isin(own.stamps_ns, truth.stamps_ns)
    return {"log": name, "seed": seed, "pose_source": door_map.pose_source,
            "mapping_rmse_m": round(ate_rmse(align_first_pose(mapped.poses[mapped.valid], truth.poses[mapped.valid]),
                                             truth.poses[mapped.valid]), 3),
            "own_poses_rmse_m": round(ate_rmse(align_first_pose(own.poses[at_scans], truth.poses), truth.poses), 3),
            "seconds": round(seconds, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=["orebro", "intel", "aces"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[7])
    parser.add_argument("--work", type=Path, help="keep the raw logs here (default: a temporary folder)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for name in args.logs:
            for seed in args.seeds:
                print(measure(name, seed, work), flush=True)


if __name__ == "__main__":
    main()
