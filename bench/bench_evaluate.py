"""Trajectory metrics speed: doorbatch's vectorized APE + RPE against evo's on the same trajectories.

A 2-D drive of N poses at 10 Hz (1 m/s with turns), the estimate a noisy copy with 10 % of the poses dropped
and the stamps jittered by ≤ 4 ms. Timed: association (t_max_diff 0.01 s), APE translation and rotation,
RPE translation and rotation over 1 m (consecutive pairs), statistics; doorbatch's
``trajectory_errors`` + ``statistics`` against evo's ``associate_trajectories`` + ``APE``/``RPE``
``process_data`` + ``get_all_statistics`` (trajectories already in memory for both; evo's SE(3) matrices are
built before timing). Prints the time per call, best of ``--repeats``, and poses per second.

Run: ``taskset -c 0 python bench/bench_evaluate.py [--poses 10000 100000] [--repeats 3] [--evo-max-poses 20000]``
"""

from __future__ import annotations

import argparse
import copy
import platform
import time
from collections.abc import Callable

import numpy as np

from doorbatch.pipeline.evaluate.trajectory_metrics import statistics, trajectory_errors


def _drive(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    stamps = 1_700_000_000_000_000_000 + 100_000_000 * np.arange(n, dtype=np.int64)
    yaw = np.cumsum(rng.normal(0.0, 0.05, n))
    ref = np.stack([np.cumsum(0.1 * np.cos(yaw)), np.cumsum(0.1 * np.sin(yaw)), np.angle(np.exp(1j * yaw))], 1)
    keep = rng.random(n) > 0.1
    est = ref[keep] + rng.normal(0.0, [0.05, 0.05, 0.01], (int(keep.sum()), 3))
    est_stamps = stamps[keep] + rng.integers(-4_000_000, 4_000_000, int(keep.sum()))
    return stamps, ref, est_stamps, est


def _best(fn: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def _ours(stamps: np.ndarray, ref: np.ndarray, est_stamps: np.ndarray, est: np.ndarray) -> None:
    e = trajectory_errors(est_stamps, est, stamps, ref, max_diff_s=0.01, rpe_delta_m=1.0)
    for a in (e.ape_m, e.ape_rad, e.rpe_m, e.rpe_rad):
        statistics(a)


def _evo_trajectories(stamps: np.ndarray, ref: np.ndarray, est_stamps: np.ndarray, est: np.ndarray
                      ) -> tuple[object, object]:
    from evo.core.trajectory import PoseTrajectory3D

    def traj(t: np.ndarray, p: np.ndarray) -> object:
        xyz = np.stack([p[:, 0], p[:, 1], np.zeros(len(p))], 1)
        wxyz = np.stack([np.cos(p[:, 2] / 2), np.zeros(len(p)), np.zeros(len(p)), np.sin(p[:, 2] / 2)], 1)
        return PoseTrajectory3D(xyz, wxyz, t / 1e9)

    return traj(stamps, ref), traj(est_stamps, est)


def _evo(traj_ref: object, traj_est: object) -> None:
    from evo.core import metrics, sync

    r, e = sync.associate_trajectories(copy.deepcopy(traj_ref), copy.deepcopy(traj_est), max_diff=0.01)
    rel = metrics.PoseRelation
    for relation in (rel.translation_part, rel.rotation_angle_rad):
        ape = metrics.APE(relation)
        ape.process_data((r, e))
        ape.get_all_statistics()
        rpe = metrics.RPE(relation, delta=1.0, delta_unit=metrics.Unit.meters)
        rpe.process_data((r, e))
        rpe.get_all_statistics()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--poses", nargs="+", type=int, default=[10_000, 100_000])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--evo-max-poses", type=int, default=20_000, help="time evo only up to this size (it is slow)")
    args = ap.parse_args()
    print(f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, NumPy {np.__version__}")
    print("| poses | doorbatch APE+RPE | poses/s | evo APE+RPE | speed-up |")
    print("| --- | --- | --- | --- | --- |")
    for n in args.poses:
        data = _drive(n, 0)
        ours = _best(lambda d=data: _ours(*d), args.repeats)
        try:
            if n > args.evo_max_poses:
                raise ImportError
            trajs = _evo_trajectories(*data)
            evo = _best(lambda t=trajs: _evo(*t), args.repeats)
            evo_text, ratio = f"{evo * 1e3:.0f} ms", f"{evo / ours:.0f}×"
        except ImportError:
            evo_text, ratio = "–", "–"
        print(f"| {n:,} | {ours * 1e3:.1f} ms | {n / ours / 1e6:.2f} M | {evo_text} | {ratio} |")


if __name__ == "__main__":
    main()
